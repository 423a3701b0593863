"""The graph-form dependency plan: hand-built cases, re-scheduling, and a brute-force reference."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.dependency_plan import dependency_plan
from service.core.problem import Problem, problem_from_request
from service.core.schemas import DependencyTime, ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from tests.reference import tiny_request

EXCLUSIVE, FOLLOWING = False, True


def _problem(req: dict[str, Any]) -> Problem:
    return problem_from_request(ScheduleRequest.model_validate(req))


def _node(nid: str, enter: float, exit_: float) -> dict[str, Any]:
    return {"id": nid, "enter": enter, "exit": exit_, "density": 3}


# a: node a0 [0, 10], section [4, 8] -> points 0, 4, 8, 10; b: b0 [1, 9], section [3, 5].
TWO = _problem(
    {
        "robots": [
            {"id": "a", "nodes": [_node("a0", 0.0, 10.0)]},
            {"id": "b", "nodes": [_node("b0", 1.0, 9.0)]},
        ],
        "conflicts": [
            {"a": "a0", "b": "b0", "a_enter": 4.0, "a_exit": 8.0, "b_enter": 3.0, "b_exit": 5.0}
        ],
    }
)

# b waits at its node's enter (1) for a twice (a0 exits at 2, a1 at 7) and for c (exits at 3).
THREE = _problem(
    {
        "robots": [
            {"id": "a", "nodes": [_node("a0", 0.0, 2.0), _node("a1", 5.0, 7.0)]},
            {"id": "b", "nodes": [_node("b0", 1.0, 8.0)]},
            {"id": "c", "nodes": [_node("c0", 0.0, 3.0)]},
        ],
        "conflicts": [{"a": "c0", "b": "b0"}, {"a": "a1", "b": "b0"}, {"a": "a0", "b": "b0"}],
    }
)
A_FIRST = Assignments.single([True, True, True], [EXCLUSIVE] * 3)


def _wait(time: float, *after: tuple[str, float]) -> dict[str, Any]:
    return {"time": time, "after": [{"robot": r, "time": t} for r, t in after]}


def test_exclusive_waits_at_pair_enter_for_the_other_pair_exit() -> None:
    plan = dependency_plan(TWO, Assignments.single([True], [EXCLUSIVE]))
    assert plan == [{"robot": "a", "waits": []}, {"robot": "b", "waits": [_wait(3.0, ("a", 8.0))]}]


def test_following_waits_for_the_other_pair_enter() -> None:
    plan = dependency_plan(TWO, Assignments.single([True], [FOLLOWING]))
    assert plan[1] == {"robot": "b", "waits": [_wait(3.0, ("a", 4.0))]}


def test_other_direction_makes_a_wait() -> None:
    plan = dependency_plan(TWO, Assignments.single([False], [EXCLUSIVE]))
    assert plan == [{"robot": "a", "waits": [_wait(4.0, ("b", 5.0))]}, {"robot": "b", "waits": []}]


def test_each_robot_once_per_point_with_its_latest_point_in_request_order() -> None:
    plan = dependency_plan(THREE, A_FIRST)
    assert plan == [
        {"robot": "a", "waits": []},
        {"robot": "b", "waits": [_wait(1.0, ("a", 7.0), ("c", 3.0))]},
        {"robot": "c", "waits": []},
    ]


def test_rescheduling_names_points_by_planned_time_and_drops_the_past() -> None:
    # Progress shifts the times the evaluator works on; the plan still names planned times.
    shifted = replace(THREE, tp_time=THREE.tp_time + 100.0)
    assert dependency_plan(shifted, A_FIRST) == dependency_plan(THREE, A_FIRST)
    # a1 -> b0 realized: only a's earlier point (2) is left to wait for.
    realized = replace(THREE, realized=np.array([False, True, False]))
    assert dependency_plan(realized, A_FIRST)[1]["waits"] == [_wait(1.0, ("a", 2.0), ("c", 3.0))]
    # c passed its point 3: that wait is satisfied for good.
    c_passed = replace(THREE, tp_passed=THREE.tp_robot == 2)
    assert dependency_plan(c_passed, A_FIRST)[1]["waits"] == [_wait(1.0, ("a", 7.0))]
    # b passed its wait point: it never waits there again.
    b_passed = replace(THREE, tp_passed=THREE.tp_planned <= 1.0)
    assert dependency_plan(b_passed, A_FIRST)[1]["waits"] == []


def test_no_conflicts_gives_every_robot_an_empty_entry() -> None:
    problem = _problem({"robots": [{"id": "x", "nodes": [_node("x0", 0.0, 1.0)]}]})
    empty = np.zeros(0, dtype=bool)
    assert dependency_plan(problem, Assignments.single(empty, empty)) == [
        {"robot": "x", "waits": []}
    ]


# --- a brute-force reference ------------------------------------------------------------------


@cache
def _random_problem(kind: str, seed: int) -> Problem:
    if kind == "tiny":
        return _problem(tiny_request(seed))
    return _problem(small_problem(seed) if kind == "small" else stitched_problem(seed, 12, 3.0))


def _reference(
    problem: Problem, assignments: Assignments, passed_until: np.ndarray
) -> dict[tuple[str, float], dict[str, float]]:
    """{(robot, wait time): {robot waited for: its latest time}}, one conflict at a time.

    Reads pair times (planned) and robots, never time point indices; a point is passed
    when planned at or before its robot's ``passed_until``.
    """
    out: dict[tuple[str, float], dict[str, float]] = {}
    for c in range(problem.n_conflicts):
        if problem.realized[c]:
            continue
        nodes = (int(problem.conf_a[c]), int(problem.conf_b[c]))
        first = 0 if assignments.a_first[0, c] else 1
        fr, to = (int(problem.node_robot[nodes[s]]) for s in (first, 1 - first))
        wait = float(problem.pair_enter[c, 1 - first])
        leaves = problem.pair_enter if assignments.following[0, c] else problem.pair_exit
        until = float(leaves[c, first])
        if wait <= passed_until[to] or until <= passed_until[fr]:
            continue
        after = out.setdefault((problem.robot_ids[to], wait), {})
        after[problem.robot_ids[fr]] = max(after.get(problem.robot_ids[fr], -1.0), until)
    return out


def _as_reference(
    problem: Problem, plan: list[DependencyTime]
) -> dict[tuple[str, float], dict[str, float]]:
    """The plan in the reference's form, checking its order on the way."""
    assert [d["robot"] for d in plan] == list(problem.robot_ids)
    rank = {rid: r for r, rid in enumerate(problem.robot_ids)}
    out: dict[tuple[str, float], dict[str, float]] = {}
    for dep in plan:
        times = [w["time"] for w in dep["waits"]]
        assert times == sorted(set(times))  # path order, each point once
        for w in dep["waits"]:
            robots = [a["robot"] for a in w["after"]]
            assert robots and robots == sorted(set(robots), key=rank.__getitem__)
            out[(dep["robot"], w["time"])] = {a["robot"]: a["time"] for a in w["after"]}
    return out


@settings(max_examples=80, deadline=None, derandomize=True)
@given(
    kind=st.sampled_from(["tiny", "small", "stitched"]),
    seed=st.integers(0, 200),
    draw=st.integers(0, 2**32 - 1),
    rescheduled=st.booleans(),
)
def test_plan_equals_brute_force(kind: str, seed: int, draw: int, rescheduled: bool) -> None:
    """Any assignment (valid or not), fresh or with realized conflicts and passed points."""
    problem = _random_problem(kind, seed)
    rng = np.random.default_rng(draw)
    m = problem.n_conflicts
    assignments = Assignments(rng.random((1, m)) < 0.5, rng.random((1, m)) < 0.5)
    passed_until = np.full(problem.n_robots, -1.0)
    if rescheduled:
        starts, ends = problem.tp_planned[problem.tp_start[:-1]], problem.free_time()
        passed_until = rng.uniform(starts - 1.0, (starts + ends) / 2)  # (R,)
        problem = replace(
            problem,
            realized=rng.random(m) < 0.3,
            tp_passed=problem.tp_planned <= passed_until[problem.tp_robot],
        )
    plan = dependency_plan(problem, assignments)
    assert _as_reference(problem, plan) == _reference(problem, assignments, passed_until)
