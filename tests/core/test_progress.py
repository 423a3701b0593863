"""Re-scheduling from progress: the residual problem against an independent reference.

The reference (tests/reference.py) executes an assignment (least times), reads
the progress a fleet would report at a random moment, rebuilds the residual
problem from the documented rules in plain Python (shifted times, settled and
realized conflicts) and enumerates it by brute force. The service's residual
problem must evaluate every assignment like the reference, CP-SAT must reach
the brute-force optimum, and the progress checks must name the field at fault.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import find_cliques
from service.core.evaluate import Evaluator
from service.core.problem import Problem, ProblemError, problem_from_request
from service.core.progress import previous_from_wire, progress_from_wire, residual_problem
from service.core.schemas import ProgressIn, ScheduleRequest
from service.solvers.dispatch import DispatchPolicy, dispatch
from tests.reference import (
    OBJECTIVE_NAMES,
    costs,
    feasible_assignments,
    least_times,
    reference_problem,
    tiny_request,
)


def _wire(problem: Problem, a_first: Any, following: Any) -> list[dict[str, str]]:
    """An assignment as the wire ``previous`` list."""
    ids = problem.node_ids
    out = []
    for m, (a, b) in enumerate(zip(problem.conf_a, problem.conf_b, strict=True)):
        u, v = (a, b) if a_first[m] else (b, a)
        out.append(
            {"from": ids[u], "to": ids[v], "type": "following" if following[m] else "exclusive"}
        )
    return out


def _observed(ref: Any, times: list[list[float]], t: float) -> dict[str, Any]:
    """The progress a fleet executing ``times`` reports at ``t``: last passed point, its delay."""
    robots = {}
    for rid, planned, actual in zip(ref.robot_ids, ref.time_points, times, strict=True):
        passed = [k for k, a in enumerate(actual) if a <= t]
        if passed:
            k = passed[-1]
            robots[rid] = {"passed_until": planned[k], "delay": actual[k] - planned[k]}
    return {"time": t, "robots": robots}


def _shift(planned: list[float], p: float, d: float, t: float) -> dict[float, float]:
    """The documented residual times of one robot (planned -> shifted)."""
    done = [x for x in planned if x <= p]
    todo = [x for x in planned if x > p]
    a = min(d, t - done[-1]) if done else 0.0
    u = max(d, t - todo[0]) if todo else 0.0
    return {x: x + (a if x <= p else u) for x in planned}


def _reference_residual(req: dict[str, Any], ref: Any, progress: dict[str, Any]) -> dict[str, Any]:
    """``req`` with every time replaced by its residual time (plain Python, from the docs)."""
    t = progress["time"]
    maps = {}
    for rid, planned in zip(ref.robot_ids, ref.time_points, strict=True):
        rp = progress["robots"].get(rid, {"passed_until": -math.inf, "delay": 0.0})
        maps[rid] = _shift(planned, rp["passed_until"], rp["delay"], t)
    node_map = {n["id"]: maps[r["id"]] for r in req["robots"] for n in r["nodes"]}
    robots = [
        {
            **r,
            **({"goal_time": maps[r["id"]][r["goal_time"]]} if r.get("goal_time") else {}),
            "nodes": [
                {**n, "enter": maps[r["id"]][n["enter"]], "exit": maps[r["id"]][n["exit"]]}
                for n in r["nodes"]
            ],
        }
        for r in req["robots"]
    ]
    nodes = {n["id"]: n for r in req["robots"] for n in r["nodes"]}
    conflicts = []
    for c in req["conflicts"]:
        c = dict(c)
        for side in ("a", "b"):
            for end in ("enter", "exit"):
                key = f"{side}_{end}"
                value = c.get(key, nodes[c[side]][end])
                c[key] = node_map[c[side]][value]
        conflicts.append(c)
    return {**req, "robots": robots, "conflicts": conflicts}


def _case(seed: int) -> tuple[dict[str, Any], Problem, Any, tuple, list, dict[str, Any]] | None:
    """A tiny problem, a valid assignment, its execution and the progress at a random time."""
    req = tiny_request(seed)
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    ref = reference_problem(req)
    cands = [c for c in feasible_assignments(ref) if math.isfinite(c.costs["avg_completion"])]
    if not cands or problem.n_conflicts == 0:
        return None
    rng = np.random.default_rng(seed)
    chosen = cands[int(rng.integers(len(cands)))]
    times = least_times(ref, chosen.a_first, chosen.following)
    lo = min(ts[0] for ts in ref.time_points)
    hi = max(ts[-1] for ts in times)
    progress = _observed(ref, times, float(rng.uniform(lo, hi)))
    return req, problem, ref, chosen, cands, progress


@pytest.mark.parametrize("seed", range(40))
def test_residual_evaluates_like_the_reference_and_cp_sat_reaches_brute_force(seed: int) -> None:
    case = _case(seed)
    if case is None:
        pytest.skip("no conflict")
    req, problem, ref, chosen, cands, progress = case
    previous = previous_from_wire(
        problem,
        ScheduleRequest.model_validate(
            {**req, "previous": _wire(problem, chosen.a_first, chosen.following)}
        ).previous,
    )
    res = residual_problem(
        problem, progress_from_wire(problem, ProgressIn.model_validate(progress)), previous
    )
    res_ref = reference_problem(_reference_residual(req, ref, progress))
    assert np.allclose(np.sort(res.tp_time), np.sort([x for ts in res_ref.time_points for x in ts]))
    skip = frozenset(np.flatnonzero(res.realized).tolist())
    # Every assignment the residual admits: the settled directions and realized types.
    fixed = np.flatnonzero(res.forced)
    typed = np.flatnonzero(res.fixed_type >= 0)
    admitted = [
        c
        for c in cands
        if all(c.a_first[m] == (res.forced[m] > 0) for m in fixed)
        and all(c.following[m] == (res.fixed_type[m] == 1) for m in typed)
    ]
    assert any(c.a_first == chosen.a_first and c.following == chosen.following for c in admitted)
    batch = Assignments(
        np.array([c.a_first for c in admitted], dtype=bool),
        np.array([c.following for c in admitted], dtype=bool),
    )
    ours = Evaluator(res).evaluate(batch)
    assert check(res, find_cliques(res), batch).ok.all()
    expected = [
        costs(res_ref, least_times(res_ref, c.a_first, c.following, skip)) for c in admitted
    ]
    for objective in OBJECTIVE_NAMES:
        want = np.array([e[objective] for e in expected])
        assert np.allclose(ours.costs[objective], want, rtol=1e-9, atol=1e-9), objective
    # CP-SAT on the re-schedule request reaches the brute-force optimum.
    body = {
        **req,
        "objective": "avg_completion",
        "previous": _wire(problem, chosen.a_first, chosen.following),
        "progress": progress,
        "options": {"solver": "exact", "time_limit_s": 20.0},
    }
    answer = dispatch(ScheduleRequest.model_validate(body), DispatchPolicy())
    best = min(e["avg_completion"] for e in expected)
    assert answer.solver.optimal
    assert answer.cost == pytest.approx(best, rel=1e-9, abs=1e-9)
    assert answer.checks.forced and answer.checks.acyclic and answer.checks.density
    # The previous answer is never worse than executing it from here.
    before = costs(ref, least_times(ref, chosen.a_first, chosen.following))["avg_completion"]
    assert best <= before + 1e-9


def test_no_progress_is_the_problem_itself() -> None:
    req = tiny_request(3)
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    start = float(problem.tp_time.min())
    res = residual_problem(problem, progress_from_wire(problem, ProgressIn(time=start)), None)
    assert np.array_equal(res.tp_time, problem.tp_time)
    assert not res.realized.any() and not res.tp_passed.any()
    assert np.array_equal(res.forced, problem.forced)


def test_delay_shifts_the_rest_of_a_robot_and_time_bounds_a_waiting_robot() -> None:
    req = {
        "robots": [
            {"id": "r0", "nodes": [{"id": "r0/0", "enter": 10.0, "exit": 20.0}]},
            {"id": "r1", "nodes": [{"id": "r1/0", "enter": 12.0, "exit": 22.0}]},
        ],
        "conflicts": [{"a": "r0/0", "b": "r1/0"}],
    }
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    wire = {"time": 15.0, "robots": {"r0": {"passed_until": 10.0, "delay": 3.0}}}
    res = residual_problem(
        problem, progress_from_wire(problem, ProgressIn.model_validate(wire)), None
    )
    # r0 passed its enter (10 -> 13, when it was passed), runs 3 s late: exit 23.
    assert res.node_enter.tolist() == [13.0, 15.0]  # r1 has not started: cannot enter before 15
    assert res.node_exit.tolist() == [23.0, 25.0]
    assert res.forced.tolist() == [1]  # r0 entered first: it keeps the conflict
    assert res.tp_passed.tolist() == [True, False, False, False]


@pytest.mark.parametrize(
    ("body", "loc"),
    [
        ({"progress": {"time": 5.0, "robots": {"zz": {}}}}, ["body", "progress", "robots", "zz"]),
        (
            {"progress": {"time": 5.0, "robots": {"r1": {"passed_until": 12.0}}}},
            ["body", "progress", "robots", "r1", "passed_until"],
        ),
        (
            {"previous": [{"from": "r0/0", "to": "nope", "type": "exclusive"}]},
            ["body", "previous", 0, "to"],
        ),
        ({"previous": []}, ["body", "previous"]),
        (
            {
                "previous": [{"from": "r0/0", "to": "r1/0", "type": "exclusive"}] * 2,
            },
            ["body", "previous", 1],
        ),
        (
            {
                "conflicts": [{"a": "r0/0", "b": "r1/0", "first": "a"}],
                "progress": {"time": 13.0, "robots": {"r1": {"passed_until": 12.0}}},
            },
            ["body", "progress", "robots", "r1", "passed_until"],
        ),
    ],
)
def test_bad_progress_is_a_422_naming_the_field(body: dict[str, Any], loc: list[Any]) -> None:
    req = {
        "robots": [
            {"id": "r0", "nodes": [{"id": "r0/0", "enter": 10.0, "exit": 20.0}]},
            {"id": "r1", "nodes": [{"id": "r1/0", "enter": 12.0, "exit": 22.0}]},
        ],
        "conflicts": [{"a": "r0/0", "b": "r1/0"}],
        **body,
    }
    with pytest.raises(ProblemError) as err:
        dispatch(ScheduleRequest.model_validate(req), DispatchPolicy())
    assert [e.as_dict()["loc"] for e in err.value.errors][0] == loc


def test_the_past_wins_over_a_previous_answer_it_contradicts() -> None:
    """r1 entered the section previous gave to r0, which has not: r1 keeps it."""
    req = {
        "robots": [
            {"id": "r0", "nodes": [{"id": "r0/0", "enter": 10.0, "exit": 20.0}]},
            {"id": "r1", "nodes": [{"id": "r1/0", "enter": 12.0, "exit": 22.0}]},
        ],
        "conflicts": [{"a": "r0/0", "b": "r1/0"}],
        "previous": [{"from": "r0/0", "to": "r1/0", "type": "exclusive"}],
        "progress": {"time": 13.0, "robots": {"r1": {"passed_until": 12.0}}},
    }
    answer = dispatch(ScheduleRequest.model_validate(req), DispatchPolicy())
    assert answer.assignment[0]["from"] == "r1/0"
    assert answer.checks.forced


def test_negative_delay_is_rejected_by_the_schema() -> None:
    with pytest.raises(ValueError, match="delay"):
        ProgressIn.model_validate({"time": 1.0, "robots": {"r0": {"delay": -1.0}}})
