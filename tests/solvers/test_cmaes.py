"""cmaes: valid, never worse than FCFS, deterministic for a seed, within its time limit."""

from __future__ import annotations

import time

import numpy as np
import pytest

from service.core.check import check
from service.learning.generate import stitched_problem
from service.solvers.cmaes import CmaesConfig, cmaes, cmaes_search
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext, get_solver
from tests.solvers.common import context, cost

OBJECTIVES = ("avg_completion", "sync_completion")
SMALL = CmaesConfig(max_evaluations=300)  # a few generations: enough to test, fast


def _ctx(seed: int, objective: str, time_limit_s: float = 30.0, n_robots: int = 20) -> SolveContext:
    return context(stitched_problem(seed, n_robots, 3.0), objective, time_limit_s, seed=seed)


def _fcfs_cost(ctx: SolveContext) -> float:
    return cost(ctx, fcfs(ctx))


def test_registered_as_cmaes() -> None:
    assert get_solver("cmaes") is cmaes


@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize("seed", [0, 1])
def test_valid_never_worse_than_fcfs_and_deterministic(seed: int, objective: str) -> None:
    ctx = _ctx(seed, objective)
    best, found, evaluated = cmaes_search(ctx, SMALL)
    assert 1 < evaluated <= SMALL.max_evaluations + 100  # the last generation may overrun
    assert check(ctx.problem, ctx.cliques, best).ok.tolist() == [True]
    assert found == pytest.approx(float(ctx.evaluator.evaluate(best).costs[objective][0]))
    assert found <= _fcfs_cost(ctx)
    again, cost_again, evaluated_again = cmaes_search(_ctx(seed, objective), SMALL)
    assert (cost_again, evaluated_again) == (found, evaluated)
    assert np.array_equal(again.a_first, best.a_first)
    assert np.array_equal(again.following, best.following)


def test_full_covariance_below_the_threshold() -> None:
    ctx = _ctx(0, "avg_completion", n_robots=5)  # a dozen dimensions
    assert ctx.problem.n_nodes + ctx.problem.n_conflicts <= SMALL.full_covariance_max_dim
    best, found, _ = cmaes_search(ctx, SMALL)
    assert check(ctx.problem, ctx.cliques, best).ok.tolist() == [True]
    assert found <= _fcfs_cost(ctx)


def test_solver_reports_its_samples() -> None:
    ctx = _ctx(2, "avg_completion")
    out = cmaes(ctx)
    assert out.samples is not None and out.samples > 1
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_time_limit_is_honoured(objective: str) -> None:
    ctx = _ctx(3, objective, time_limit_s=0.05, n_robots=80)
    _fcfs_cost(ctx)  # compile the evaluator outside the clock
    start = time.perf_counter()
    best, found, _ = cmaes_search(ctx, CmaesConfig(max_evaluations=10**9))
    assert time.perf_counter() - start < ctx.time_limit_s + 1.0
    assert check(ctx.problem, ctx.cliques, best).ok.tolist() == [True]
    assert found <= _fcfs_cost(ctx)


def test_no_generation_starts_that_would_end_past_the_limit(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each generation is timed; the next starts only where one as long ends in time (at
    250 robots a generation takes 0.2-0.35 s, and 0.5-s requests ran 0.78-0.92 s). Here
    decoding takes 0.3 s of a 0.5-s limit: one generation, then the answer."""
    import service.solvers.cmaes as module

    decode = module.decode_candidates

    def slow_decode(*args: object, **kwargs: object) -> object:
        time.sleep(0.3)
        return decode(*args, **kwargs)

    ctx = _ctx(1, "avg_completion", time_limit_s=0.5)
    cmaes(_ctx(0, "avg_completion", time_limit_s=0.1))  # compiled before the clock
    monkeypatch.setattr(module, "decode_candidates", slow_decode)
    start = time.perf_counter()
    out = cmaes(ctx)
    assert time.perf_counter() - start < 0.5
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]
