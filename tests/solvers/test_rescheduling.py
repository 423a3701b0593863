"""Re-schedules of larger problems: valid, faithful to the past, never worse than the previous
answer, for every solver; the Rescheduler answers like dispatch with the same request."""

from __future__ import annotations

import gc
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.evaluate import Evaluator
from service.core.problem import Problem
from service.core.progress import previous_from_wire, progress_from_wire, residual_problem
from service.core.schemas import PreviousConflictIn, ProgressIn, ScheduleRequest
from service.learning.generate import stitched_problem
from service.solvers.dispatch import DispatchPolicy, dispatch, render_reserve
from service.solvers.rescheduling import Rescheduler

POLICY = DispatchPolicy()
SOLVERS = ("auto", "tabu", "priority_tabu", "reinsert", "fcfs", "random", "bbts", "cmaes")


def _progress(problem: Problem, previous: Assignments, rng: np.random.Generator) -> dict[str, Any]:
    """What a fleet executing ``previous`` reports at a random moment, some robots later."""
    ev = Evaluator(problem)
    result = ev.evaluate(previous)
    delays = ev.delays_at(result, 0, np.arange(problem.tp_time.size))  # (P,)
    actual = problem.tp_time + delays  # (P,)
    now = float(rng.uniform(problem.tp_time.min(), result.completion.max()))
    robots = {}
    for r, rid in enumerate(problem.robot_ids):
        span = slice(problem.tp_start[r], problem.tp_start[r + 1])
        passed = np.flatnonzero(actual[span] <= now)
        if passed.size:
            k = passed[-1]
            late = float(rng.exponential(3.0)) if rng.random() < 0.3 else 0.0
            robots[rid] = {
                "passed_until": float(problem.tp_time[span][k]),
                "delay": float(delays[span][k]) + late,
            }
    return {"time": now, "robots": robots}


def _case(seed: int, objective: str) -> tuple[ScheduleRequest, Rescheduler, list, dict[str, Any]]:
    req = ScheduleRequest.model_validate(
        {**stitched_problem(seed, 12, 3.0), "objective": objective}
    )
    first = dispatch(
        req.model_copy(update={"options": req.options.model_copy(update={"solver": "fcfs"})}),
        POLICY,
    )
    previous = [PreviousConflictIn.model_validate(a) for a in first.assignment]
    rs = Rescheduler(req, POLICY)
    progress = _progress(
        rs.problem, previous_from_wire(rs.problem, previous), np.random.default_rng(seed)
    )
    return req, rs, previous, progress


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 10_000),
    solver=st.sampled_from(SOLVERS),
    objective=st.sampled_from(["avg_completion", "max_completion", "avg_delay"]),
)
def test_a_reschedule_is_valid_keeps_the_past_and_is_never_worse_than_previous(
    seed: int, solver: str, objective: str
) -> None:
    req, rs, previous, progress = _case(seed, objective)
    answer = rs.solve(
        previous, ProgressIn.model_validate(progress), time_limit_s=0.3, solver=solver
    )
    assert answer.checks.acyclic and answer.checks.density and answer.checks.forced
    warm = previous_from_wire(rs.problem, previous)
    decided = {(a["from"], a["to"]): a["type"] for a in answer.assignment}
    wire = ProgressIn.model_validate(progress)
    res = residual_problem(rs.problem, progress_from_wire(rs.problem, wire), warm)
    ids = res.node_ids
    for m in np.flatnonzero(res.forced).tolist():  # settled directions kept
        a, b = ids[res.conf_a[m]], ids[res.conf_b[m]]
        assert ((a, b) if res.forced[m] > 0 else (b, a)) in decided
    for m in np.flatnonzero(res.realized).tolist():  # realized types kept
        a, b = ids[res.conf_a[m]], ids[res.conf_b[m]]
        pair = (a, b) if warm.a_first[0, m] else (b, a)
        assert decided[pair] == ("following" if warm.following[0, m] else "exclusive")
    if solver in ("auto", "tabu", "priority_tabu"):  # from the previous answer or better
        warm_cost = Evaluator(res).evaluate(warm).costs[objective][0]
        assert answer.cost <= warm_cost + 1e-9


@pytest.mark.parametrize("seed", range(3))
def test_rescheduler_answers_like_dispatch(seed: int) -> None:
    req, rs, previous, progress = _case(seed, "avg_completion")
    body = req.model_copy(
        update={
            "previous": previous,
            "progress": ProgressIn.model_validate(progress),
            "options": req.options.model_copy(update={"solver": "fcfs", "time_limit_s": 1.0}),
        }
    )
    direct = dispatch(body, POLICY)
    cached = rs.solve(previous, body.progress, time_limit_s=1.0, solver="fcfs")
    assert cached.cost == pytest.approx(direct.cost, rel=1e-12)
    assert cached.assignment == direct.assignment


def test_a_reschedule_leaves_the_collector_as_it_was() -> None:
    _, rescheduler, previous, progress = _case(0, "avg_completion")
    assert gc.isenabled()
    rescheduler.solve(previous, ProgressIn.model_validate(progress), time_limit_s=0.2)
    assert gc.isenabled()


def test_the_reserve_follows_the_measured_tails() -> None:
    """The solver stops early enough for recent calls' checking and rendering, and never
    later than the model of that work says."""
    _, rescheduler, previous, progress = _case(1, "avg_completion")
    floor = render_reserve(rescheduler.problem)
    assert rescheduler.reserve(rescheduler.problem) == floor
    rescheduler.tails.extend([floor / 2] * 20)
    assert rescheduler.reserve(rescheduler.problem) == floor
    rescheduler.tails.extend([0.05] * 18 + [0.2] * 2)
    assert rescheduler.reserve(rescheduler.problem) == pytest.approx(0.05 + 0.1 * 0.15, rel=1e-9)
    rescheduler.tails.clear()
    rescheduler.solve(previous, ProgressIn.model_validate(progress), time_limit_s=0.1)
    assert len(rescheduler.tails) == 1 and rescheduler.tails[0] < 0.1
