"""Robot-priority search and re-insertion search in turns.

The two searches get stuck in different places. Re-insertion
(:mod:`service.solvers.reinsert`) re-plans a few robots with every other robot's times
held, delaying a held robot only where that costs nothing (up to its latest delays):
before it could do even that, on a dense two-way warehouse of 250 robots (~175
conflicts per robot) it plateaued at 0.81 of the best known after 20-30 s (the bench's
slower Xeon), where priority search alone reached 0.88 in 30 s. Priority search
(:mod:`service.solvers.priority`) shifts one robot's priority against every robot it
meets, delaying them where that pays, but its random shifts rarely find the fine
re-orderings re-insertion finds in a step: on a two-lane warehouse of 250 robots it
reached 0.75 in 30 s, re-insertion 0.89 in 5 s. In turns, each starts from the other's
answer: priority search from ranks that decode to it
(:func:`~service.solvers.priority.answer_ranks`), re-insertion from its directions. The
split of a turn follows the cost each search took off per second in the last one, so
the search that pays on a fleet gets the time. Measured (docs/benchmarks.md,
"Re-insertion and priority search in turns"): ``auto`` on the two-way warehouses of 250
robots 0.61 -> 0.73 at 1 s and 0.79 -> 0.92 at 5 s against re-insertion alone; a fixed
60/40 split read 0.68 and 0.89.

Priority search takes its part only once re-insertion's annealing is cold (the first
COOLED_SHARE of the time, the turns are re-insertion's alone, each from the best so far):
its moves paid there no more than the re-insertion steps they took the time of. Measured
(session 38; ``auto`` through the dispatcher beside same-code controls, docs/benchmarks.md
"Priority search once re-insertion is cold"): generated warehouses of 250 robots 1 s
+0.009 / +0.014 (four seeds), 5 s +0.004 / -0.003 (two); of 100 robots even at 1 s,
+0.003 / +0.011 at 5 s; kinds not tuned on (wh_mixed, wh_one_way of 250) +0.035 at 1 s,
+0.021 at 5 s; wh_parked even at 1 s, +0.017 at 5 s. Without priority search at all:
+0.015 at 1 s but -0.005 at 5 s (250 robots).
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass
from typing import NamedTuple

from service.core.assignment import Assignments
from service.solvers.priority import answer_ranks, priority_search
from service.solvers.registry import SolveContext
from service.solvers.reinsert import ReinsertResult, reinsert_search

__all__ = ["COOLED_SHARE", "TurnsConfig", "TurnsResult", "take_turns"]


# Share of the time given to the turns over which re-insertion's annealing cools (its
# temperature falls linearly to zero, see ``reinsert.ANNEAL``); from then on it keeps only
# cheaper repairs. The best answers came in the cold: traced at 5 s on a two-lane
# warehouse of 250 robots, the last 0.12 s of turns (the coldest) took the cost ratio from
# 0.823 to 0.864, as much as the 0.8 s before. Measured (session 35, ``auto`` at 1 s (four
# seeds) and 5 s (two) on the 12 generated warehouses of 100 and 250 robots, references
# r5, beside same-code controls; docs/benchmarks.md): cooling over all of the time 1 s
# 0.8413 / 0.8383 / 0.8402, 5 s 0.9218 / 0.9288 / 0.9336; over half 1 s 0.8472 / 0.8550,
# 5 s 0.9341 / 0.9319; over 0.7 1 s 0.8472, 5 s 0.9278; over 0.3 1 s 0.8472, 5 s 0.9193.
# On kinds not tuned on (wh_mixed, wh_one_way, wh_parked at 250 robots): even at both.
COOLED_SHARE = 0.5
# Chain k > 0 of a turn's re-insertion (see TurnsConfig.chains) searches with the turn's seed
# plus k times this: no two chains of the turns of one search share a seed.
CHAIN_SEED_STRIDE = 1_000_003


@dataclass(frozen=True)
class TurnsConfig:
    """How long a turn lasts and how it is split."""

    turn_s: float = 0.5  # a turn's length, at most (1 s measured the same)
    turn_share: float = 0.25  # ... and at most this share of the time given
    # Priority search's part of the first turn: 0.3 since re-insertion may delay held
    # robots up to their latest (0.6 before; 0.4 measured the same then).
    priority_share: float = 0.3
    least_share: float = 0.1  # the least part of a turn either search keeps
    # Re-insertion's annealing cools over this share of the time given, and searches cold
    # for the rest (see COOLED_SHARE).
    cooling_share: float = COOLED_SHARE
    # Priority search takes turns from the start, not only once re-insertion is cold (see
    # the module: measured worse at 1 s).
    priority_while_hot: bool = False
    # Re-insertion searches a turn runs at once, each in a thread from the best answer so far
    # with a seed of its own; the cheapest goes on (None: one per core the solve has,
    # ``SolveContext.workers``). A step's kernels release the GIL, the Python between them
    # does not: two threads took 1.43-1.9x the steps of one (session 30). Measured (session
    # 44, ``python -m bench.ab``, two chains against one on one solve's two cores; 1 s,
    # generated warehouses of 100 and 250 robots, three worlds a kind, two seeds, cost
    # ratio): with ``--method auto_2cores`` the two-way and two-lane kinds 0.8892 / 0.8829
    # (14 cheaper, 10 dearer of 24), other worlds of those and of wh_one_way and wh_mixed 250
    # (seeds from 2,000) 0.9805 / 0.9688 (21 / 15); two threads forced on one worker's
    # ``auto``: 0.9006 / 0.8954 (15 / 9), seeds from 1,000 0.9800 / 0.9626 (25 / 11); 5 s
    # 0.9587 / 0.9556 (12 / 12).
    chains: int | None = None


class TurnsResult(NamedTuple):
    """The best answer, its cost and the turns taken."""

    best: Assignments
    cost: float
    turns: int


def take_turns(
    ctx: SolveContext,
    start: Assignments,
    cost: float,
    deadline: float,
    seed: int,
    config: TurnsConfig | None = None,
) -> TurnsResult:
    """Re-insertion then priority search, in turns from the valid ``start`` (of ``cost``)
    until ``deadline`` (monotonic); each turn's searches get the next seed, and its
    re-insertion runs in ``config.chains`` threads (one per core of the solve by default).
    ``config`` None: TurnsConfig's defaults, read at the call (so that ``bench.ab`` can
    vary them)."""
    config = TurnsConfig() if config is None else config
    best, turns, share = start, 0, config.priority_share
    now = time.monotonic()
    turn_s = min(config.turn_s, config.turn_share * (deadline - now))
    cooling = (now, now + config.cooling_share * (deadline - now))  # then it searches cold
    chains = config.chains or ctx.workers
    with ThreadPoolExecutor(chains) if chains > 1 else nullcontext() as pool:
        while (began := time.monotonic()) < deadline:
            before, turn_seed, turns = cost, seed + turns, turns + 1
            # While re-insertion is hot, the turns are its own (see the module).
            split = share if config.priority_while_hot or began >= cooling[1] else 0.0
            until = min(deadline, began + (1 - split) * turn_s)
            found = _reinsertion(ctx, best, until, turn_seed, cooling, pool, chains)
            best, cost = found.best, found.cost
            middle, between = time.monotonic(), cost
            left = min(split * turn_s, deadline - middle)
            if left <= 0:
                continue
            ranks = answer_ranks(ctx, best)
            # Given less than PriorityConfig.refit_min_s (0.5 s) here, it refits no types.
            best, cost, _ = priority_search(ctx, left, turn_seed, start=(ranks, best, cost))
            gains = (before - between, between - cost)
            spent = (middle - began, time.monotonic() - middle)
            share = _next_share(config, share, gains, spent)
    return TurnsResult(best, cost, turns)


def _reinsertion(
    ctx: SolveContext,
    start: Assignments,
    until: float,
    seed: int,
    cooling: tuple[float, float],
    pool: ThreadPoolExecutor | None,
    chains: int,
) -> ReinsertResult:
    """A turn's re-insertion search from ``start`` until ``until`` (monotonic), cooling over
    ``cooling``: ``chains`` searches at once in ``pool``'s threads (None: one, in this
    thread), chain k with ``seed`` + k * CHAIN_SEED_STRIDE -> the cheapest result (the
    first of equals: chain 0 is the single search's)."""
    if pool is None:
        return reinsert_search(ctx, start, until, seed, cooling=cooling)
    runs = [
        pool.submit(
            reinsert_search, ctx, start, until, seed + k * CHAIN_SEED_STRIDE, cooling=cooling
        )
        for k in range(chains)
    ]
    return min((run.result() for run in runs), key=lambda found: found.cost)


def _next_share(
    config: TurnsConfig, share: float, gains: tuple[float, float], seconds: tuple[float, float]
) -> float:
    """Priority search's part of the next turn: halfway from ``share`` to its part of the
    cost taken off per second in the last turn (``gains`` and ``seconds`` of re-insertion,
    then of priority search), within ``least_share`` of either end; unchanged where
    neither took anything off."""
    rates = [gain / max(spent, 1e-6) for gain, spent in zip(gains, seconds, strict=True)]
    if sum(rates) <= 0:
        return share
    measured = rates[1] / sum(rates)
    return min(max(0.5 * (share + measured), config.least_share), 1 - config.least_share)
