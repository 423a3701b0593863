"""Priority search and re-insertion in turns: priority search goes on from any valid
answer (ranks that decode to it), and the turns return a valid answer no worse than
their start, within their deadline (hypothesis over tiny, fixed-direction, small,
stitched and conformance problems)."""

from __future__ import annotations

import json
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.check import check
from service.solvers import turns
from service.solvers.priority import PriorityConfig, answer_ranks, priority_search
from service.solvers.registry import SolveContext
from service.solvers.reinsert import ReinsertResult, reinsert_search
from service.solvers.tabu import plain_start
from service.solvers.turns import TurnsConfig, _next_share, take_turns
from tests.solvers.test_reinsert import CONTEXTS, DATA, SLOW, _context


def _assert_valid(ctx: SolveContext, answer: Assignments, cost: float) -> None:
    """``answer`` passes the checker and costs ``cost`` by the one evaluator."""
    checks = check(ctx.problem, ctx.cliques, answer)
    assert checks.acyclic[0] and checks.density[0] and checks.forced[0]
    assert cost == float(ctx.evaluator.evaluate(answer).costs[ctx.objective][0])


@settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=SLOW)
@given(ctx=CONTEXTS, seed=st.integers(0, 1000))
def test_priority_search_goes_on_from_any_valid_answer(ctx: SolveContext, seed: int) -> None:
    """Ranks of a re-insertion search's answer decode to its directions (fixed ones
    included), and priority search from them never returns worse or invalid."""
    if ctx.problem.n_conflicts == 0:
        return
    found = reinsert_search(ctx, plain_start(ctx), np.inf, seed, max_steps=10)
    ranks = answer_ranks(ctx, found.best)  # (V,)
    assert np.array_equal(ctx.decoder.directions(ranks[None]), found.best.a_first)
    cfg = PriorityConfig(max_rounds=20)
    best, cost, rounds = priority_search(ctx, 60.0, seed, cfg, (ranks, found.best, found.cost))
    assert rounds <= 20
    assert cost <= found.cost
    _assert_valid(ctx, best, cost)


@settings(max_examples=15, deadline=None, derandomize=True, suppress_health_check=SLOW)
@given(ctx=CONTEXTS, seed=st.integers(0, 1000))
def test_turns_return_a_valid_answer_no_worse_than_their_start(
    ctx: SolveContext, seed: int
) -> None:
    if ctx.problem.n_conflicts == 0:
        return
    start = plain_start(ctx)
    start_cost = float(ctx.evaluator.evaluate(start).costs[ctx.objective][0])
    config = TurnsConfig(turn_s=0.02, turn_share=1.0)
    found = take_turns(ctx, start, start_cost, time.monotonic() + 0.1, seed, config)
    assert found.cost <= start_cost
    _assert_valid(ctx, found.best, found.cost)


def test_turns_stop_at_their_deadline_and_take_several() -> None:
    line = (DATA / "wh_50.jsonl").read_text().splitlines()[0]
    ctx = _context(json.loads(line)["request"], "avg_completion")
    start = plain_start(ctx)
    cost = float(ctx.evaluator.evaluate(start).costs["avg_completion"][0])
    begin = time.monotonic()
    found = take_turns(ctx, start, cost, begin + 0.4, 0)
    assert time.monotonic() - begin < 0.4 + 0.1
    assert found.turns >= 3  # turns of at most a quarter of the time given


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    share=st.floats(0.1, 0.9),
    gains=st.tuples(st.floats(0, 1e3), st.floats(0, 1e3)),
    seconds=st.tuples(st.floats(1e-4, 1.0), st.floats(1e-4, 1.0)),
)
def test_the_split_moves_toward_the_search_that_paid(
    share: float, gains: tuple[float, float], seconds: tuple[float, float]
) -> None:
    """The next split stays within least_share of either end, is unchanged where neither
    search took anything off, and lies between the last split and priority search's part
    of the cost taken off per second."""
    config = TurnsConfig()
    nxt = _next_share(config, share, gains, seconds)
    assert config.least_share <= nxt <= 1 - config.least_share
    rate_r, rate_p = gains[0] / seconds[0], gains[1] / seconds[1]
    if rate_r + rate_p == 0:
        assert nxt == share
        return
    low, high = sorted((share, rate_p / (rate_r + rate_p)))
    least, most = config.least_share, 1 - config.least_share
    assert min(max(low, least), most) - 1e-12 <= nxt <= min(max(high, least), most) + 1e-12


def test_reinsertion_cools_over_the_first_share_of_the_turns(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Every re-insertion search of the turns gets the same cooling span: from the turns'
    start over cooling_share of their time (then it searches cold to the deadline)."""
    spans: list[tuple[float, float]] = []

    def recorded(*args, cooling, **kwargs):
        spans.append(cooling)
        return reinsert_search(*args, cooling=cooling, **kwargs)

    monkeypatch.setattr(turns, "reinsert_search", recorded)
    line = (DATA / "wh_50.jsonl").read_text().splitlines()[0]
    ctx = _context(json.loads(line)["request"], "avg_completion")
    start = plain_start(ctx)
    cost = float(ctx.evaluator.evaluate(start).costs["avg_completion"][0])
    begin = time.monotonic()
    take_turns(ctx, start, cost, begin + 0.4, 0, TurnsConfig(cooling_share=0.25))
    assert len(spans) >= 3 and len(set(spans)) == 1
    warm_from, cold_at = spans[0]
    assert begin <= warm_from < begin + 0.01
    assert abs((cold_at - warm_from) - 0.25 * (begin + 0.4 - warm_from)) < 1e-9


def test_priority_search_waits_until_reinsertion_is_cold(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """While re-insertion's annealing is hot, the turns are re-insertion's alone; once it
    is cold, priority search takes its part of each turn (and from the start where
    ``priority_while_hot``)."""
    calls: list[float] = []

    def recorded(*args, **kwargs):
        calls.append(time.monotonic())
        return priority_search(*args, **kwargs)

    monkeypatch.setattr(turns, "priority_search", recorded)
    line = (DATA / "wh_50.jsonl").read_text().splitlines()[0]
    ctx = _context(json.loads(line)["request"], "avg_completion")
    start = plain_start(ctx)
    cost = float(ctx.evaluator.evaluate(start).costs["avg_completion"][0])
    reinsert_search(ctx, start, np.inf, 0, max_steps=2)  # compiled before the clock runs
    priority_search(ctx, 0.01, 0, start=(answer_ranks(ctx, start), start, cost))
    config = TurnsConfig(turn_s=0.05, cooling_share=0.5)
    begin = time.monotonic()
    found = take_turns(ctx, start, cost, begin + 0.6, 0, config)
    assert calls and min(calls) >= begin + 0.3  # cold from half of the time on
    assert found.turns > len(calls)  # re-insertion alone in the hot turns
    calls.clear()
    begin = time.monotonic()
    take_turns(ctx, start, cost, begin + 0.6, 0, replace(config, priority_while_hot=True))
    assert calls and min(calls) < begin + 0.1


def _wh50() -> tuple[SolveContext, Assignments, float]:
    line = (DATA / "wh_50.jsonl").read_text().splitlines()[0]
    ctx = _context(json.loads(line)["request"], "avg_completion")
    start = plain_start(ctx)
    return ctx, start, float(ctx.evaluator.evaluate(start).costs["avg_completion"][0])


@pytest.mark.parametrize(
    ("workers", "chains", "expected"), [(1, None, 1), (2, None, 2), (2, 1, 1), (1, 3, 3)]
)
def test_a_turn_runs_one_reinsertion_chain_per_core_each_with_its_own_seed(
    workers: int, chains: int | None, expected: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One chain per core the solve has (``ctx.workers``) unless the config says how many;
    chain 0 has the turn's seed (one chain: the single search's), the others seeds of their
    own; the turns still return a valid answer no worse than their start."""
    seeds: list[int] = []

    def recorded(ctx, start, until, seed, **kwargs):
        seeds.append(seed)
        return reinsert_search(ctx, start, until, seed, **kwargs)

    monkeypatch.setattr(turns, "reinsert_search", recorded)
    ctx, start, cost = _wh50()
    ctx = replace(ctx, workers=workers)
    config = TurnsConfig(turn_s=0.05, cooling_share=1.0, chains=chains)
    found = take_turns(ctx, start, cost, time.monotonic() + 0.3, 7, config)
    assert found.cost <= cost
    _assert_valid(ctx, found.best, found.cost)
    assert len(seeds) == expected * found.turns
    by_turn = [sorted(seeds[k : k + expected]) for k in range(0, len(seeds), expected)]
    stride = turns.CHAIN_SEED_STRIDE
    assert by_turn == [[7 + t + k * stride for k in range(expected)] for t in range(found.turns)]


def test_a_turn_goes_on_from_its_cheapest_chain_the_first_of_equals(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Of a turn's chains the cheapest result goes on; of equals, chain 0's."""
    ctx, start, cost = _wh50()
    costs = {0: 5.0, turns.CHAIN_SEED_STRIDE: 3.0, 2 * turns.CHAIN_SEED_STRIDE: 3.0}

    def fake(ctx, start, until, seed, **kwargs):
        return ReinsertResult(start, costs[seed], seed)  # steps: which chain

    monkeypatch.setattr(turns, "reinsert_search", fake)
    with ThreadPoolExecutor(3) as pool:
        found = turns._reinsertion(ctx, start, time.monotonic(), 0, (0.0, 1.0), pool, 3)
    assert (found.cost, found.steps) == (3.0, turns.CHAIN_SEED_STRIDE)
    costs[0] = 3.0
    with ThreadPoolExecutor(3) as pool:
        found = turns._reinsertion(ctx, start, time.monotonic(), 0, (0.0, 1.0), pool, 3)
    assert found.steps == 0
