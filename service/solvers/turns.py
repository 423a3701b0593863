"""Re-insertion search in turns: a chain per free core, each restarted from its own best each turn.

``auto``'s large stage (:mod:`service.solvers.portfolio`) runs re-insertion search
(:mod:`service.solvers.reinsert`) in turns of at most ``turn_s`` and ``turn_share`` of
the time given. Each turn of a chain starts from that chain's best answer so far, so an
annealed search that wandered off while hot comes back to it. With several cores a turn
runs one chain per core at once, each with a seed of its own, and each chain is a
lineage of its own: its next turn starts from its own best, and the turns answer the
cheapest lineage's best. Runs of one search end in basins far apart (docs/benchmarks.md,
sessions 59 and 64), and lineages kept apart sample more of them than chains restarted
from the cheapest of a turn (as from session 44 to 64: see TurnsConfig.chains). A
lineage whose turn found nothing cheaper than its start has stalled in its basin, and one
that ended the turn more than BEHIND dearer than the cheapest is unlikely to catch up:
either goes on from the cheapest lineage's best, with its own seed
(TurnsConfig.meet_stalled), so that no core keeps searching a basin that gave up or lags
far. The cores are those the solve may take at that turn: its share of the machine among
the solves under way
(:func:`~service.core.threads.cores_per_solve`), so a lone request searches on every core
whatever its ``workers``, and one that arrives while it searches gets its share from the
next turn on (the dearest lineages stop; where cores free up, new lineages start from the
cheapest answer). Every turn's search cools over the same span (the first COOLED_SHARE
of the time, and all but MOST_COLD_S at least), then searches cold.

The first lineages start from different answers where the caller has several (``auto``:
its prioritized plans, ``others``), not from copies of the cheapest: where a search ends
depends on where it started more than on what the start cost (traced on a two-way
warehouse of 250 robots, ``auto`` at 5 s, six seeds: the two lineages of one run, from one
plan, ended their first turn at 110.8 / 112.5, 127.6 / 131.2, 119.5 / 120.3 and so on, and
plans of 214-299 ended at 100.9-105.0, the cheapest plan at 103.7). Measured (session 67,
``python -m bench.ab``, ``auto`` of one worker on two cores, an ad hoc flag; cost ratio
without / with, B's gain with its 95 % interval over worlds, runs cheaper / dearer with):
1 s, wh_two_way, wh_two_lane, floor_dense of 100 and wh_two_way, wh_two_lane, wh_one_way,
wh_mixed of 250 robots, six worlds a kind, two seeds, 0.9657 / 0.9695, +0.0037 (-0.0047,
+0.0118), 48 / 33; other worlds (``--seed 600000``: wh_two_way, wh_two_lane, wh_mixed of
100, floor_dense of 50, wh_two_way, wh_one_way, wh_mixed of 250) 0.9764 / 0.9849, +0.0085
(+0.0024, +0.0152), 46 / 33 (wh_two_way 250 0.942 / 0.972); 5 s, the first kinds, four
worlds, two seeds, even: 0.9831 / 0.9833, +0.0003 (-0.0059, +0.0061), 30 / 24. Where the
first turn lasts RACE_LEAST_S at least, RACE lineages a core race from as many starts, in RACE
turns of their own, and the cheapest go on (see RACE).

Robot-priority search (:mod:`service.solvers.priority`) took a part of every cold turn
from session 26 to session 50 (its part following the cost each search took off per
second; from the start of the turns until session 38): then re-insertion never delayed a
held robot, and priority search's shifts were the one way to trade one robot's delay
for another's. Since re-insertion may push held robots past their latest at a price
(``reinsert.PUSH``) and holds them by what the objective reads
(:meth:`~service.core.evaluate.Evaluator.held_weights`), its time pays more. Measured
(session 51, ``python -m bench.ab``, ``auto`` with priority search's first part 0.3, as
shipped, against none; docs/benchmarks.md "Re-insertion alone in the turns"): 1 s,
generated warehouses of 100 and 250 robots, avg_completion 0.9487 -> 0.9553 (25 of 36
runs cheaper without), other worlds 0.9714 -> 0.9779 (19 / 17), avg_delay 0.8840 ->
0.8990 (18 / 6), other kinds and sizes 0.9835 -> 0.9898 (13 / 6); 2 s 0.9636 -> 0.9646;
5 s 0.9730 -> 0.9752 (16 / 8), avg_delay even; 10 s even.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass
from typing import NamedTuple

from service.core.assignment import Assignments
from service.core.threads import available_cores, cores_per_solve
from service.solvers.registry import SolveContext
from service.solvers.reinsert import ReinsertResult, reinsert_search

__all__ = ["BEHIND", "COOLED_SHARE", "MOST_COLD_S", "TurnsConfig", "TurnsResult", "take_turns"]


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
# ... and it searches cold for this many seconds at most (it cools over the rest): at 100
# robots the cold turns stall after ~1-1.5 s (traced at 5 s, floor_dense/100/61: the last
# five of ten turns found nothing cheaper), and the time they waste pays more while warm.
# Measured (session 59, ``python -m bench.ab``, ``auto``, 5 s, cooling over 0.75 of the
# time (1.25 s cold) against 0.5; wh_two_way, wh_two_lane, floor_dense, wh_mixed of 100
# and wh_two_way, wh_two_lane of 250 robots, two worlds a kind, two seeds; cost ratio,
# runs cheaper / dearer with it): ``--seed 600000`` 0.9826 -> 0.9870 (14 / 9), ``--seed
# 700000`` 0.9840 -> 0.9888 (13 / 9); 250-robot warehouses 0.9533 -> 0.9844, 0.9703 ->
# 0.9914 and the like; wh_two_way 100 dearer in one run (0.9868 -> 0.9631, 0 / 4), even
# in the other. At 1 s (0.5 s cold, as before) cooling over 0.75 read 0.9776 / 0.9797
# (12 / 17): mixed, so budgets up to 2.5 s keep half. See docs/benchmarks.md, "Session 59".
MOST_COLD_S = 1.25
# A lineage that ended a turn this share dearer than the cheapest goes on from the cheapest's best
# (as one that stalled: see the module), however much its turn found. Measured (session 65, ``python
# -m bench.ab``, ``auto`` of one worker on two cores, two worlds a kind, two seeds; cost ratio, runs
# cheaper / dearer with B) on set one (wh_two_way, wh_two_lane, floor_dense of 100, wh_two_way,
# wh_two_lane, wh_one_way, wh_mixed of 250 robots) and set two (``--seed 600000``: wh_two_way,
# wh_two_lane, wh_mixed of 100, floor_dense of 50, wh_two_way, wh_one_way, wh_mixed of 250). 0.03
# (B, ``--b service.solvers.turns.TurnsConfig.behind=0.03``) against stalled lineages alone meeting:
# set one 1 s 0.9527 / 0.9577 (16 / 11; wh_two_way 250 0.896 / 0.927, 4 / 0), 5 s 0.9838 / 0.9862
# (16 / 9; wh_two_lane 250 0.987 / 0.973, 0 / 4); set two 1 s 0.9808 / 0.9854 (16 / 11; wh_one_way
# 250 0.954 / 0.973, 4 / 0), 5 s 0.9839 / 0.9838 (11 / 11). At 1 s a lagging lineage has no time to
# catch up; at 5 s the meeting costs diversity about as much as it gains. 0.015 (B) against 0.03:
# set one 1 s 0.9570 / 0.9557 (15 / 12), 5 s 0.9827 / 0.9850 (11 / 11); set two 1 s 0.9889 / 0.9915
# (16 / 7), 5 s 0.9860 / 0.9893 (11 / 10).
BEHIND = 0.015
# Lineages a chain races where the first turn lasts RACE_LEAST_S at least (budgets of ~2 s and
# more), each from a start of its own (``auto``'s plans: see take_turns' ``others``), in RACE
# turns of their own: the first turn runs the cheapest ``chains`` starts, each on a core of its
# own, the next turn the next ``chains``, and the cheapest ``chains`` of them all go on (no
# meeting between them). The basins a search ends in are set in its first turns
# (docs/benchmarks.md, sessions 67 and 70), so more of them are tried where a lineage has time
# to show which is deep. Measured (``python -m bench.ab``, ``auto`` of one worker on two cores;
# cost ratio A / B, B's gain with its 95 % interval over worlds, runs A cheaper / dearer; the
# figures by kind in docs/benchmarks.md, sessions 70 and 71):
# - Session 70, racing at once (each core ran RACE lineages in the first turn, at a share of
#   the core) against none, 5 s: wh_two_way, wh_two_lane, floor_dense of 100 and wh_two_way,
#   wh_two_lane of 250 robots (three worlds, two seeds) 0.9823 / 0.9869, +0.0046 (+0.0001,
#   +0.0093), 14 / 15; ``--seed 600000`` (wh_two_way, wh_two_lane, wh_mixed, floor_dense of 100,
#   wh_two_way, wh_one_way, wh_mixed of 250, two worlds) +0.0030 (-0.0072, +0.0124); ``--seed
#   700000`` +0.0029 (-0.0056, +0.0141); 3 s +0.0013 (-0.0041, +0.0063); at 1 s (turns of ~0.22
#   s) -0.0030 (-0.0113, +0.0049): hence the least length. The 100-robot families gained (+0.007
#   in 10 of 13 family runs: runs that no longer end in a poor basin, the typical run a little
#   dearer), the 250-robot ones lost (-0.003), where a racer on half a core makes too few steps
#   to show its basin; so at once only up to 150 robots, then (``--seed 800000``) even against
#   none, and (session 71, ``--seed 900000``, wh_two_way, wh_two_lane, floor_dense, wh_mixed of
#   100, three worlds) 0.9941 (none) / 0.9964, +0.0023 (-0.0001, +0.0048), 8 / 15.
# - Session 71, in turns against none at 250 robots (wh_two_way, wh_two_lane, wh_one_way,
#   wh_mixed, three worlds, two seeds): 5 s 0.9750 / 0.9775, +0.0024 (-0.0053, +0.0103), 13 /
#   11; ``--seed 600000`` 0.9828 / 0.9898, +0.0070 (-0.0031, +0.0213), 11 / 13; 3 s, ``--seed
#   700000``, 0.9745 / 0.9824, +0.0079 (-0.0078, +0.0269), 9 / 15; ``--seed 800000`` 0.9771 /
#   0.9783, +0.0012 (-0.0148, +0.0194), 16 / 8. Over the four +0.0046, racing cheaper in 47 of
#   96 runs: the gain is in runs that no longer end in a poor basin (wh_one_way 250 +0.007 to
#   +0.038 in every set), the typical run a little dearer (wh_two_lane 250 -0.026 to +0.002).
# - Session 71, in turns against at once at 100 robots (wh_two_way, wh_two_lane, floor_dense,
#   wh_mixed, three worlds, two seeds), 5 s: 0.9882 / 0.9940, +0.0057 (+0.0012, +0.0114), 7 /
#   13; ``--seed 900000`` 0.9951 / 0.9948, -0.0003 (-0.0039, +0.0035), 11 / 9; ``--seed
#   600000`` 0.9936 / 0.9941 (the 100-robot kinds), 8 / 15. In turns at every size, then: no
#   worse where racing at once paid, and one way to race instead of two.
# - Session 72, as shipped against none on more worlds (``--seed 400000``: the 250-robot kinds
#   above and wh_two_way, wh_two_lane, floor_dense, wh_mixed of 100, six worlds, two seeds; 96
#   pairs, more than a 24-pair run resolves): 0.9886 / 0.9844 (none), -0.0042 (-0.0097,
#   +0.0027) for none, 37 / 58, every 250-robot kind for racing (wh_two_way and wh_two_lane
#   intervals below 0); floor_dense 100 on twenty worlds even (0.9925 / 0.9912).
# Racing three lineages a core from six plans (``race`` 3, ``portfolio.PLANNED_ORDERS`` 6;
# racing at once at 100 robots, in turns at 250), 5 s, session 70's first kinds: even, 0.9843 /
# 0.9839, -0.0005 (-0.0061, +0.0041). At 1 s in turns (``race_least_s`` 0.2: two of the ~4
# turns of a 250-robot fleet racing): 0.9628 / 0.9586, -0.0042 (-0.0120, +0.0036), 21 / 11.
RACE = 2
RACE_LEAST_S = 0.5
# Chain k > 0 of a turn (see TurnsConfig.chains) searches with the turn's seed plus k times
# this: no two chains of the turns of one search share a seed.
CHAIN_SEED_STRIDE = 1_000_003


@dataclass(frozen=True)
class TurnsConfig:
    """How long a turn lasts, how re-insertion cools over the turns, and how many chains
    a turn runs."""

    turn_s: float = 0.5  # a turn's length, at most (1 s measured the same)
    turn_share: float = 0.25  # ... and at most this share of the time given
    # Re-insertion's annealing cools over this share of the time given at least (all but
    # most_cold_s where that is more), and searches cold for the rest (see COOLED_SHARE).
    cooling_share: float = COOLED_SHARE
    most_cold_s: float = MOST_COLD_S  # ... for this many seconds at most (see MOST_COLD_S)
    # Re-insertion searches a turn runs at once, each in a thread from its own lineage's best answer
    # so far with a seed of its own (see the module; None: one per core the solve may take at that
    # turn, ``threads.cores_per_solve``, and ``SolveContext.workers`` at least; until session 64 its
    # ``workers`` alone, so the service's default of one worker per solve, two solves at once, left
    # a lone request's second core idle). A step's kernels release the GIL, the Python between them
    # does not: two threads took 1.43-1.9x the steps of one (session 30). Measured (session 44,
    # ``python -m bench.ab``, two chains against one on one solve's two cores; 1 s, generated
    # warehouses of 100 and 250 robots, three worlds a kind, two seeds, cost ratio): with ``--method
    # auto_2cores`` the two-way and two-lane kinds 0.8892 / 0.8829 (14 cheaper, 10 dearer of 24),
    # other worlds of those and of wh_one_way and wh_mixed 250 (seeds from 2,000) 0.9805 / 0.9688
    # (21 / 15); two threads forced on one worker's ``auto``: 0.9006 / 0.8954 (15 / 9), seeds from
    # 1,000 0.9800 / 0.9626 (25 / 11); 5 s 0.9587 / 0.9556 (12 / 12). Again in session 64 (``python
    # -m bench.ab --b service.solvers.turns.TurnsConfig.chains=2``: ``auto`` of one worker as the
    # service runs a lone request, one chain against two; wh_two_way, wh_two_lane, floor_dense of
    # 100 and wh_two_way, wh_two_lane of 250 robots, three worlds, two seeds): 1 s 0.9266 / 0.9346
    # (12 cheaper, 18 dearer of 30 with one; floor_dense 100 0.960 / 0.989, wh_two_way 250 0.847 /
    # 0.858), 5 s 0.9755 / 0.9776 (14 / 15; wh_two_lane 250 0.975 / 0.988, but wh_two_way 100 0.986
    # / 0.959, dearer in 6 of 6: at 100 robots each of two chains takes 0.70-0.83 of one chain's
    # steps, at 250 no fewer). Since session 64 the chains are lineages that never meet (see the
    # module; since session 65, unless one stalls or lags: meet_stalled). Measured (``python -m
    # bench.ab --b service.solvers.turns.TurnsConfig.independent=True``, an ad hoc flag: each chain
    # its own turns to the deadline, the cheapest answer kept; against the cheapest chain of each
    # turn going on in both, two chains on one worker's ``auto``; the kinds above, three worlds, two
    # seeds): 1 s 0.9302 / 0.9333 (9 cheaper, 21 dearer of 30 merged; wh_two_lane 250 0.904 /
    # 0.918), 5 s 0.9770 / 0.9829 (13 / 16; wh_two_way 100 0.977 / 0.988); other worlds (``--seed
    # 600000``, wh_two_way, wh_two_lane, floor_dense, wh_mixed of 100, wh_two_way, wh_one_way,
    # wh_mixed of 250, two worlds, two seeds) 1 s 0.9801 / 0.9823 (11 / 17), 5 s 0.9889 / 0.9875 (14
    # / 12; wh_one_way 250 0.987 / 0.978, dearer in 4 of 4, wh_mixed 250 0.984 / 0.973, the
    # 100-robot kinds better).
    chains: int | None = None
    # Whether a lineage whose turn found nothing cheaper than its start goes on from the
    # cheapest lineage's best (see the module). Measured (session 65, ``python -m bench.ab
    # --b service.solvers.turns.TurnsConfig.meet_stalled=True`` while False was the default:
    # against lineages that never meet, ``auto`` of one worker on two cores; wh_two_way,
    # wh_two_lane, floor_dense of 100, wh_two_way, wh_two_lane, wh_one_way, wh_mixed of 250
    # robots, two worlds, two seeds; cost ratio, runs cheaper / dearer meeting): 1 s 0.9485 /
    # 0.9522 (16 / 9; wh_two_way 250 0.874 / 0.883, 4 / 0), 5 s 0.9779 / 0.9839 (17 / 9;
    # wh_one_way 250 0.970 / 0.992, 4 / 0); other worlds (``--seed 600000``: wh_two_way,
    # wh_two_lane, wh_mixed of 100, floor_dense of 50, wh_two_way, wh_one_way, wh_mixed of
    # 250) 1 s 0.9817 / 0.9826 (14 / 9), 5 s 0.9866 / 0.9895 (12 / 12; wh_mixed 250 0.986 /
    # 0.996, 4 / 0, floor_dense 50 0.996 / 0.986, 0 / 2).
    meet_stalled: bool = True
    # ... and where it ended more than this share dearer than the cheapest (inf: stalled alone)
    behind: float = BEHIND
    # Lineages per chain that race, in turns of their own, where the first turn lasts
    # race_least_s at least, from as many starts (see RACE; 1: none race)
    race: int = RACE
    race_least_s: float = RACE_LEAST_S


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
    others: Sequence[tuple[Assignments, float]] = (),
    held: int = 0,
    stop: threading.Event | None = None,
) -> TurnsResult:
    """Re-insertion search in turns from the valid ``start`` (of ``cost``) until
    ``deadline`` (monotonic): ``config.chains`` lineages at once (by default one per core
    the solve may take at that turn, at least ``ctx.workers``: see TurnsConfig.chains),
    each turn of each from its own best answer so far with the turn's seed (lineage k's
    plus k times CHAIN_SEED_STRIDE), or from the cheapest lineage's where its last turn
    found nothing cheaper or ended more than ``config.behind`` dearer than the cheapest
    (``config.meet_stalled``) -> the cheapest lineage's best (the first of equals).
    ``config`` None: TurnsConfig's defaults, read at the call (so that ``bench.ab`` can
    vary them).

    ``others``: further valid starts, each with its cost (``auto``'s other plans): the
    first turn's lineages start from the cheapest of ``start`` and these, and only where
    there are fewer than lineages from copies of the cheapest (see the module). Where the
    first turn lasts ``config.race_least_s`` at least, ``config.race`` lineages a chain race
    (as many as there are starts at most; see RACE), ``chains`` a turn, the cheapest starts
    first, in turns of their own; then the cheapest ``chains`` go on.

    ``held``: cores the solve keeps for other work meanwhile (``auto``'s CP-SAT stages, see
    :mod:`service.solvers.portfolio`, BESIDE): by default the turns take one lineage per core
    the solve may take less these, and end at a turn where none is left. ``stop``: the turns
    end once it is set (a search checks it before each step)."""
    config = TurnsConfig() if config is None else config
    lineages = [ReinsertResult(answer, of, 0) for answer, of in [(start, cost), *others]]
    turns = 0
    now = time.monotonic()
    turn_s = min(config.turn_s, config.turn_share * (deadline - now))
    cold_s = min((1 - config.cooling_share) * (deadline - now), config.most_cold_s)
    cooling = (now, deadline - cold_s)  # then it searches cold
    most = config.chains or max(_chains(ctx, held, available_cores()), 1)
    races = turn_s >= config.race_least_s  # the first lineages race (see RACE)
    waiting: list[ReinsertResult] = []  # starts that race in turns of their own, still to run
    with ThreadPoolExecutor(most) if most > 1 else nullcontext() as pool:
        while (began := time.monotonic()) < deadline and not (stop and stop.is_set()):
            until = min(deadline, began + turn_s)
            chains = config.chains or _chains(ctx, held, cores_per_solve())
            if chains < 1:
                break
            if races and turns == 0:
                waiting = _racing_in_turns(config, chains, lineages)
            racing = bool(waiting)  # a turn of the race
            if racing:
                began_from, waiting = waiting[:chains], waiting[chains:]
            else:
                began_from = _as_many(lineages, chains)
            starts = [line.best for line in began_from]
            ended = _reinsertion(ctx, starts, until, seed + turns, cooling, pool, stop)
            if racing:  # every racer so far, unmet (the race starts at turn 0); the cheapest
                lineages = ended if turns == 0 else lineages + ended  # go on once none wait
            elif config.meet_stalled:
                lineages = _met(began_from, ended, config.behind)
            else:
                lineages = ended
            turns += 1
    best = _cheapest(lineages)
    return TurnsResult(best.best, best.cost, turns)


def _chains(ctx: SolveContext, held: int, cores: int) -> int:
    """Lineages on ``cores`` (those the solve may take now for the next turn,
    :func:`~service.core.threads.cores_per_solve`; the machine's for the threads kept): one
    per core, at least ``ctx.workers`` where the solve holds none for other work, else less
    the ``held`` cores (0: none left)."""
    if held == 0:
        return max(ctx.workers, cores)
    return max(cores - held, 0)


def _racing_in_turns(
    config: TurnsConfig, chains: int, lineages: list[ReinsertResult]
) -> list[ReinsertResult]:
    """The starts of a race (see RACE), cheapest first, ``chains`` a turn: the
    cheapest ``config.race`` times ``chains`` of ``lineages``; none (no race) where that
    is no more than ``chains``."""
    racers = sorted(lineages, key=lambda line: line.cost)[: config.race * chains]
    return racers if len(racers) > chains else []


def _as_many(lineages: list[ReinsertResult], n: int) -> list[ReinsertResult]:
    """``n`` lineages from ``lineages``: the cheapest n in their order where there are more
    (the dearest stop), else all and then copies of the cheapest (new lineages start from
    the best answer so far)."""
    if len(lineages) > n:
        kept = sorted(range(len(lineages)), key=lambda k: lineages[k].cost)[:n]
        return [lineages[k] for k in sorted(kept)]
    cheapest = _cheapest(lineages)
    return lineages + [cheapest] * (n - len(lineages))


def _cheapest(lineages: list[ReinsertResult]) -> ReinsertResult:
    """The cheapest of ``lineages`` (the first of equals)."""
    return min(lineages, key=lambda line: line.cost)


def _met(
    began_from: list[ReinsertResult], ended: list[ReinsertResult], behind: float
) -> list[ReinsertResult]:
    """The lineages after a turn that ``began_from`` those and ``ended`` with these (in
    the same order): each that found nothing cheaper, or ended more than ``behind`` (a
    share) dearer than the cheapest, replaced by the cheapest (the first of equals)."""
    cheapest = _cheapest(ended)
    lagging = (1 + behind) * cheapest.cost
    return [
        cheapest if end.cost >= began.cost or end.cost > lagging else end
        for began, end in zip(began_from, ended, strict=True)
    ]


def _reinsertion(
    ctx: SolveContext,
    starts: list[Assignments],
    until: float,
    seed: int,
    cooling: tuple[float, float],
    pool: ThreadPoolExecutor | None,
    stop: threading.Event | None,
) -> list[ReinsertResult]:
    """A turn's re-insertion searches until ``until`` (monotonic), cooling over
    ``cooling``: search k from ``starts[k]`` with ``seed`` + k * CHAIN_SEED_STRIDE, all at
    once in ``pool``'s threads (None: one search, in this thread) -> their results in
    that order; each ends early once ``stop`` is set."""
    if pool is None or len(starts) == 1:
        return [reinsert_search(ctx, starts[0], until, seed, cooling=cooling, stop=stop)]
    runs = [
        pool.submit(
            reinsert_search,
            ctx,
            start,
            until,
            seed + k * CHAIN_SEED_STRIDE,
            cooling=cooling,
            stop=stop,
        )
        for k, start in enumerate(starts)
    ]
    return [run.result() for run in runs]
