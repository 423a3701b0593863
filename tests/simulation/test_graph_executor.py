"""The graph-form executor: least times when undisturbed, dependencies kept when disturbed,
deadlocks reported, wire plans checked.

Hand-worked times: each robot passes its first point at its planned time and every
next point one planned gap of progress later, unless it waits there.
"""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.cliques import find_cliques
from service.core.decode import Decoder
from service.core.dependency_plan import dependency_plan, wait_constraints
from service.core.evaluate import Evaluator
from service.core.problem import Problem, ProblemError, problem_from_request
from service.core.progress import Progress, residual_problem
from service.core.schemas import ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from service.simulation.disturbances import Rate
from service.simulation.graph_executor import GraphRun, TimePointPlan, execute_plan, plan_from_wire
from tests.reference import tiny_request


def _problem(req: dict[str, Any]) -> Problem:
    return problem_from_request(ScheduleRequest.model_validate(req))


def _lane(rid: str, enter: float, exit_: float) -> dict[str, Any]:
    """A robot with one node."""
    return {"id": rid, "nodes": [{"id": f"{rid}0", "enter": enter, "exit": exit_}]}


# a: points 0, 4, 8, 10 (section [4, 8]); b: points 1, 3, 5, 9 (section [3, 5]).
TWO = _problem(
    {
        "robots": [_lane("a", 0.0, 10.0), _lane("b", 1.0, 9.0)],
        "conflicts": [
            {"a": "a0", "b": "b0", "a_enter": 4.0, "a_exit": 8.0, "b_enter": 3.0, "b_exit": 5.0}
        ],
    }
)
A_FIRST = Assignments.single([True], [False])  # b waits at 3 until a passed 8


def _run(problem: Problem, assignments: Assignments, rates: list[Rate] | None = None) -> GraphRun:
    """Plan, through the wire, and execute."""
    return execute_plan(
        problem, plan_from_wire(problem, dependency_plan(problem, assignments)), rates
    )


def _times(problem: Problem, run: GraphRun) -> list[list[float]]:
    return [run.robot_times(problem, r).tolist() for r in range(problem.n_robots)]


def test_undisturbed_run_waits_exactly_as_long_as_needed() -> None:
    run = _run(TWO, A_FIRST)
    assert _times(TWO, run) == [[0, 4, 8, 10], [1, 8, 10, 14]]
    assert run.completion.tolist() == [10, 14] and run.deadlocked == ()


def test_a_stop_delays_the_robot_and_those_waiting_for_it() -> None:
    # a stops on [2, 5): it passes 4 at 7, 8 at 11; b waits at its point 3 until 11.
    run = _run(TWO, A_FIRST, [Rate.of([(2.0, 3.0, 0.0)]), Rate()])
    assert _times(TWO, run) == [[0, 7, 11, 13], [1, 11, 13, 17]]


def test_a_late_start_and_a_slow_down_are_absorbed_by_a_wait() -> None:
    # b starts 2 s late (stopped on [1, 3)) and runs at half rate on [3, 5): it gains 1 s of
    # the 2 s to its point 3 by 5 and arrives at 6 (alone: passes 3 at 6, 5 at 8, 9 at 12).
    # It waits there for a's point 8 anyway, until 8, and so keeps its undisturbed times.
    rates = [Rate(), Rate.of([(1.0, 2.0, 0.0), (3.0, 2.0, 0.5)])]
    assert _times(TWO, _run(TWO, A_FIRST, rates))[1] == [1, 8, 10, 14]
    alone = execute_plan(TWO, TimePointPlan(np.zeros(0, int), np.zeros(0, int)), rates)
    assert alone.robot_times(TWO, 1).tolist() == [1, 6, 8, 12]


def test_a_cycle_of_waits_deadlocks_its_robots_and_those_waiting_for_them() -> None:
    # Four robots, one node [0, 10] each (points 0 and 10): a and b wait at 10 for each
    # other's 10, c at 10 for a's 10; d waits at 10 for a's 0, which a passed at once.
    problem = _problem({"robots": [_lane(r, 0.0, 10.0) for r in "abcd"]})
    deps = [
        {"robot": "a", "waits": [{"time": 10.0, "after": [{"robot": "b", "time": 10.0}]}]},
        {"robot": "b", "waits": [{"time": 10.0, "after": [{"robot": "a", "time": 10.0}]}]},
        {"robot": "c", "waits": [{"time": 10.0, "after": [{"robot": "a", "time": 10.0}]}]},
        {"robot": "d", "waits": [{"time": 10.0, "after": [{"robot": "a", "time": 0.0}]}]},
    ]
    run = execute_plan(problem, plan_from_wire(problem, deps))
    assert run.deadlocked == (0, 1, 2)
    assert np.isnan(run.completion[:3]).all() and run.completion[3] == 10.0
    passed_a = run.robot_times(problem, 0)
    assert passed_a[0] == 0.0 and np.isnan(passed_a[1])  # a stands at its point 10


def test_wire_plans_name_existing_robots_and_points() -> None:
    deps = [
        {"robot": "a", "waits": [{"time": 4.0, "after": [{"robot": "x", "time": 5.0}]}]},
        {"robot": "b", "waits": [{"time": 3.5, "after": [{"robot": "a", "time": 8.0}]}]},
    ]
    with pytest.raises(ProblemError) as err:
        plan_from_wire(TWO, deps)
    assert [e.loc for e in err.value.errors] == [
        ("body", "dependencies", 0, "waits", 0, "after", 0, "robot"),
        ("body", "dependencies", 1, "waits", 0, "time"),
    ]


# --- random problems and valid assignments -----------------------------------------------------


@cache
def _setup(kind: str, seed: int) -> tuple[Problem, Decoder, Evaluator]:
    if kind == "tiny":
        req = tiny_request(seed)
    else:
        req = small_problem(seed) if kind == "small" else stitched_problem(seed, 12, 3.0)
    problem = _problem(req)
    return problem, Decoder(problem, find_cliques(problem)), Evaluator(problem)


def _valid(kind: str, seed: int, draw: int) -> tuple[Problem, Evaluator, Assignments]:
    """A random problem and a random decoded (acyclic, density-feasible) assignment."""
    problem, decoder, evaluator = _setup(kind, seed)
    rng = np.random.default_rng(draw)
    bids = rng.exponential(size=(1, problem.n_nodes)) + 1e-3
    return problem, evaluator, decoder.decode(bids, rng.random((1, problem.n_conflicts)))


def _disturbances(problem: Problem, draw: int) -> list[Rate]:
    """Per robot up to three stops or slow-downs (one may be a late start)."""
    rng = np.random.default_rng(draw)
    start, end = problem.tp_time[problem.tp_start[:-1]], problem.free_time()
    rates = []
    for r in range(problem.n_robots):
        pieces = [
            (float(rng.uniform(start[r], end[r])), float(rng.exponential(2.0)), float(factor))
            for factor in rng.choice([0.0, 0.3, 0.8], size=rng.integers(0, 4))
        ]
        if rng.random() < 0.3:
            pieces.append((float(start[r]), float(rng.exponential(3.0)), 0.0))
        rates.append(Rate.of(pieces))
    return rates


def _least(problem: Problem, evaluator: Evaluator, assignments: Assignments) -> np.ndarray:
    """(P,) the evaluator's least updated time of every time point."""
    evaluation = evaluator.evaluate(assignments)
    return problem.tp_time + evaluator.delays_at(evaluation, 0, np.arange(problem.tp_time.size))


KINDS = st.sampled_from(["tiny", "small", "stitched"])
SEEDS = st.integers(0, 200)
DRAWS = st.integers(0, 2**32 - 1)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(kind=KINDS, seed=SEEDS, draw=DRAWS)
def test_the_wire_names_the_planned_points(kind: str, seed: int, draw: int) -> None:
    """Read back from the wire, a plan is its constraints, also when times were shifted."""
    problem, _, assignments = _valid(kind, seed, draw)
    shifted = replace(problem, tp_time=problem.tp_time + 7.25)
    plan = plan_from_wire(shifted, dependency_plan(shifted, assignments))
    wait, until = wait_constraints(problem, assignments)
    assert plan.wait.tolist() == wait.tolist() and plan.until.tolist() == until.tolist()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(kind=KINDS, seed=SEEDS, draw=DRAWS)
def test_undisturbed_times_are_the_least_updated_times(kind: str, seed: int, draw: int) -> None:
    problem, evaluator, assignments = _valid(kind, seed, draw)
    run = _run(problem, assignments)
    np.testing.assert_allclose(
        run.passed, _least(problem, evaluator, assignments), rtol=1e-9, atol=0
    )
    assert run.deadlocked == ()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(kind=KINDS, seed=SEEDS, draw=DRAWS)
def test_disturbed_runs_keep_every_dependency(kind: str, seed: int, draw: int) -> None:
    problem, _, assignments = _valid(kind, seed, draw)
    plan = plan_from_wire(problem, dependency_plan(problem, assignments))
    calm = execute_plan(problem, plan)
    run = execute_plan(problem, plan, _disturbances(problem, draw))
    assert run.deadlocked == ()
    assert np.all(run.passed[plan.wait] >= run.passed[plan.until])
    assert np.all(run.passed >= calm.passed * (1 - 1e-12))
    # Never faster than planned between consecutive points of a robot.
    step = np.diff(run.passed)[np.diff(problem.tp_robot) == 0]
    planned = np.diff(problem.tp_time)[np.diff(problem.tp_robot) == 0]
    assert np.all(step >= planned * (1 - 1e-9))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(kind=KINDS, seed=SEEDS, draw=DRAWS, moment=st.floats(0.0, 1.0))
def test_a_reschedule_plan_runs_at_the_residual_least_times(
    kind: str, seed: int, draw: int, moment: float
) -> None:
    """Stopped at a moment of its undisturbed run, the fleet re-schedules with the same
    assignment: the plan leaves out the past, and executing it gives the residual times."""
    problem, evaluator, assignments = _valid(kind, seed, draw)
    least = _least(problem, evaluator, assignments)
    now = float(np.quantile(least, moment))
    passed_until = np.full(problem.n_robots, -np.inf)
    done = least <= now
    np.maximum.at(passed_until, problem.tp_robot[done], problem.tp_time[done])
    progress = Progress(now, passed_until, np.zeros(problem.n_robots))
    residual = residual_problem(problem, progress, assignments)
    plan = plan_from_wire(residual, dependency_plan(residual, assignments))
    assert not residual.tp_passed[plan.wait].any() and not residual.tp_passed[plan.until].any()
    run = execute_plan(residual, plan)
    want = _least(residual, Evaluator(residual), assignments)
    np.testing.assert_allclose(run.passed, want, rtol=1e-9, atol=0)
