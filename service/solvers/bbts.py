"""Budgeted backtracking: the cheapest of the first 1,000 valid assignments found depth first.

Conflicts are decided in time order (earliest pair enter first), each trying
the FCFS direction before the other and following-type before exclusive; a
value is skipped when it would close a cycle or overfill a density clique
(:class:`OrientationGraph`), so every leaf is a valid assignment and the
search never dead-ends; a conflict with a fixed direction only branches on its
type. Leaves are evaluated in batches as they come. This is
the published "BBTS" baseline: its first leaf is FCFS-like and the next ones
differ only in the last few decisions (1,000 leaves span about log4(1000) ~ 5
conflicts), which is why it falls off as problems grow.
"""

from __future__ import annotations

import time

import numpy as np

from service.solvers.fcfs import fcfs_priorities
from service.solvers.pace import Pace
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["BATCH", "LEAVES", "bbts"]

LEAVES = 1000  # valid assignments enumerated (the published budget)
BATCH = 100  # leaves enumerated and evaluated per step, at most
# An enumeration step makes at most the moves (values tried or undone at one depth) that
# SLICE_S, or the time left if less, holds at the last step's pace, and at most twice the
# last step's (a move's cycle check costs more the deeper it is: 256 shallow moves in
# 2.4 ms foretold 5,373 in 50 ms, which took 341 ms); the time limit is checked between
# steps. With steps of 100 leaves, a 250-robot warehouse's first leaf (11,000-23,000
# conflicts, a cycle check each) took a 0.5-s request to 9-11 s, and 100 robots overran
# 1.8 s by 0.34 s (session 30).
SLICE_S = 0.05
FIRST_MOVES = 256  # moves of the first step, which times the next


@register("bbts")
def bbts(ctx: SolveContext) -> SolverOutput | None:
    """Cheapest of the first ``LEAVES`` valid assignments, within the request's time limit
    (None where not even the first was reached in it: the dispatcher falls back)."""
    pace = Pace(time.perf_counter() + ctx.time_limit_s, time.perf_counter)
    problem = ctx.problem
    ranks, scores = fcfs_priorities(problem)
    order = np.lexsort((np.arange(problem.n_conflicts), -scores))  # earliest conflict first
    prefer_a = ctx.decoder.directions(ranks[None])[
        0
    ]  # (M,) FCFS: who is expected first passes first
    search = ctx.orientation.enumerate(order, prefer_a, follow_first=True)
    best, best_cost, seen, moves = None, np.inf, 0, FIRST_MOVES
    while seen < LEAVES and not search.done and moves > 0:
        began, before = pace.clock(), search.moves
        leaves = search.next(min(BATCH, LEAVES - seen), moves)
        if leaves.n_samples > 0:
            seen += leaves.n_samples
            costs = ctx.evaluator.evaluate(leaves).costs[ctx.objective]  # (K,)
            k = int(np.argmin(costs))
            if costs[k] < best_cost:
                best, best_cost = leaves.take(k), float(costs[k])
        made = search.moves - before
        pace.record(began, made)
        moves = min(pace.units(SLICE_S), 2 * max(made, 1))
    if best is None:
        return None
    return SolverOutput(best, samples=seen, detail=f"{seen} assignments enumerated")
