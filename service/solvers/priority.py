"""Robot-priority search: an evolution strategy over one rank offset per robot.

Tabu search changes one conflict per iteration; on a congested warehouse of 100-250
robots the blended start (:func:`~service.solvers.tabu.plain_start`) is thousands of
conflicts from a good schedule, and tabu search spends seconds walking there. Here a
move shifts one robot's whole priority: node ranks are the cheapest blend's ranks
(V,) plus an offset per robot (constant along its path, so ranks stay non-decreasing
along every path and every decoded answer is acyclic and valid); a candidate adds
N(0, (``step`` x time span)^2) to one random robot's offset, which reverses every conflict
whose order against that robot the shift crosses, at once. Each round decodes and
evaluates ``candidates`` of them that reorder something (a third of the shifts cross no
other robot's rank where they meet, and are skipped) in one batched call and keeps the
cheapest if it beats the current (a (1 + lambda) strategy). Types are the decoder's
greedy fill by FCFS scores, which does not depend on directions: decoded once.

Measured (docs/benchmarks.md, "Anytime auto"): as ``auto``'s first stage it beat tabu
search alone on every generated warehouse and floor at 0.3-3 s (``wh_two_lane`` of 100
robots: 0.92 against 0.77 of the best known at 1 s). On warehouses of 100 robots it
stalls after a few hundred rounds, and :func:`priority_tabu` hands over to tabu search,
which then still finds single-conflict improvements; at 250 robots it was still
improving after 10 s. Costing candidates incrementally (as groups of reversals) was
tried and measured no faster: a shift reverses 5-300 conflicts, and on a two-way
warehouse of 250 robots their propagation costs as much as the full evaluation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from service.core.assignment import Assignments
from service.solvers.fcfs import cheapest_blend
from service.solvers.registry import SolveContext, SolverOutput, register
from service.solvers.tabu import tabu_search

__all__ = ["PriorityConfig", "priority_search", "priority_tabu"]


@dataclass(frozen=True)
class PriorityConfig:
    """Candidates per round, step size and the stopping rule."""

    candidates: int = 8  # robots shifted per round, one each (a batched evaluation)
    step: float = 0.1  # offset standard deviation, as a share of the problem's time span
    patience: int = 30  # rounds without a cheaper candidate before stopping
    max_rounds: int = 100_000


def priority_search(
    ctx: SolveContext, budget_s: float, seed: int, cfg: PriorityConfig = PriorityConfig()
) -> tuple[Assignments, float, int]:
    """Search robot offsets from the cheapest blend -> (best, its cost, rounds run).

    Stops after ``cfg.patience`` rounds without improvement, after ``cfg.max_rounds`` or
    after ``budget_s`` seconds; deterministic for a seed when it stops on one of the first
    two.
    """
    deadline = time.perf_counter() + budget_s
    p, decoder, evaluator = ctx.problem, ctx.decoder, ctx.evaluator
    rng = np.random.default_rng(seed)
    base, best, best_cost = cheapest_blend(ctx)  # ranks (V,), its assignment, its cost
    following = best.following  # (1, M): greedy by FCFS scores, whatever the directions
    offsets = np.zeros(p.n_robots)  # (R,) the current (best) offsets
    sigma = cfg.step * float(p.node_exit.max() - p.node_enter.min())
    draws = 2 * cfg.candidates  # a third of single-robot shifts reorder nothing: drawn over
    rows = np.arange(draws)
    stale = rounds = 0
    while stale < cfg.patience and rounds < cfg.max_rounds and time.perf_counter() < deadline:
        rounds += 1
        stale += 1
        trial = np.repeat(offsets[None], draws, axis=0)  # (D, R)
        trial[rows, rng.integers(p.n_robots, size=draws)] += rng.normal(0.0, sigma, draws)
        a_first = decoder.directions(base[None] + trial[:, p.node_robot])  # (D, M)
        moved = np.flatnonzero((a_first != best.a_first).any(axis=1))[: cfg.candidates]
        if moved.size == 0:
            continue
        found = Assignments(a_first[moved], np.repeat(following, moved.size, axis=0))
        cost = evaluator.evaluate(found).costs[ctx.objective]  # (C',)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best, best_cost, offsets = found.take(k), float(cost[k]), trial[moved[k]]
            stale = 0
    return best, best_cost, rounds


@register("priority_tabu")
def priority_tabu(ctx: SolveContext) -> SolverOutput:
    """Robot-priority search until it stalls, then tabu search from the cheaper of its
    best and a re-schedule's previous answer, in the request's time limit (the search
    starts at the cheapest blend and never returns worse)."""
    deadline = time.perf_counter() + ctx.time_limit_s
    found, cost, rounds = priority_search(ctx, ctx.time_limit_s, ctx.seed)
    warm = ctx.warm
    if warm is not None and float(ctx.evaluator.evaluate(warm).costs[ctx.objective][0]) < cost:
        found = warm
    left = deadline - time.perf_counter()
    best, _, iterations = tabu_search(ctx, found, budget_s=max(left, 0.0))
    return SolverOutput(best, detail=f"{rounds} priority rounds, {iterations} tabu iterations")
