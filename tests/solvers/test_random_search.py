"""random: valid, deterministic for a seed, within its sample count and time limit."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest

from service.core.check import check
from service.core.decode import decode_candidates
from service.learning.generate import stitched_problem
from service.solvers.fcfs import fcfs
from service.solvers.random_search import BATCH, DEFAULT_SAMPLES, random_search
from service.solvers.registry import SolveContext, get_solver
from tests.solvers.common import context, cost

OBJECTIVES = ("avg_completion", "sync_completion")


def _ctx(
    seed: int, objective: str, samples: int | None = None, time_limit_s: float = 30.0
) -> SolveContext:
    return context(
        stitched_problem(seed, 20, 3.0), objective, time_limit_s, seed=seed, samples=samples
    )


def test_registered_as_random() -> None:
    assert get_solver("random") is random_search


@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize("seed", [0, 1])
def test_valid_and_deterministic(seed: int, objective: str) -> None:
    ctx = _ctx(seed, objective)
    out = random_search(ctx)
    assert out.samples == DEFAULT_SAMPLES
    assert out.assignment.n_samples == 1
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]
    again = random_search(_ctx(seed, objective))
    assert cost(ctx, again) == cost(ctx, out)
    assert np.array_equal(again.assignment.a_first, out.assignment.a_first)
    assert np.array_equal(again.assignment.following, out.assignment.following)


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_one_sample_evaluates_one_row(objective: str) -> None:
    ctx = _ctx(2, objective, samples=1)
    out = random_search(ctx)
    assert out.samples == 1
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]


def test_more_samples_never_worse() -> None:
    few = _ctx(3, "avg_completion", samples=64)  # exactly the first batch of the larger run
    many = _ctx(3, "avg_completion", samples=300)
    out = random_search(many)
    assert out.samples == 300
    assert cost(many, out) <= cost(few, random_search(few))


def test_time_limit_is_honoured() -> None:
    ctx = _ctx(0, "sync_completion", samples=10**6, time_limit_s=0.05)
    ctx.evaluator.evaluate(fcfs(ctx).assignment)  # compile the evaluator outside the clock
    start = time.perf_counter()
    out = random_search(ctx)
    assert time.perf_counter() - start < ctx.time_limit_s + 1.0
    assert 0 < out.samples < 10**6
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]


@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize("samples", [1, 40, 64, 100])
def test_chunks_give_the_answer_of_whole_batches(objective: str, samples: int) -> None:
    """Rows are decoded in chunks sized by the time left (the first row alone): the
    answer is the cheapest of the same rows as decoding each drawn batch whole."""
    ctx = _ctx(4, objective, samples=samples)
    rng = np.random.default_rng(ctx.seed)
    best, best_cost = None, np.inf
    for size in [min(BATCH, samples - lo) for lo in range(0, samples, BATCH)]:
        bids = 1.0 - rng.random((size, ctx.problem.n_nodes))
        scores = rng.random((size, ctx.problem.n_conflicts))
        candidates = decode_candidates(ctx.decoder, bids, scores, objective)
        costs = ctx.evaluator.evaluate(candidates).costs[objective]
        if costs.min() < best_cost:
            best, best_cost = candidates.take(int(np.argmin(costs))), float(costs.min())
    out = random_search(ctx)
    assert out.samples == samples
    assert np.array_equal(out.assignment.a_first, best.a_first)
    assert np.array_equal(out.assignment.following, best.following)


def test_a_slow_row_still_ends_near_the_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    """Where one row takes 40 ms (0.58 s for a batch of 64 rows at 250 robots), a
    0.1-s limit gets a few rows, not a batch."""
    import service.solvers.random_search as module

    decode = module.decode_candidates

    def slow_decode(decoder: Any, bids: np.ndarray, *args: Any) -> Any:
        time.sleep(0.04 * bids.shape[0])
        return decode(decoder, bids, *args)

    ctx = _ctx(5, "avg_completion", time_limit_s=0.1)
    random_search(_ctx(5, "avg_completion", samples=2))  # compiled outside the clock
    monkeypatch.setattr(module, "decode_candidates", slow_decode)
    start = time.perf_counter()
    out = random_search(ctx)
    assert time.perf_counter() - start < 0.1 + 0.05
    assert 1 <= out.samples <= 3
