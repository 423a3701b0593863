"""tabu, priority_tabu and bbts: valid, never worse than FCFS, deterministic, within the time limit.

On tiny problems the backtracking tree has fewer than 1,000 leaves, so bbts
sees every valid assignment and must match the brute-force optimum.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core import evaluate
from service.core.check import check
from service.core.retype import refit_types
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.generate import stitched_problem
from service.solvers.bbts import LEAVES, bbts
from service.solvers.dispatch import DispatchPolicy, dispatch
from service.solvers.fcfs import blended_priorities, fcfs
from service.solvers.priority import (
    PriorityConfig,
    RankFlips,
    priority_search,
    priority_tabu,
    reversed_in,
    shifted_flips,
)
from service.solvers.registry import SolveContext
from service.solvers.tabu import TabuConfig, tabu, tabu_search
from tests.reference import feasible_assignments, fix_directions, reference_problem, tiny_request
from tests.solvers.common import context, cost
from tests.worlds import congested_warehouse, world_request

SOLVERS = {"tabu": tabu, "priority_tabu": priority_tabu, "bbts": bbts}


def _ctx(req: dict[str, Any], objective: str, time_limit_s: float = 30.0, seed: int = 0):
    return context(req, objective, time_limit_s, seed=seed)


@pytest.mark.parametrize("name", SOLVERS)
@pytest.mark.parametrize("objective", ["avg_completion", "sync_completion"])
@pytest.mark.parametrize("seed", range(3))
def test_valid_and_never_worse_than_fcfs(name: str, objective: str, seed: int) -> None:
    ctx = _ctx(stitched_problem(seed, 25, 3.0), objective)
    out = SOLVERS[name](ctx)
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]
    assert cost(ctx, out) <= cost(ctx, fcfs(ctx)) + 1e-9


@pytest.mark.parametrize("name", SOLVERS)
def test_deterministic_for_a_seed(name: str) -> None:
    req = stitched_problem(5, 30, 4.0)
    first = SOLVERS[name](_ctx(req, "avg_completion", seed=3))
    again = SOLVERS[name](_ctx(req, "avg_completion", seed=3))
    assert np.array_equal(first.assignment.a_first, again.assignment.a_first)
    assert np.array_equal(first.assignment.following, again.assignment.following)


@pytest.mark.parametrize("name", SOLVERS)
def test_time_limit_is_honoured(name: str) -> None:
    ctx = _ctx(stitched_problem(1, 250, 4.0), "avg_completion", time_limit_s=0.05)
    SOLVERS[name](_ctx(stitched_problem(0, 10, 2.0), "avg_completion"))  # compile first
    start = time.perf_counter()
    out = SOLVERS[name](ctx)
    assert time.perf_counter() - start < 0.05 + 1.0
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]


def test_tabu_counts_the_time_its_start_took(monkeypatch: pytest.MonkeyPatch) -> None:
    """The start (FCFS's cheapest blend, 0.14 s at 250 robots) is searched within the time
    limit, not before it: a start that takes the whole limit leaves no tabu iteration."""
    import service.solvers.tabu as module

    find_start = module.plain_start

    def slow_start(ctx: SolveContext) -> Any:
        time.sleep(ctx.time_limit_s)
        return find_start(ctx)

    ctx = _ctx(stitched_problem(2, 30, 4.0), "avg_completion", time_limit_s=0.2)
    monkeypatch.setattr(module, "plain_start", slow_start)
    out = tabu(ctx)
    assert out.detail == "0 tabu iterations"
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]


def test_tabu_improves_a_poor_start_and_counts_its_iterations() -> None:
    ctx = _ctx(stitched_problem(2, 30, 4.0), "avg_completion")
    start = fcfs(ctx).assignment
    cfg = TabuConfig(max_iterations=40, patience=1000)
    best, found, iterations = tabu_search(ctx, start, cfg)
    assert iterations == 40
    assert found < cost(ctx, fcfs(ctx))
    assert found == pytest.approx(float(ctx.evaluator.evaluate(best).costs[ctx.objective][0]))


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_priority_search_improves_the_cheapest_blend(objective: str) -> None:
    ctx = _ctx(stitched_problem(4, 60, 4.0), objective)
    ranks, scores = blended_priorities(ctx.problem)
    blends = ctx.evaluator.evaluate(ctx.decoder.decode_ranks(ranks, scores)).costs[objective]
    cfg = PriorityConfig(patience=40)
    best, found, rounds = priority_search(ctx, 30.0, seed=1, cfg=cfg)
    assert check(ctx.problem, ctx.cliques, best).ok.tolist() == [True]
    assert found == pytest.approx(float(ctx.evaluator.evaluate(best).costs[objective][0]))
    assert found <= blends.min() + 1e-9
    assert rounds >= cfg.patience  # stopped on patience, not on time
    again = priority_search(ctx, 30.0, seed=1, cfg=cfg)
    assert again[1] == found and again[2] == rounds


@pytest.mark.parametrize("name", ["tabu", "priority_tabu"])
def test_two_cores_change_no_step_of_the_search(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """A solve given two cores evaluates its batches in two threads: the same search,
    step for step, as with one (the same answer when it stops on its own rules)."""
    req = stitched_problem(7, 120, 4.0)
    one = SOLVERS[name](_ctx(req, "avg_completion", seed=2))
    monkeypatch.setattr(evaluate, "MIN_THREAD_WORK", 1)  # split every batch of two or more
    two = SOLVERS[name](context(req, "avg_completion", 30.0, seed=2, workers=2))
    assert two.detail == one.detail  # rounds and iterations
    assert np.array_equal(two.assignment.a_first, one.assignment.a_first)
    assert np.array_equal(two.assignment.following, one.assignment.following)


def test_priority_search_refits_its_types_every_refit_every_rounds() -> None:
    """On a congested warehouse, the round that refits comes out no dearer than the
    refit of the rounds before it, which is cheaper than they were: the refit runs, and
    only ever lowers the cost."""
    ctx = context(congested_warehouse(), "avg_completion", seed=0)
    rounds = 20
    before, before_cost, _ = priority_search(
        ctx, 30.0, seed=0, cfg=PriorityConfig(patience=10**6, max_rounds=rounds - 1, refit_every=0)
    )
    refit_cost = refit_types(ctx.decoder, ctx.evaluator, ctx.objective, before)[1]
    assert refit_cost < before_cost - 1e-6
    cfg = PriorityConfig(patience=10**6, max_rounds=rounds, refit_every=rounds)
    best, found, _ = priority_search(ctx, 30.0, seed=0, cfg=cfg)
    assert found <= refit_cost + 1e-9
    assert found == pytest.approx(float(ctx.evaluator.evaluate(best).costs[ctx.objective][0]))
    assert check(ctx.problem, ctx.cliques, best).ok.tolist() == [True]


def test_priority_search_steps_wide_from_its_size_threshold() -> None:
    """From wide_from conflicts the offsets are drawn with wide_step, below with step: the
    same search, round for round, as the other step set as the one used."""
    ctx = context(world_request("wh_two_way", 25, 60), "avg_completion", seed=0)
    n = ctx.problem.n_conflicts
    fixed = PriorityConfig(patience=10**6, max_rounds=30)

    def run(cfg: PriorityConfig) -> tuple:
        best, found, rounds = priority_search(ctx, 30.0, seed=3, cfg=cfg)
        return best.a_first.tobytes(), best.following.tobytes(), found, rounds

    wide = replace(fixed, wide_from=n, wide_step=0.3)
    assert run(wide) == run(replace(fixed, step=0.3, wide_from=n + 1))
    assert run(replace(wide, wide_from=n + 1)) == run(replace(fixed, wide_from=n + 1))
    assert run(wide) != run(replace(wide, wide_from=n + 1))  # the step moves the search


def test_priority_search_moves_many_conflicts_at_once() -> None:
    """On a congested 120-robot problem, robot moves improve on every blend."""
    ctx = _ctx(stitched_problem(6, 120, 4.0), "avg_completion")
    ranks, scores = blended_priorities(ctx.problem)
    blends = ctx.evaluator.evaluate(ctx.decoder.decode_ranks(ranks, scores)).costs
    _, found, _ = priority_search(ctx, 30.0, seed=0, cfg=PriorityConfig(patience=60))
    assert found < blends["avg_completion"].min()


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    robots=st.integers(3, 40),
    share=st.sampled_from([0.0, 0.2, 0.6]),
    scale=st.sampled_from([0.01, 0.1, 1.0]),
)
def test_shifted_flips_equal_decoding_the_shifted_ranks_whole(
    seed: int, robots: int, share: float, scale: float
) -> None:
    """Only the conflicts of nodes whose repaired rank moved are looked at, yet every
    draw's directions are the decoder's for its whole ranks, fixed directions included."""
    ctx = _ctx(fix_directions(stitched_problem(seed, robots, 3.0), seed, share), "avg_completion")
    p, rng = ctx.problem, np.random.default_rng(seed)
    blends = blended_priorities(p)[0]  # (K, V) non-decreasing along every path
    base = blends[rng.integers(len(blends))]  # (V,)
    span = float(p.node_exit.max() - p.node_enter.min())
    offsets = rng.normal(0.0, scale * span, p.n_robots)  # (R,) a current best's offsets
    current = (base + offsets[p.node_robot])[None]  # (1, V)
    ranks = ctx.decoder.repair(current)  # (1, V)
    best = ctx.decoder.decode_ranks(current, np.zeros((1, p.n_conflicts)))
    robot = rng.integers(p.n_robots, size=12)  # (D,)
    shifted = offsets[robot] + rng.normal(0.0, scale * span, robot.size)  # (D,)
    moved, start, flipped, moved_ranks = shifted_flips(
        ctx, RankFlips(p), robot, shifted, base, offsets, ranks[0], best, robot.size
    )
    pairs = zip(start[:-1], start[1:], strict=True)
    a_first = np.concatenate(
        [reversed_in(best, flipped[lo:hi]).a_first for lo, hi in pairs]
        or [np.zeros((0, p.n_conflicts), dtype=bool)]
    )  # (C, M)
    trial = np.repeat(offsets[None], robot.size, axis=0)  # (D, R)
    trial[np.arange(robot.size), robot] = shifted
    whole = ctx.decoder.directions(base[None] + trial[:, p.node_robot])  # (D, M)
    assert np.array_equal(moved, np.flatnonzero((whole != best.a_first).any(axis=1)))
    assert np.array_equal(a_first, whole[moved])
    repaired = ctx.decoder.repair(base[None] + trial[moved][:, p.node_robot])  # (C, V)
    assert np.array_equal(moved_ranks, repaired)


def test_bbts_stops_at_its_leaf_budget() -> None:
    ctx = _ctx(stitched_problem(3, 40, 3.0), "avg_completion")
    assert bbts(ctx).samples == LEAVES


@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize("seed", range(12))
def test_bbts_finds_the_brute_force_optimum_on_tiny_problems(objective: str, seed: int) -> None:
    req = tiny_request(seed, objective)
    candidates = feasible_assignments(reference_problem(req))
    assert len(candidates) < LEAVES  # the whole tree is enumerated
    ctx = _ctx(req, objective)
    out = bbts(ctx)
    assert out.samples == len(candidates)
    assert cost(ctx, out) == pytest.approx(min(c.costs[objective] for c in candidates))


class _SlowClock:
    """A ``time`` module whose every reading is a second after the last."""

    def __init__(self) -> None:
        self.now = 0.0

    def perf_counter(self) -> float:
        self.now += 1.0
        return self.now


def test_bbts_without_its_first_leaf_in_time_gives_no_answer_and_the_dispatcher_falls_back(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Enumeration steps are timed and the limit checked between them: where the first
    leaf (1,000 conflicts decided) is not reached when the limit has passed, bbts gives no
    answer instead of running on (a 250-robot warehouse's first leaf took 8-9 s), and FCFS
    answers for it."""
    monkeypatch.setattr("service.solvers.bbts.time", _SlowClock())
    request = {**stitched_problem(1, 250, 4.0), "objective": "avg_completion"}
    assert bbts(context(request, "avg_completion", 0.5)) is None
    body = {**request, "options": {"solver": "bbts", "time_limit_s": 0.5}}
    answer = dispatch(ScheduleRequest.model_validate(body), DispatchPolicy())
    assert (answer.solver.name, answer.solver.fallback_from) == ("fcfs", "bbts")
    assert answer.checks.acyclic and answer.checks.density and answer.checks.forced


def test_bbts_when_the_tree_ends_exactly_at_a_batch_boundary(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    req = tiny_request(5)
    leaves = len(feasible_assignments(reference_problem(req)))
    monkeypatch.setattr("service.solvers.bbts.BATCH", leaves)
    ctx = _ctx(req, "avg_completion")
    out = bbts(ctx)
    assert out.samples == leaves
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]


def test_tabu_search_without_time_builds_nothing_and_returns_its_start() -> None:
    ctx = context(stitched_problem(5, 30, 3.0), "avg_completion", 1.0)
    start = fcfs(ctx)
    found, found_cost, iterations = tabu_search(ctx, start.assignment, budget_s=0.0)
    assert found is start.assignment and iterations == 0 and "orientation" not in ctx.__dict__
    assert found_cost == cost(ctx, start)
