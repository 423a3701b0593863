"""dispatch: solve, fall back to FCFS, check, evaluate, render."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.problem import ProblemError
from service.core.schemas import ScheduleRequest, ScheduleResponse
from service.learning.generate import small_problem
from service.solvers import registry
from service.solvers.dispatch import DispatchPolicy, dispatch
from service.solvers.registry import SolveContext, SolverOutput
from tests.reference import costs, least_times, reference_problem, trap_request

POLICY = DispatchPolicy(default_time_limit_s=10.0, exact_max_conflicts=60)


def _request(req: dict[str, Any], **options: Any) -> ScheduleRequest:
    return ScheduleRequest.model_validate({**req, "options": options})


@pytest.mark.parametrize("objective", ["avg_completion", "sync_completion"])
def test_exact_response_matches_reference(objective: str) -> None:
    req = small_problem(2, objective)
    response = dispatch(_request(req, solver="exact"), POLICY)
    assert response.solver.name == "exact" and response.solver.optimal
    assert response.solver.fallback_from is None
    assert response.checks.acyclic and response.checks.density
    ref = reference_problem(req)
    index = {c.a + "|" + c.b: k for k, c in enumerate(ref.conflicts)}
    a_first = [False] * len(ref.conflicts)
    following = [False] * len(ref.conflicts)
    for out in response.assignment:
        k = index.get(out["from"] + "|" + out["to"], index.get(out["to"] + "|" + out["from"]))
        assert k is not None
        a_first[k] = ref.conflicts[k].a == out["from"]
        following[k] = out["type"] == "following"
    times = least_times(ref, a_first, following)
    want = costs(ref, times)
    assert response.cost == pytest.approx(want[objective], rel=1e-9)
    assert response.costs.model_dump() == pytest.approx(want, rel=1e-9)
    assert times is not None
    for r, robot in enumerate(response.schedule):
        assert robot.robot == ref.robot_ids[r]
        assert robot.completion == pytest.approx(times[r][-1])
        assert robot.delay == pytest.approx(times[r][-1] - ref.time_points[r][-1])
        k = {t: i for i, t in enumerate(ref.time_points[r])}
        for node, plan in zip(robot.nodes, ref.robot_nodes[r], strict=True):
            assert node.id == plan["id"]
            assert node.enter == pytest.approx(times[r][k[plan["enter"]]])
            assert node.exit == pytest.approx(times[r][k[plan["exit"]]])


def test_no_answer_falls_back_to_fcfs(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(registry._REGISTRY, "exact", lambda ctx: None)
    response = dispatch(_request(small_problem(1), solver="exact"), POLICY)
    assert response.solver.name == "fcfs"
    assert response.solver.fallback_from == "exact"
    assert response.checks.acyclic and response.checks.density


def test_a_failing_solver_falls_back(monkeypatch: pytest.MonkeyPatch, caplog) -> None:
    def broken(ctx: SolveContext) -> SolverOutput:
        raise ValueError("a bug")

    monkeypatch.setitem(registry._REGISTRY, "exact", broken)
    response = dispatch(_request(small_problem(1), solver="exact"), POLICY)
    assert response.solver.name == "fcfs" and response.solver.fallback_from == "exact"
    assert "solver exact failed" in caplog.text


def test_invalid_answer_is_never_returned(monkeypatch: pytest.MonkeyPatch) -> None:
    def cyclic(ctx: SolveContext) -> SolverOutput:
        # The trap's free node cycle: time-feasible, but not acyclic.
        return SolverOutput(Assignments.single([False] * 3, [False] * 3), optimal=True)

    monkeypatch.setitem(registry._REGISTRY, "exact", cyclic)
    response = dispatch(_request(trap_request(), solver="exact"), POLICY)
    assert response.solver.name == "fcfs" and response.solver.fallback_from == "exact"
    assert response.checks.acyclic
    assert response.cost > 10.0


def test_invalid_problem_raises() -> None:
    req = small_problem(0)
    req["conflicts"][0]["a"] = "nope"
    with pytest.raises(ProblemError):
        dispatch(_request(req), POLICY)


def test_fcfs_response() -> None:
    response = dispatch(_request(small_problem(4), solver="fcfs"), POLICY)
    assert response.solver.name == "fcfs" and not response.solver.optimal
    assert np.isfinite(response.cost)


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    solver=st.sampled_from(["fcfs", "exact", "tabu", "auto"]),
    objective=st.sampled_from(["avg_completion", "max_completion", "sync_completion"]),
)
def test_rendered_answer_is_what_validation_makes_of_it(
    seed: int, solver: str, objective: str
) -> None:
    """Answers are constructed without validation (speed): they must be exactly what the
    response model makes of their own dump, field types included."""
    req = small_problem(seed, objective)
    response = dispatch(_request(req, solver=solver, time_limit_s=1.0), POLICY)
    dumped = response.model_dump(by_alias=True)
    again = ScheduleResponse.model_validate(dumped)
    assert again.model_dump(by_alias=True) == dumped
    assert again.model_dump_json(by_alias=True) == response.model_dump_json(by_alias=True)
    assert all(type(n.enter) is float for r in response.schedule for n in r.nodes)


def test_finding_the_cliques_counts_against_the_deadline(monkeypatch: pytest.MonkeyPatch) -> None:
    """Cliques found after the solver's time was read once let a 0.3 s request of a
    250-robot warehouse with 14 million clique incidences run 0.85 s."""
    from service.solvers import dispatch as module

    seen: list[float] = []
    slow = module.find_cliques

    def slow_cliques(problem):  # noqa: ANN001, ANN202
        found = slow(problem)
        time.sleep(0.3)  # past the deadline below
        return found

    def spy(ctx: SolveContext) -> SolverOutput:
        seen.append(ctx.time_limit_s)
        return registry.get_solver("fcfs")(ctx)

    monkeypatch.setattr(module, "find_cliques", slow_cliques)
    monkeypatch.setitem(registry._REGISTRY, "exact", spy)
    request = _request(small_problem(3), solver="exact", time_limit_s=0.2)
    response = module.dispatch(request, POLICY, deadline=time.monotonic() + 0.2)
    assert seen == [0.0] and response.solver.name == "exact"
