"""FCFS: always valid, deterministic, first to arrive passes first; its blends toward robot
priorities, the searches' plain start."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from service.core.assignment import Assignments
from service.core.check import check
from service.core.problem import problem_from_request
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from service.solvers.fcfs import (
    COMPLETION_BLENDS,
    EXIT_BLENDS,
    blended_priorities,
    fcfs,
    fcfs_priorities,
)
from service.solvers.registry import SolveContext, SolverOutput, get_solver
from service.solvers.tabu import plain_start
from tests.reference import tiny_request, trap_request
from tests.solvers.common import context, cost


def _context(req: dict[str, Any], seed: int = 0, time_limit_s: float = 5.0) -> SolveContext:
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    return SolveContext(problem, "avg_completion", time_limit_s, seed=seed)


REQUESTS = (
    [("small", s, small_problem(s)) for s in range(20)]
    + [("tiny", s, tiny_request(s)) for s in range(20)]
    + [("stitched", s, stitched_problem(s, 80, 3.0)) for s in range(3)]
    + [("trap", 0, trap_request())]
)


@pytest.mark.parametrize(
    "req", [r for _, _, r in REQUESTS], ids=[f"{k}-{s}" for k, s, _ in REQUESTS]
)
def test_fcfs_is_valid(req: dict[str, Any]) -> None:
    ctx = _context(req)
    out = fcfs(ctx)
    assert not out.optimal
    assert out.assignment.a_first.shape == (1, ctx.problem.n_conflicts)
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]
    # The node entering first passes first (equal enter times: the lower node index).
    p = ctx.problem
    ea, eb = p.node_enter[p.conf_a], p.node_enter[p.conf_b]
    expect = (ea < eb) | ((ea == eb) & (p.conf_a < p.conf_b))
    np.testing.assert_array_equal(out.assignment.a_first[0], expect)
    # Following type wherever no budget forbids it; never inside a zero-budget clique.
    following = out.assignment.following[0]
    assert not np.any(following & ctx.cliques.forbidden())
    if not ctx.cliques.binding().any():
        np.testing.assert_array_equal(following, ~ctx.cliques.forbidden())


def test_fcfs_is_deterministic() -> None:
    for seed in range(10):
        req = small_problem(seed)
        first = fcfs(_context(req, seed=0, time_limit_s=5.0)).assignment
        again = fcfs(_context(req, seed=12345, time_limit_s=0.001)).assignment
        np.testing.assert_array_equal(first.a_first, again.a_first)
        np.testing.assert_array_equal(first.following, again.following)


def test_fcfs_grants_following_earliest_first() -> None:
    # A triangle of density-2 nodes: budget h(2) = 2 of 3 conflicts. The conflict whose
    # earlier side enters last (v1-v2, first pair enter 2) is the one left exclusive.
    req = {
        "robots": [
            {
                "id": f"r{i}",
                "nodes": [{"id": f"v{i}", "enter": float(i), "exit": 10.0, "density": 2}],
            }
            for i in range(3)
        ],
        "conflicts": [{"a": "v0", "b": "v1"}, {"a": "v1", "b": "v2"}, {"a": "v0", "b": "v2"}],
    }
    out = fcfs(_context(req))
    assert out.assignment.following[0].tolist() == [True, False, True]
    assert out.assignment.a_first[0].tolist() == [True, True, True]


def test_fcfs_is_registered() -> None:
    assert get_solver("fcfs") is fcfs


@pytest.mark.parametrize(
    "req", [r for _, _, r in REQUESTS], ids=[f"{k}-{s}" for k, s, _ in REQUESTS]
)
def test_blended_priorities_rank_along_paths_and_include_fcfs(req: dict[str, Any]) -> None:
    p = _context(req).problem
    ranks, scores = blended_priorities(p)
    rows = len(COMPLETION_BLENDS) + len(EXIT_BLENDS)
    assert ranks.shape == (rows, p.n_nodes) and scores.shape == (rows, p.n_conflicts)
    same_robot = p.node_robot[1:] == p.node_robot[:-1]  # (V-1,) v and v + 1 on one path
    assert np.all(np.diff(ranks, axis=1)[:, same_robot] >= 0)  # what the decoder needs
    fcfs_ranks, fcfs_scores = fcfs_priorities(p)
    np.testing.assert_array_equal(ranks[COMPLETION_BLENDS.index(0.0)], fcfs_ranks)
    np.testing.assert_array_equal(ranks[-1], p.node_exit)  # exit blend mu = 1
    np.testing.assert_array_equal(scores, np.repeat(fcfs_scores[None], rows, axis=0))


@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize(
    "req", [r for _, _, r in REQUESTS], ids=[f"{k}-{s}" for k, s, _ in REQUESTS]
)
def test_the_plain_start_is_valid_and_no_worse_than_fcfs(
    req: dict[str, Any], objective: str
) -> None:
    ctx = context(req, objective)
    start = plain_start(ctx)
    assert check(ctx.problem, ctx.cliques, start).ok.tolist() == [True]
    assert cost(ctx, SolverOutput(start)) <= cost(ctx, fcfs(ctx))


def test_a_blend_beats_fcfs_where_robots_queue_for_one_corridor() -> None:
    """Three robots for one exclusive corridor: the first to arrive holds it for 10 s on a
    long trip, two short trips arrive just after and hold it 1 s each. FCFS makes both
    short trips wait 10 s; a blend toward completion lets them pass first (the long trip
    waits 2 s), lowering the average completion."""

    def robot(rid: str, enter: float, exit_: float, goal: float) -> dict[str, Any]:
        node = {"id": f"{rid}/0", "enter": enter, "exit": exit_, "density": 1}
        return {"id": rid, "nodes": [node], "goal_time": goal}

    req = {
        "robots": [
            robot("long", 0.0, 10.0, 100.0),
            robot("s1", 0.5, 1.5, 3.0),
            robot("s2", 0.7, 1.7, 3.2),
        ],
        "conflicts": [
            {"a": "long/0", "b": "s1/0"},
            {"a": "long/0", "b": "s2/0"},
            {"a": "s1/0", "b": "s2/0"},
        ],
    }
    ctx = context(req, "avg_completion")
    assert cost(ctx, SolverOutput(plain_start(ctx))) < cost(ctx, fcfs(ctx)) - 5.0


def test_the_plain_start_is_found_once_per_context_and_warm_start() -> None:
    ctx = context(stitched_problem(1, 40, 3.0), "avg_completion")
    first = plain_start(ctx)
    assert plain_start(ctx) is first  # the portfolio and its first stage share it
    ctx.warm = Assignments(first.a_first.copy(), first.following.copy())
    again = plain_start(ctx)  # a new warm start: found again (and no worse)
    assert ctx.__dict__["_plain_start"][0] is ctx.warm
    assert cost(ctx, SolverOutput(again)) <= cost(ctx, SolverOutput(first))


def _corridor_robot(rid: str, enter: float, exit_: float, goal: float, density: int) -> dict:
    node = {"id": f"{rid}/0", "enter": enter, "exit": exit_, "density": density}
    return {"id": rid, "nodes": [node], "goal_time": goal}


def test_the_start_spends_a_following_budget_where_it_spares_most() -> None:
    """Four robots in one corridor of density 2 (two following-type conflicts at most):
    FCFS's scores give both to the earliest arrival's conflicts (a-b, a-c), and c then
    waits for b to leave; the start gives them where they spare most (a-b, b-c: a convoy)."""
    req = {
        "robots": [
            _corridor_robot("a", 0.0, 10.0, 12.0, 2),
            _corridor_robot("b", 0.5, 10.5, 12.5, 2),
            _corridor_robot("c", 1.0, 11.0, 13.0, 2),
            _corridor_robot("d", 30.0, 40.0, 42.0, 2),
        ],
        "conflicts": [
            {"a": x, "b": y}
            for i, x in enumerate(["a/0", "b/0", "c/0", "d/0"])
            for y in ["a/0", "b/0", "c/0", "d/0"][i + 1 :]
        ],
    }
    ctx = context(req, "avg_completion")
    start = plain_start(ctx)
    assert check(ctx.problem, ctx.cliques, start).ok.tolist() == [True]
    following = {
        (int(ctx.problem.conf_a[c]), int(ctx.problem.conf_b[c]))
        for c in np.flatnonzero(start.following[0])
    }
    assert ctx.problem.n_conflicts == 6 and following == {(0, 1), (1, 2)}
    assert cost(ctx, SolverOutput(start)) < cost(ctx, fcfs(ctx)) - 0.1
