"""FCFS: always valid, deterministic, first to arrive passes first."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from service.core.check import check
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext, get_solver
from tests.reference import tiny_request, trap_request


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
