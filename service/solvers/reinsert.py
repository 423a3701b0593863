"""Re-insertion search: large-neighbourhood search repaired by prioritized planning.

:mod:`service.solvers.lns` re-plans a few robots at a time exactly, with CP-SAT, in
10-110 ms a step. Here the same neighbourhoods (a seed robot drawn by its delay, then
robots drawn by the conflicts they share with those picked, a binding wait counting
more) are repaired the way multi-agent path finding's anytime LNS repairs them, by
prioritized planning: every other robot's times are held, and the picked robots are
put back one after the other, in a random order (except that a robot that must pass
another picked robot first comes before it), each on its cheapest passage past the
robots already placed (:func:`_passage`, a dynamic programme over its events:
milliseconds for all of them). Once the search is cold (below), several orders are
tried per step (while it is hot, one: HOT_ORDERS) and the one whose picked robots finish
earliest is evaluated by the one evaluator and kept when cheaper;
an order in which a robot fixed to pass another first finds no passage is tried again
with that robot first (RETRIES).

**A passage** of robot r past placed robots with held times: each of r's nodes takes a
*gap* among the positions (a topological order of the placed robots' node graph) of
the nodes it conflicts with; a partner node before the gap passes first (r waits at its
pair enter for the partner's pair exit, or pair enter where following-type is allowed
and needed), one after it passes second (r must have left, or entered, before the
partner's held pair enter). Gaps never fall along r's path, so r's nodes slot into the
order between their partners and every arc still goes forward in it: the answer is
acyclic by construction, the one cycle that time bounds alone do not exclude (pair
sections inside merged nodes) included. r's delay rises only where it waits, the least
such profile is the cheapest for fixed gaps, and the programme keeps, per gap, the
least delay reachable so far (a smaller delay dominates: waiting longer never helps a
deadline), so the passage is exact for r alone. Following-type is allowed on a conflict
only while every binding density clique of it has room left (held and placed conflicts
counted), and kept only where the exclusive constraint would not hold: the budgets
always hold.

**Room for following-type.** Which of r's conflicts get a clique's last room is decided
before its passage, conflict by conflict (those following-type in the incumbent first),
so where room is short the passage may be far from the best one the room allows: on a
two-way warehouse of 250 robots, one robot put back alone finished at 285 s where
CP-SAT (LNS) placed it at 57 s, following-type on four other conflicts of the same
cliques. So in a cold step, where room was short for a robot, its passage is also sought
as if every clique had room, then without the conflicts whose following-type overfilled
a clique (the latest on its path first), up to ROOM_ROUNDS passages; the first that fits
replaces the passage found where it is cheaper for the robot and takes no more
following-type conflicts (taking more starved the robots put back after it: measured
worse), unless the robot is the last of its order (ROOM_LAST_MORE: none comes after it).

A picked robot waits for a held partner's least time, and may pass first as long as
the partner is then delayed no further than its *latest* delay
(:meth:`~service.core.evaluate.Evaluator.latest_delays` of the incumbent): the latest
that leaves every robot's part of the objective where it was (for avg_delay, whose every
event weighs, every robot's completion: see
:meth:`~service.core.evaluate.Evaluator.held_weights`). A held robot that waits
further on can be delayed for free up to that wait; where robots queue, that is where
the room is (on generated warehouses of 100-250 robots, a third of the events have
some). Delays up to the latest never add up to more (a schedule below the latest stays
below it), so the held robots' part stays; the picked robots' part is exact unless a
robot pushed a held partner that it (or another picked robot) waits for further on,
which then releases it later than planned: the exact evaluation that decides counts
that. A picked robot may also pass a held partner first where that delays the partner
past its latest, at a price per unit past it (PUSH): a trade the held times alone never
allow (one robot's gain against another's loss), which the evaluation then prices
exactly; the partner's held times are not moved for the robots put back after it.
Objectives: the sums, as :mod:`service.solvers.lns` (avg_completion, avg_delay;
for avg_delay the held robots' events before their completion may then wait longer,
which costs their part a little: the evaluation counts it); a passage
minimises its robot's last delay, which for avg_delay is a proxy that the evaluation
corrects. Deterministic for a seed where the steps are capped (``max_steps``).

**Annealed acceptance** (``ReinsertConfig.anneal``, default ANNEAL): a repair dearer than
the current answer by x is kept with probability exp(-x / T), the temperature T falling
linearly from ``anneal`` times the best cost (twice that from LARGE_FLEET robots:
LARGE_HEAT) to zero over the search (over the first half of its turns' time, in
:mod:`service.solvers.turns`, then cold: only cheaper repairs kept); the search returns
the cheapest answer it saw.
Keeping only cheaper repairs, it stalled: alone from the plans, on the generated
warehouses of 100 and 250 robots, it read 0.76-0.94 of the best known after 2 s and
barely more after 5 s with 2.5 times the steps (session 32), and two repairs a step on two
threads (merged where their robots were disjoint) gained nothing once the first ~20
steps had both improved. See ANNEAL for what annealing gained. While hot, a step tries
one order (HOT_ORDERS): more steps of rougher repairs, which the annealing tolerates.

**A plan** (:func:`planned_starts`) is the same repair of the whole fleet from no robot
placed: prioritized planning in one order, each robot on its exact passage past those
before it; ``auto`` starts its large problems from the cheapest of a few. Where fixed
directions between robots close cycles (robots parked in others' ways), each placement is
also bounded by the transitive closure of the fixed node order (:func:`_plan_reach`,
:func:`_repair`): without, no plan was found on most such warehouses.
"""

from __future__ import annotations

import heapq
import threading
import time
from dataclasses import dataclass
from typing import NamedTuple

import networkx as nx
import numba
import numpy as np

from service.core.assignment import Assignments
from service.core.digraph import is_dag, path_arcs
from service.core.evaluate import Evaluation
from service.core.problem import Problem
from service.solvers.registry import SolveContext, SolverOutput, register
from service.solvers.tabu import plain_start

__all__ = [
    "ANNEAL",
    "HOT_ORDERS",
    "REINSERT_OBJECTIVES",
    "ReinsertConfig",
    "ReinsertResult",
    "cheapest_plan",
    "planned_starts",
    "reinsert_search",
]

# Whether a robot's partners are drawn by the waits critical to the cost (binding ones from
# which a path of tight constraints leads to an event the cost reads) rather than by every
# binding wait: a wait no completion depends on gains nothing when repaired. Measured
# (session 46, `python -m bench.ab --b service.solvers.reinsert.CRITICAL_BLOCKING=False`,
# ``auto``, avg_completion, two-way and two-lane warehouses of 100 and 250 robots, one-way
# and mixed of 250, two seeds): 1 s 0.9709 / 0.9651 (19 cheaper, 17 dearer of 36), on other
# worlds 0.9699 / 0.9679 (20 / 16); 5 s 0.9722 / 0.9657 (14 / 10 of 24). By family the
# sign varies from one set of worlds to the next (two-way 100: 1 / 5, then 4 / 2).
CRITICAL_BLOCKING = True
# Objectives a repair's part of the cost stands for (sums over robots; measured for both,
# see ``portfolio.REINSERT_SHARE``).
REINSERT_OBJECTIVES = ("avg_completion", "avg_delay")
TOL = 1e-9  # delays closer than this are equal
# Annealing's first temperature, as a share of the best cost (see the module). Measured
# (session 32; ``auto`` through the dispatcher, 1 and 5 s, on the 12 generated warehouses of
# 100 and 250 robots of ``bench.anytime``, seeds 0-1, mean cost ratio against the best
# known on one yardstick for all runs; cooling over all of the re-insertion turns): none
# 0.8032 / 0.9012 and, again, 0.8005 / 0.9001; 0.01 0.8163 / 0.9193; 0.02 0.8074 / 0.9302
# and, again, 0.8098 / 0.9296; 0.04 0.8043 / 0.9243. Cooling within each turn instead
# (each search from its own start to its deadline) read 0.7953 / 0.9233 at 0.02. Since
# repairs may push held robots (PUSH; session 36, the same worlds, four seeds at 1 s and
# two at 5 s, beside two same-code controls a run, references r5): 1 s 0.01 0.8672, 0.04
# 0.8860 against 0.8766 / 0.8794; 5 s 0.04 0.9671 against 0.9540 / 0.9632 and, again,
# 0.9605 against 0.9537 / 0.9528 (250 robots +0.01-0.02, 100 robots even or -0.005).
# Since session 57's derived densities (following allowed wherever the paths allow it),
# 0.08 with FLEET_SHARE's larger neighbourhoods (session 58, ``python -m bench.ab``, 1 s,
# four seeds, three worlds a kind: wh_two_way, wh_two_lane 100 and 250, floor_dense 100):
# 0.08 against 0.04 0.9111 / 0.9027 (40 cheaper, 20 dearer of 60), 0.02 0.9015 / 0.8985
# (30 / 29), 0.16 against 0.08 0.9217 / 0.9139 (30 / 30); together with FLEET_SHARE see there.
ANNEAL = 0.08
# ... times this for fleets of LARGE_FLEET robots and more (ReinsertConfig.large_heat). Since
# session 64's lineages and 65's meetings (each turn of a lineage starts from its own best,
# so a hot turn is a wide kick from it), the large fleets gained from a hotter start and the
# small ones did not. Measured (session 69, ``python -m bench.ab --b
# service.solvers.reinsert.ReinsertConfig.anneal=0.16``, ``auto`` as the service runs it,
# 0.08 everywhere against 0.16 everywhere; cost ratio A / B, B's gain with its 95 % interval
# over worlds, runs cheaper / dearer with 0.16): 5 s, wh_two_way, wh_two_lane, floor_dense of
# 100 and wh_two_way, wh_two_lane of 250 robots (three worlds, two seeds) 0.9798 / 0.9868,
# +0.0070 (-0.0023, +0.0180), 20 / 9, every kind cheaper; other worlds (``--seed 600000``:
# wh_two_way, wh_two_lane, wh_mixed, floor_dense of 100, wh_two_way, wh_one_way, wh_mixed
# of 250, two worlds) 0.9804 / 0.9856, +0.0052 (-0.0026, +0.0138), 15 / 13; 1 s, the first
# kinds (six worlds) and floor_dense, wh_two_way of 50 0.9716 / 0.9769, +0.0053 (+0.0003,
# +0.0108), 39 / 38 (250 robots +0.011 and +0.019, floor_dense 50 -0.005); avg_delay, 1 s,
# the first kinds (three worlds) 0.9311 / 0.9614, +0.0303 (+0.0081, +0.0522), 22 / 8; the
# sets wh_50, wh_100, geo_dense_25 and wh_two_way 25, floor_sparse, wh_two_lane 50 (four
# worlds) 0.9991 / 0.9982, -0.0009 (-0.0022, +0.0001), 5 / 8, proven 18 / 18 (wh_two_way
# 25 -0.004, floor_sparse 50 -0.004); 1 s, wh_two_way, wh_two_lane, floor_dense,
# floor_sparse of 75 (four worlds) even, 0.9866 / 0.9876, +0.0010 (-0.0056, +0.0080), 16 /
# 14: so from 100 robots. Hotter still, 0.32 against 0.16: 1 s -0.0036 (-0.0103,
# +0.0024), 5 s -0.0004 (-0.0098, +0.0061); cooler at 5 s, 0.04 against 0.08: -0.0057
# (-0.0135, +0.0008).
LARGE_HEAT = 2.0
LARGE_FLEET = 100
# A picked robot may pass a held partner first even where that delays the partner past
# its latest, at a price per unit of delay past it of PUSH times the incumbent's mean slope
# (:meth:`~service.core.evaluate.Evaluator.evaluate_with_latest`: the objective's rise
# per unit of an event's delay past its latest, to first order, averaged over events):
# a flat price, since a push spreads further than the first order where it passes the
# next robots' slack, and the mean scales with how far pushes spread on the fleet (on
# warehouses of 250 robots 7.5 on two-lane, 31 on two-way ones). Measured (session 36;
# re-insertion alone from the plans for 0.8 s, the 12 generated warehouses of 100 and
# 250 robots, two seeds, against r5): held at their latest (no pushes) 0.8167, PUSH 2
# 0.8755, 4 0.8712, 8 0.8517; a price per event by its own slope (x0.5-2) 0.52-0.66,
# stuck on two-way warehouses (pushes there spread far past the first order); a price
# of 16 or 32 for every fleet good on two-lane, bad on two-way ones. ``auto`` at 1 s
# (four seeds, beside two controls): 0.8523 / 0.8537 -> PUSH 1 0.8684, 2 0.8889, 4 0.8761.
PUSH = 2.0
# Passages tried per robot, in a cold step where room for following-type was short, as if
# it were not and then without the conflicts that overfilled a binding clique (see the
# module, "Room for following-type"; 0: none). Read at each call (so that ``bench.ab`` can
# vary it). Measured (session 54, ``python -m bench.ab``, ``auto``, 0 against 4; docs/
# benchmarks.md "Room for following-type in a passage"): 1 s, wh_two_way and wh_two_lane
# of 100 and 250 robots (three worlds, two seeds) 0.9332 -> 0.9478 (15 cheaper, 9 dearer
# of 24), other worlds (``--seed 500000``, two) 0.9685 -> 0.9788 (11 / 5), wh_one_way,
# wh_mixed, wh_parked of 100 and wh_one_way, wh_mixed of 250 (two) 0.9578 -> 0.9815
# (15 / 5); avg_delay 1 s 0.8584 -> 0.8759 (16 / 4); 5 s 0.9744 -> 0.9838 (14 / 9); the
# sets wh_25, wh_50, wh_100, geo_dense_25 at 5 s proven 26 / 26 as before. In hot steps
# too: 0.9431 / 0.9346 (a step costs up to twice as much; hot, a step's count matters
# more); in the plans too: 0.9497 / 0.9486 (14 / 7 cheaper without); 2 rounds against 4
# even (12 / 12).
# Without the rule "no more following-type conflicts", 400 cold steps from the cheapest
# plan reached 155.0 on wh_two_lane/250/0 against 147.4 without rounds (148.0 with it),
# and 163.0 on wh_two_way/100/0 against 184.0 (164.3 with it).
ROOM_ROUNDS = 4
# Whether the last robot of an order may take more following-type conflicts than the
# passage it replaces (no robot put back after it can starve). Read at each call. Measured
# (session 54, ``python -m bench.ab``, 1 s, wh_two_way and wh_two_lane of 100 and 250,
# three worlds, two seeds): 0.9439 -> 0.9540 (16 cheaper, 8 dearer of 24; every family
# better); wh_one_way, wh_mixed, wh_parked 100 and wh_one_way, wh_mixed 250 (two worlds)
# 0.9633 -> 0.9817 (15 / 5); avg_delay 0.8656 -> 0.8910 (15 / 5). A rule for every
# robot, taking more wherever every clique it fills keeps room for all the
# may-be-following conflicts of the robots not yet put back (their count per clique kept
# up to date through the repair): 0.9480 -> 0.9555 (15 / 9), no better, with an (M,)
# count per repair; not kept.
ROOM_LAST_MORE = True
# Random orders tried per step while annealing is hot (ReinsertConfig.hot_orders; once
# cold, ReinsertConfig.orders). Measured (session 37; ``auto`` through the dispatcher on
# the 12 generated warehouses of 100 and 250 robots, references r5, beside same-code
# controls in the same run): 1 s (four seeds) 1 while hot 0.9018 against 0.8854 / 0.8755
# and, other seeds, 0.9049 against 0.8881; 5 s (two seeds) 0.9585 / 0.9676 against
# 0.9529 / 0.9587 (250 robots +0.02, 100 robots -0.008). One order all the time: 1 s
# 0.8993 / 0.9028 against 0.8867 / 0.8879, but 5 s 0.9444 against 0.9589 (four seeds).
HOT_ORDERS = 1
# Robots re-inserted per step at first, as a share of the fleet (ReinsertConfig.robots at
# least, so fleets of up to 40 robots keep ROBOTS): a step's evaluation walks the whole fleet,
# its repair only the picked robots, so bigger fleets afford more robots a step. Measured
# (session 33; ``auto`` through the dispatcher on the generated warehouses, mean cost
# ratio on one yardstick per comparison, each beside a control in the same hour): 16
# robots instead of 8 at 250 robots, 1 s (four seeds) 0.7857 -> 0.7917 and, with the
# 100-robot worlds in the run, 0.790 / 0.793 -> 0.802 (two-way), 0.804 -> 0.809
# (two-lane); 5 s (two seeds, twice) 0.9147 -> 0.9378 and 0.9169 -> 0.9288; 24 robots
# 0.7893 at 1 s. At 100 robots 16 read 0.808 against 0.825 (two-way, 1 s) and 4 robots
# 0.783: 8 stayed there then (since session 41 6, see ROBOTS). Since session 57's derived
# densities (following allowed wherever the paths allow it, so a robot's passage depends
# on more partners) larger neighbourhoods pay (session 58, ``python -m bench.ab``, 1 s,
# wh_two_way and wh_two_lane 250, three worlds, four seeds): 1/32 against 1/16 0.7982 /
# 0.8223 (7 cheaper, 17 dearer of 24), 0.1 against 1/16 0.8677 / 0.8396 (17 / 7), 0.128
# against 0.1 0.8881 / 0.8740 (14 / 10), 0.16 (40 robots, max_robots 40) against 0.1
# 0.8871 / 0.8597 (20 / 4), 0.24 (60) against 0.16 even (0.8879 / 0.8892). Together with
# ANNEAL 0.08 against both as before, other worlds (``--seed 600000``, two a kind, two
# seeds): wh_two_way, wh_two_lane, wh_one_way, wh_mixed 250 0.9122 -> 0.9728 (15 cheaper, 1
# dearer of 16), wh_two_way, wh_two_lane, wh_mixed, floor_dense 100 (16 robots a step)
# 0.9691 -> 0.9815 (13 / 3), wh_two_way 25, wh_two_lane, floor_dense, floor_sparse 50 (6-8
# robots) 0.9815 -> 0.9884 (9 / 4), the sets wh_50, wh_100 even; ``--seed 500000`` with
# ROBOTS 10 too: 100 and 250 robots better in 26 of 32 runs, but floor_sparse 50 0.9911 ->
# 0.9704 and wh_two_way 25 0.9988 -> 0.9944: ROBOTS stays. With neighbourhoods starting
# at 0.16 of the fleet, MAX_SHARE no longer makes them grow in ``auto``.
FLEET_SHARE = 0.16
# Robots re-inserted per step at first, at least. Measured (session 41, ``python -m
# bench.ab``: ``auto`` through the dispatcher, variants interleaved run by run, mean cost
# ratio against the r5 references, runs where 6 cost less / more than 8), 6 against 8:
# wh_two_way and wh_two_lane 100 (since MID_LNS_LEAST_S the turns take a 1-s budget whole
# there) 1 s, four seeds, 0.9402 / 0.9317 (16 / 8; 12 against 8: 0.9239 / 0.9342, 8 / 16),
# 5 s, two seeds, 0.9705 / 0.9679 (7 / 5), avg_delay 1 s 0.9359 / 0.9148 (9 / 3); kinds not
# tuned on (wh_one_way, wh_mixed, wh_parked 100) 1 s 0.9737 / 0.9707 (9 / 9). Fleets of
# 41 robots and more take FLEET_SHARE (104 and more until session 58).
ROBOTS = 6
# Neighbourhoods grow on a stall up to this share of the fleet (and max_robots). While
# annealing is hot nearly every step counts as a stall (a dearer repair kept improves on no
# best), so every turn's neighbourhoods soon reached 32 robots: a third of a 100-robot fleet,
# whose greedy repairs are rough and slow. Measured (session 47, ``python -m bench.ab``,
# ``auto``, avg_completion, 1 s unless said, the share against 1.0, i.e. growth to 32):
# wh_two_way, wh_two_lane, wh_one_way, wh_mixed, wh_parked of 100 robots and wh_two_way,
# wh_two_lane of 50 (three worlds, two seeds) 0.9568 -> 0.9863 at 1/8 (33 cheaper, 8
# dearer of 42; two-way 100 0.926 -> 0.968, parked 100 0.935 -> 0.995, two-lane 100 even);
# growth to 16 at 250 robots (their first size: no growth) 0.8757 / 0.9353 -> 0.8727 /
# 0.9196 (two-way / two-lane); no growth at all against 1/8 (100 and 250 robots) 0.9352
# against 0.9585 (8 / 24); 1/5 against 1/8 even (0.9840 / 0.9844); 5 s, 100 and 250 robots,
# two sets of worlds 0.9775 / 0.9835 (9 / 7) and 0.9943 / 0.9780 (11 / 5); avg_delay see
# docs/benchmarks.md ("Neighbourhoods that stop growing", session 47).
MAX_SHARE = 1 / 8


# Repairs of an order tried again where a robot had no passage, each with that robot put
# back first. Only a robot fixed to pass another first can lack one (any other may pass
# after all its partners): where robots put back before it made it wait too long. Put
# back first, it waits for held robots only, no longer than it did in the incumbent,
# whose passage (with the room of its following-type conflicts, see _repair) is then
# still open to it. On the generated warehouses of 250 robots (~230 fixed directions:
# robots parked in others' ways), 300 steps of 16 robots in 3 orders: without either,
# 42-48 % of steps found no repair at all; with the room alone 10-38 %, with both 0-2 %.
RETRIES = 3
# Fleets of up to this many nodes get a plan's order bounds where fixed directions between
# robots close cycles (a (V, V) table: 16 MB here; see _repair).
REACH_MAX_NODES = 4000


@dataclass(frozen=True)
class ReinsertConfig:
    """Robots per step, orders tried per step, and how neighbourhoods grow."""

    robots: int = ROBOTS  # robots re-inserted per step, at first, at least
    # ... and at first this share of the fleet where that is more (see FLEET_SHARE)
    fleet_share: float = FLEET_SHARE
    # Random orders tried per step, the best evaluated. Measured (session 34, `auto` at 1 s
    # on the 12 generated warehouses of 100 and 250 robots, four seeds, references r5,
    # alternating): 3 orders 0.8831 / 0.8769 (100 robots) and 0.7796 / 0.7777 (250), 2
    # orders 0.8976 / 0.9006 and 0.7871 / 0.7932, 1 order 0.8966 and 0.7819; at 5 s (two
    # seeds) 2 and 3 even (0.9454 / 0.8854 against 0.9447 / 0.8844). 3 was chosen while
    # ~45 % of the 250-robot steps found no repair at all (see RETRIES). Since repairs
    # may push held robots (PUSH), this holds for a search once cold; while hot, see
    # hot_orders.
    orders: int = 2
    # Random orders tried per step while annealing is hot (a repair dearer than the
    # current answer may still be kept): there a step's count matters more than how good
    # its repair is. See HOT_ORDERS.
    hot_orders: int = HOT_ORDERS
    # After steps without improvement that together freed stall_cover times the fleet,
    # neighbourhoods grow by ``growth`` (up to max_robots and max_share of the fleet, never
    # below where they start), as in LNS. See MAX_SHARE.
    stall_cover: float = 1.0
    growth: float = 1.5
    max_robots: int = 40  # 32 until session 58 (see FLEET_SHARE)
    max_share: float = MAX_SHARE
    blocking_weight: float = 10.0  # a binding wait against 1 per shared conflict
    # Steps without improvement, each re-inserting the whole fleet (in ``orders`` random
    # orders), after which the search ends (None: never): only fleets of up to
    # max_robots get there. The ``reinsert`` solver sets it, so that a 4-robot problem
    # no longer takes the whole time limit (5 s by default); ``auto``'s turns do not
    # (unmeasured there).
    whole_fleet_plateau: int | None = None
    # Annealed acceptance: a repair costing more than the current answer is kept too, with
    # probability exp(-excess / T), T falling linearly from ``anneal`` x the best cost
    # to 0 over the search's cooling span (0: only cheaper repairs are kept); the best
    # answer seen is what the search returns. See ANNEAL.
    anneal: float = ANNEAL
    # ... times this for fleets of ``large_fleet`` robots and more (see LARGE_HEAT)
    large_heat: float = LARGE_HEAT
    large_fleet: int = LARGE_FLEET
    # A unit of delay past a held robot's latest costs push x the incumbent's mean slope
    # (0: none allowed, held robots stay within their latest). See PUSH.
    push: float = PUSH

    def heat(self, n_robots: int) -> float:
        """Annealing's first temperature for a fleet of ``n_robots``, as a share of the
        best cost: ``anneal``, times ``large_heat`` from ``large_fleet`` robots."""
        return self.anneal * (self.large_heat if n_robots >= self.large_fleet else 1.0)


# The ``reinsert`` solver's: small fleets grow to the whole fleet, where it stops.
SOLVER_CONFIG = ReinsertConfig(whole_fleet_plateau=64, max_share=1.0)


class ReinsertResult(NamedTuple):
    """What a search ended with: the best answer, its cost and the steps taken."""

    best: Assignments
    cost: float
    steps: int


class _Static(NamedTuple):
    """The arrays every step reads, built once per search (M conflicts, R robots, V nodes,
    E events, Q cliques).

    Robot-major: slot j of rc_start[r]:rc_start[r+1] is robot r's side of conflict
    rc_conf[j], and every rc_/own_/oth_ array is indexed by slot, so that a robot's
    passage reads its conflicts' data in one sweep, not scattered over (M,) arrays (a
    repair of 16 robots at 250 robots 0.75-0.85 -> 0.58-0.65 ms, the same answers;
    session 34). ``own_*`` is the evaluator's slot (see Evaluator._build_slots) where
    r passes second (its pair enter waits on the partner), ``oth_*`` the one where the
    partner does."""

    rc_start: np.ndarray  # (R+1,) robot r's slots are rc_start[r]:rc_start[r+1]
    rc_conf: np.ndarray  # (2M,) each slot's conflict
    rc_side: np.ndarray  # (2M,) the robot's side of it (0: a, 1: b)
    rc_partner: np.ndarray  # (2M,) the other robot
    rc_node: np.ndarray  # (2M,) the robot's node of it (0: its first)
    rc_partner_node: np.ndarray  # (2M,) the partner's node
    rc_force: np.ndarray  # (2M,) int, +1 the robot must pass first, -1 second, 0 free
    rc_may_follow: np.ndarray  # (2M,) bool, following-type allowed at all
    rc_roomy: np.ndarray  # (2M,) bool, allowed and in no binding clique: it needs no room
    own_live: np.ndarray  # (2M,) bool
    own_target: np.ndarray  # (2M,) the robot's pair-enter event
    own_source: np.ndarray  # (2, 2M) by type, the partner's event it waits on
    own_offset: np.ndarray  # (2, 2M)
    oth_live: np.ndarray  # (2M,) bool
    oth_target: np.ndarray  # (2M,) the partner's pair-enter event
    oth_source: np.ndarray  # (2, 2M) by type, the robot's event the partner waits on
    oth_offset: np.ndarray  # (2, 2M)
    conf_nodes: np.ndarray  # (M, 2) node of each side
    robot_start: np.ndarray  # (R+1,) nodes by robot
    ev_start: np.ndarray  # (R+1,) events by robot
    ev_node: np.ndarray  # (E,) the robot's node (0: its first) of each event
    fixed_type: np.ndarray  # (M,) int8 -1 free, 0 exclusive, 1 following
    cq_start: np.ndarray  # (M+1,) conflict -> its binding cliques
    cq_clique: np.ndarray

    @classmethod
    def of(cls, ctx: SolveContext) -> _Static:
        """The arrays of ``ctx``'s problem, built once per context (~13 ms at 22,000
        conflicts, which the turns, a new search each, would pay every turn)."""
        cached = ctx.__dict__.get("_reinsert_static")
        if cached is None:
            cached = ctx.__dict__["_reinsert_static"] = cls._build(ctx)
        return cached

    @classmethod
    def _build(cls, ctx: SolveContext) -> _Static:
        p, graph = ctx.problem, ctx.evaluator.graph
        n_conf = p.n_conflicts
        conf_robots = np.stack([p.node_robot[p.conf_a], p.node_robot[p.conf_b]], axis=1)
        conf_nodes = np.stack([p.conf_a, p.conf_b], axis=1).astype(np.int64)
        order = np.argsort(conf_robots.ravel(), kind="stable")  # (2M,)
        rc_start = np.searchsorted(conf_robots.ravel()[order], np.arange(p.n_robots + 1))
        conf, side = order // 2, order % 2  # (2M,) each slot's conflict and side
        own, oth = 2 * conf + side, 2 * conf + 1 - side  # (2M,) evaluator slots
        forced = p.forced[conf].astype(np.int64)
        event_robot = p.event_robot  # (E,)
        ev_node = np.zeros(p.events.size, dtype=np.int64)
        pair_event = graph.target.reshape(n_conf, 2)  # (M, 2) each side's pair-enter event
        ev_node[pair_event[:, 0]] = p.conf_a
        ev_node[pair_event[:, 1]] = p.conf_b
        may_follow = ctx.orientation.may_follow & (p.fixed_type < 0)  # (M,)
        # Only cliques whose budget can bind are counted.
        cq_start, cq_clique = ctx.cliques.binding_by_conflict
        return cls(
            rc_start.astype(np.int64),
            conf.astype(np.int64),
            side.astype(np.int64),
            conf_robots[conf, 1 - side].astype(np.int64),
            conf_nodes[conf, side] - p.robot_start[conf_robots[conf, side]],
            conf_nodes[conf, 1 - side],
            np.where(forced == 0, 0, np.where((forced > 0) == (side == 0), 1, -1)),
            may_follow[conf],
            may_follow[conf] & (np.diff(cq_start) == 0)[conf],
            graph.live[own],
            graph.target[own].astype(np.int64),
            np.ascontiguousarray(graph.source[:, own], dtype=np.int64),
            np.ascontiguousarray(graph.offset[:, own]),
            graph.live[oth],
            graph.target[oth].astype(np.int64),
            np.ascontiguousarray(graph.source[:, oth], dtype=np.int64),
            np.ascontiguousarray(graph.offset[:, oth]),
            conf_nodes,
            p.robot_start.astype(np.int64),
            np.searchsorted(event_robot, np.arange(p.n_robots + 1)).astype(np.int64),
            ev_node - p.robot_start[event_robot],
            p.fixed_type,
            cq_start.astype(np.int64),
            cq_clique.astype(np.int64),
        )


@numba.njit(cache=True, nogil=True)
def _passage(
    st: _Static,
    js: np.ndarray,  # (K,) int, the robot's slots of its conflicts with placed partners
    kidx: np.ndarray,  # (K,) int, each partner node's rank among the distinct positions
    m: int,  # distinct partner positions
    follow: np.ndarray,  # (K,) bool, following-type allowed
    e0: int,  # the robot's first event
    ev_node: np.ndarray,  # (N,) int, the robot's node of each of its N events
    n_nodes: int,
    d: np.ndarray,  # (E+1,) float, the placed robots' delays; the robot's written on exit
    latest: np.ndarray,  # (E+1,) float, the latest delays the placed robots' events may take
    price: float,  # a unit of delay past a partner's latest, in the objective (inf: never)
    own: float,  # the robot's weight in the objective
    gap: np.ndarray,  # (n_nodes,) int, out: each node's gap among the sorted partner positions
    first: np.ndarray,  # (K,) bool, out: the robot passes first
    following: np.ndarray,  # (K,) bool, out: following-type
    bound_node: np.ndarray,  # (B,) int, the robot's node (0: its first) of each order bound
    bound_force: np.ndarray,  # (B,) int, +1 that node before the bound's, -1 after it
    deadlines: bool,  # False: passing first sets no deadline (see _repair)
) -> float:
    """The robot's passage with the least last delay past its placed partners, whose
    times ``d`` are held (see the module), plus ``price`` per unit it delays a partner
    past its latest -> that price paid (in the objective's units), or -1 if no passage
    exists (fixed directions against held times). Gap g of a node: its partners at the
    g smallest distinct positions pass first (the partner of conflict i iff kidx[i] <
    g). Exact for the robot alone. Pushes only where the robot has one node (on the
    generated warehouses every robot has one).

    Order bounds (B,, see :func:`_repair`; kidx[K + b] their nodes' ranks) bound a node's
    gap as a fixed direction would, with no time attached. Without ``deadlines``, a
    partner the robot passes first may be pushed past its latest, unpriced."""
    k = js.size + bound_node.size
    # Each conflict's release (robot second) and deadline (robot first), at its type.
    rel_e = np.empty(k, dtype=np.int64)  # events of the robot's own: 0..N-1
    rel_v = np.full(k, -np.inf)
    dl_e = np.empty(k, dtype=np.int64)
    dl_v = np.full(k, np.inf)
    # A unit of delay past the partner's latest, in units of the robot's delay; only for a
    # robot of one node, whose gap is chosen once (with several, the cheapest way into a
    # node's gap need not lead to the cheapest passage).
    past = price / max(own, 1e-300) if n_nodes == 1 else np.inf
    force = np.empty(k, dtype=np.int64)
    for b in range(bound_node.size):  # at the node's first event (none: no bound)
        i = js.size + b
        force[i], rel_e[i], dl_e[i] = bound_force[b], ev_node.size, ev_node.size
        for e in range(ev_node.size):
            if ev_node[e] == bound_node[b]:
                rel_e[i] = dl_e[i] = e
                break
    for i in range(js.size):
        j, t = js[i], 1 if follow[i] else 0
        force[i] = st.rc_force[j]
        rel_e[i] = st.own_target[j] - e0
        dl_e[i] = st.oth_source[t, j] - e0
        if st.own_live[j]:
            rel_v[i] = d[st.own_source[t, j]] + st.own_offset[t, j]
        if st.oth_live[j] and deadlines:
            dl_v[i] = latest[st.oth_target[j]] - st.oth_offset[t, j]
    # least[g]: least delay so far with the current node in gap g; back[n, g]: the gap
    # of node n-1 that least[g] came from on entering node n. On the first node, where
    # the feasible least[g] never fall as g grows, faster (see _first_node_release).
    least = np.zeros(m + 1)
    pen = np.zeros(m + 1)  # the price paid so far for partners pushed past their latest
    # (on the first node only: there are no pushes where the robot has more)
    back = np.empty((n_nodes, m + 1), dtype=np.int64)
    # While on the first node: up[g] / down[g + 1] lead to the nearest feasible gap at or
    # above / at or below g (m + 1 / -1 if none), so that scans skip infeasible gaps.
    up, down = np.arange(m + 2), np.arange(m + 2)
    by_rel, by_dl = _by_event(rel_e, ev_node.size + 1), _by_event(dl_e, ev_node.size + 1)
    r, t, current = 0, 0, 0
    for e in range(ev_node.size):
        while ev_node[e] > current:  # into the next node: its gap is at least the last's
            current += 1
            best, arg = np.inf, 0
            for g in range(m + 1):
                if least[g] < best - TOL:
                    best, arg = least[g], g
                elif least[g] <= best + TOL:
                    arg = g  # ties: the later gap (the robot yields)
                least[g] = best
                back[current, g] = arg
        while r < k and rel_e[by_rel[r]] == e:
            i = by_rel[r]
            r += 1
            lo = kidx[i] + 1  # gaps lo..m: the partner passes first
            if current == 0:
                _first_node_release(least, up, down, lo, rel_v[i], force[i])
                continue
            if force[i] > 0:
                least[lo:] = np.inf
            else:
                for g in range(lo, m + 1):
                    least[g] = max(least[g], rel_v[i])
            if force[i] < 0:
                least[:lo] = np.inf
        while t < k and dl_e[by_dl[t]] == e:
            i = by_dl[t]
            t += 1
            if current == 0:
                _first_node_deadline(least, pen, up, down, kidx[i], dl_v[i], past)
                continue
            for g in range(kidx[i] + 1):
                if least[g] > dl_v[i] + TOL:
                    least[g] = np.inf
    for n in range(current + 1, n_nodes):  # nodes after the last event keep the gap
        back[n] = np.arange(m + 1)
    best, arg = np.inf, -1
    for g in range(m + 1):
        if least[g] + pen[g] < best - TOL:
            best, arg = least[g] + pen[g], g
        elif least[g] + pen[g] <= best + TOL and arg >= 0:
            arg = g
    if arg < 0:
        return -1.0
    gap[n_nodes - 1] = arg
    for n in range(n_nodes - 1, 0, -1):
        gap[n - 1] = back[n, gap[n]]
    # The passage's least delays, one gap per node.
    delay, r = 0.0, 0
    for e in range(ev_node.size):
        while r < k and rel_e[by_rel[r]] == e:
            i = by_rel[r]
            r += 1
            if kidx[i] < gap[ev_node[e]]:
                delay = max(delay, rel_v[i])
        d[e0 + e] = delay
    # Directions; following-type only where the exclusive constraint would not hold.
    for i in range(js.size):
        j = js[i]
        first[i] = kidx[i] >= gap[st.rc_node[j]]
        if first[i]:
            live, need = (
                st.oth_live[j],
                d[st.oth_source[0, j]] + st.oth_offset[0, j] > d[st.oth_target[j]] + TOL,
            )
        else:
            live, need = (
                st.own_live[j],
                d[st.own_source[0, j]] + st.own_offset[0, j] > d[st.own_target[j]] + TOL,
            )
        following[i] = follow[i] and live and need
    return pen[arg] * own if pen[arg] > 0 else 0.0


@numba.njit(cache=True, nogil=True)
def _first_node_release(
    least: np.ndarray,  # (m+1,) float
    up: np.ndarray,  # (m+2,) int
    down: np.ndarray,  # (m+2,) int
    lo: int,
    value: float,
    force: int,
) -> None:
    """A release on the robot's first node: gaps lo..m (the partner passes first) wait
    for ``value``; with ``force`` +1 they are infeasible, with -1 gaps 0..lo-1 are.

    On the first node the feasible least[g] never fall as g grows (from zeros, releases
    raise suffixes, and gaps only drop out), so the raise stops at the first feasible
    gap it does not raise, and infeasible gaps are skipped (``up``, ``down``, see
    :func:`_nearest`): on the generated warehouses (one node per robot, ~175 partners)
    the programme went from ~4,100 gap visits a robot to ~1,100."""
    if force > 0:
        _drop_range(least, up, down, lo, least.size - 1)
    else:
        g = _nearest(up, lo)
        while g < least.size and least[g] < value:
            least[g] = value
            g = _nearest(up, g + 1)
    if force < 0:
        _drop_range(least, up, down, 0, lo - 1)


@numba.njit(cache=True, nogil=True)
def _first_node_deadline(
    least: np.ndarray,
    pen: np.ndarray,
    up: np.ndarray,
    down: np.ndarray,
    hi: int,
    value: float,
    price: float,
) -> None:
    """A deadline on the robot's first node: gaps 0..hi (the robot passes first) whose
    least delay exceeds ``value`` are infeasible, or with a finite ``price`` pay it per
    unit past ``value`` (``pen``); scanning down from ``hi`` it stops at the first
    feasible gap within it (see :func:`_first_node_release`)."""
    g = _nearest(down, hi + 1) - 1
    while g >= 0 and least[g] > value + TOL:
        if np.isfinite(price):
            pen[g] += (least[g] - value) * price
        else:
            _drop(least, up, down, g)
        g = _nearest(down, g) - 1


@numba.njit(cache=True, nogil=True)
def _drop_range(least: np.ndarray, up: np.ndarray, down: np.ndarray, lo: int, hi: int) -> None:
    """Gaps lo..hi infeasible (each feasible one visited once)."""
    g = _nearest(up, max(lo, 0))
    while g <= hi:
        _drop(least, up, down, g)
        g = _nearest(up, g + 1)


@numba.njit(cache=True, nogil=True)
def _drop(least: np.ndarray, up: np.ndarray, down: np.ndarray, g: int) -> None:
    """Gap g infeasible: the scans step over it."""
    least[g] = np.inf
    up[g] = g + 1
    down[g + 1] = g


@numba.njit(cache=True, nogil=True)
def _nearest(link: np.ndarray, x: int) -> int:
    """The root of x in ``link`` (a union-find forest, halving the paths it walks): the
    nearest index from x on, in the direction the links point, that is its own link."""
    while link[x] != x:
        link[x] = link[link[x]]
        x = link[x]
    return x


@numba.njit(cache=True, nogil=True)
def _by_event(event: np.ndarray, n_events: int) -> np.ndarray:
    """(K,) indices of ``event`` (K,) int in 0..n_events-1, by event, ties in index order:
    a counting sort (with it in place of two argsorts and without a table filled per node,
    re-insertion steps at 250 robots ran 1.0-1.3x as fast, session 28)."""
    start = np.zeros(n_events + 1, dtype=np.int64)
    for e in event:
        start[e + 1] += 1
    for e in range(n_events):
        start[e + 1] += start[e]
    out = np.empty(event.size, dtype=np.int64)
    for i in range(event.size):
        out[start[event[i]]] = i
        start[event[i]] += 1
    return out


@numba.njit(cache=True, nogil=True)
def _repair(
    order: np.ndarray,  # (k,) int, the picked robots in the order they are put back
    st: _Static,
    d: np.ndarray,  # (E+1,) float, the incumbent's delays; the picked robots' rewritten
    latest: np.ndarray,  # (E+1,) float, the held robots' latest delays; the picked ones' set
    pos: np.ndarray,  # (V,) float, a topological order; the picked robots' nodes moved
    room: np.ndarray,  # (Q,) int, following-type conflicts each binding clique has left
    a_first: np.ndarray,  # (M,) bool, rewritten on the picked robots' conflicts
    following: np.ndarray,  # (M,) bool, likewise
    weight: np.ndarray,  # (E+1,) float, each event delay's weight in the objective
    preferred: np.ndarray,  # (M,) bool, conflicts given room for following-type first
    price: float,  # a unit of delay past a placed robot's latest (inf: never), see _passage
    rounds: int,  # ROOM_ROUNDS
    last_more: bool,  # ROOM_LAST_MORE
    reach: np.ndarray,  # (V, V) bool, the fixed order's closure (see _fixed_reach), or (0, 0)
    cap: float,  # the repair stops once its cost reaches this (inf: never)
) -> tuple[float, int]:
    """Put the picked robots back in ``order``, each on its passage past the robots
    placed so far (held ones, then those put back before it) -> (the picked robots' part
    of the objective plus the ``price`` of the pushes past a placed robot's latest, -1),
    or (inf, -1) once that reaches ``cap`` (it only grows as robots are put back: a
    step's later orders stop where they cannot be the cheapest), or (inf, the index in
    ``order`` of the first robot that had
    no passage: one fixed to pass a held robot first whose wait for robots put back
    before it made that too late). ``room`` must already count the picked robots'
    conflicts as exclusive; a robot's conflicts get it in turn, the ``preferred`` ones
    first (a step prefers the incumbent's following-type conflicts: a robot put back
    first then keeps the passage it had, which needed them; in turn by conflict alone,
    a robot that needed one of two conflicts sharing a clique's last room lost it on
    the generated warehouses, and with it every passage where it was fixed to pass
    first); with ``rounds`` (ROOM_ROUNDS) more, where room was short, see :func:`_roomier`.

    With ``reach`` (a plan where fixed directions between robots close cycles), each of
    the robot's nodes also stays before every placed node it must precede in the fixed
    order, through any robots, and after every one that must precede it: without, a
    placed robot could have been put before another that it must follow through robots
    not yet placed, leaving the robot between them no gap. A robot there that finds no
    passage within the placed robots' times then takes one that ignores them (the
    evaluation moves them): on such cycles a robot is often placed after robots it must
    pass first, or that its bounds put after it, whose times it cannot meet."""
    placed = np.ones(st.rc_start.size - 1, dtype=np.bool_)
    placed[order] = False
    need = np.zeros(room.size if rounds > 0 else 0, dtype=np.int64)  # (Q,) _roomier's scratch
    cost = 0.0
    bound_node, bound_force = np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    bound_pos = np.empty(0)  # no bounds (a search's repair): none found per robot
    for n_placed, r in enumerate(order):
        if reach.size > 0:
            bound_node, bound_force, bound_pos = _order_bounds(st, r, placed, pos, reach)
        lo, hi = st.rc_start[r], st.rc_start[r + 1]
        js = np.empty(hi - lo, dtype=np.int64)  # (K,) its slots with placed partners
        k = 0
        for j in range(lo, hi):
            if placed[st.rc_partner[j]]:
                js[k] = j
                k += 1
        js = js[:k]
        partner_pos = np.empty(k + bound_pos.size)  # the bounds' nodes after the partners'
        for i in range(k):
            partner_pos[i] = pos[st.rc_partner_node[js[i]]]
        partner_pos[k:] = bound_pos
        kidx, ranks = _distinct_ranks(partner_pos)
        e0, e1 = st.ev_start[r], st.ev_start[r + 1]
        n_nodes = st.robot_start[r + 1] - st.robot_start[r]
        gap = np.empty(n_nodes, dtype=np.int64)
        first = np.empty(k, dtype=np.bool_)
        chosen = np.empty(k, dtype=np.bool_)
        ev_node = st.ev_node[e0:e1]
        own = weight[e0:e1].sum()
        follow = _room_for(st, js, preferred, room)
        passing = _Passing(
            js, kidx, ranks.size, e0, ev_node, n_nodes, latest, price, own, bound_node,
            bound_force, reach.size > 0,
        )  # fmt: skip
        pushed = _passage_of(st, passing, follow, d, gap, first, chosen)
        if pushed < 0:
            return np.inf, n_placed
        _give_back(st, st.rc_conf[js[follow & ~chosen]], room)  # the room it did not need
        if rounds > 0 and (st.rc_may_follow[js] & ~follow).any():  # room was short
            last = last_more and n_placed == order.size - 1
            pushed = _roomier(st, passing, d, gap, first, chosen, pushed, room, need, rounds, last)
        cost += pushed
        for i in range(k):
            c = st.rc_conf[js[i]]
            a_first[c] = first[i] == (st.rc_side[js[i]] == 0)
            following[c] = chosen[i] or st.fixed_type[c] == 1
        _place(pos, st.robot_start[r], gap, ranks)
        latest[e0:e1] = d[e0:e1]  # robots placed in this repair keep their times
        placed[r] = True
        for e in range(e0, e1):
            cost += weight[e] * d[e]
        if cost >= cap:
            return np.inf, -1
    return cost, -1


@numba.njit(cache=True, nogil=True)
def _room_for(st: _Static, js: np.ndarray, preferred: np.ndarray, room: np.ndarray) -> np.ndarray:
    """(K,) bool: following-type allowed on the robot's slots ``js`` (K,) and room for it
    taken (``room`` (Q,)), the ``preferred`` (M,) conflicts' first (see :func:`_repair`).
    Conflicts in no binding clique need none and are allowed at once (on the generated
    warehouses, every one; taking room for each, in two passes over a robot's ~175
    conflicts, a step of 40 robots at 250 robots took 1.46 ms, 1.36 without, session 66)."""
    follow = st.rc_roomy[js]
    bound = np.flatnonzero(st.rc_may_follow[js] & ~follow)  # conflicts that take room
    for first_pass in (True, False):  # room for the preferred conflicts first
        for i in bound:
            c = st.rc_conf[js[i]]
            if preferred[c] == first_pass:
                follow[i] = _take_room(st, c, room)
    return follow


class _Passing(NamedTuple):
    """A robot's passage in a repair, what :func:`_passage_of` and :func:`_roomier` read
    besides the following-type allowed and their outputs (K slots with placed partners,
    N events, B order bounds; the fields as :func:`_passage`'s arguments)."""

    js: np.ndarray  # (K,) int
    kidx: np.ndarray  # (K,) int
    m: int
    e0: int
    ev_node: np.ndarray  # (N,) int
    n_nodes: int
    latest: np.ndarray  # (E+1,) float
    price: float
    own: float
    bound_node: np.ndarray  # (B,) int
    bound_force: np.ndarray  # (B,) int
    bounded: bool  # a plan's order bounds are set


@numba.njit(cache=True, nogil=True)
def _passage_of(
    st: _Static,
    pa: _Passing,
    follow: np.ndarray,  # (K,) bool, following-type allowed
    d: np.ndarray,  # (E+1,) float
    gap: np.ndarray,  # (n_nodes,) int, out
    first: np.ndarray,  # (K,) bool, out
    chosen: np.ndarray,  # (K,) bool, out
) -> float:
    """:func:`_passage` with deadlines, then (only where a plan's order bounds are set,
    ``pa.bounded``, and it found none) without: arguments and result as there."""
    pushed = -1.0
    for deadlines in (True, False):
        if pushed < 0 and (deadlines or pa.bounded):
            pushed = _passage(
                st, pa.js, pa.kidx, pa.m, follow, pa.e0, pa.ev_node, pa.n_nodes, d, pa.latest,
                pa.price, pa.own, gap, first, chosen, pa.bound_node, pa.bound_force, deadlines,
            )  # fmt: skip
    return pushed


@numba.njit(cache=True, nogil=True)
def _order_bounds(
    st: _Static, r: int, placed: np.ndarray, pos: np.ndarray, reach: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robot r's order bounds from ``reach`` (V, V): for each of its nodes and each placed
    robot's node one must precede in the fixed order (-> its node (0: its first) (B,), +1
    where r's node comes first else -1 (B,), the placed node's position (B,))."""
    first = st.robot_start[r]
    bound_node = np.empty(0, dtype=np.int64)
    bound_force = np.empty(0, dtype=np.int64)
    bound_pos = np.empty(0)
    for fill in range(2):  # count, then fill
        n = 0
        for v in range(first, st.robot_start[r + 1]):
            for q_robot in range(placed.size):
                if not placed[q_robot] or q_robot == r:
                    continue
                for q in range(st.robot_start[q_robot], st.robot_start[q_robot + 1]):
                    if reach[v, q] or reach[q, v]:
                        if fill:
                            bound_node[n] = v - first
                            bound_force[n] = 1 if reach[v, q] else -1
                            bound_pos[n] = pos[q]
                        n += 1
        if not fill:
            bound_node = np.empty(n, dtype=np.int64)
            bound_force = np.empty(n, dtype=np.int64)
            bound_pos = np.empty(n)
    return bound_node, bound_force, bound_pos


@numba.njit(cache=True, nogil=True)
def _distinct_ranks(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K,) x float -> (each value's rank among the distinct values (K,) int, the
    distinct values sorted (m,)). Positions are a topological order re-ranked to
    0..V-1 plus the fractions repairs put between them, so where they span at most
    4K units they are bucketed by their integer part (few share one) in O(K + span);
    otherwise one merge sort. At 250 robots (K ~175, V 250) the buckets took ~1.8 us a
    robot, the merge sort ~3.5-7 (numba's quicksort twice that, np.unique then
    np.searchsorted three times)."""
    k = x.size
    rank = np.empty(k, dtype=np.int64)
    if k == 0:
        return rank, np.empty(0)
    low, high = np.floor(x.min()), np.floor(x.max())
    if high - low > 4 * k:
        by_value = np.argsort(x, kind="mergesort")
    else:
        start = np.zeros(int(high - low) + 2, dtype=np.int64)  # values by integer part
        for v in x:
            start[int(np.floor(v) - low) + 1] += 1
        start = np.cumsum(start)
        by_value, filled = np.empty(k, dtype=np.int64), start[:-1].copy()
        for i in range(k):
            b = int(np.floor(x[i]) - low)
            j = filled[b]  # insertion within the bucket, which is short
            while j > start[b] and x[by_value[j - 1]] > x[i]:
                by_value[j] = by_value[j - 1]
                j -= 1
            by_value[j] = i
            filled[b] += 1
    distinct = np.empty(k)
    m = 0
    for i in by_value:
        if m == 0 or x[i] != distinct[m - 1]:
            distinct[m] = x[i]
            m += 1
        rank[i] = m - 1
    return rank, distinct[:m]


@numba.njit(cache=True, nogil=True)
def _place(pos: np.ndarray, start: int, gap: np.ndarray, ranks: np.ndarray) -> None:
    """Positions of a robot's nodes (from ``start``) in their gaps among the sorted partner
    positions ``ranks`` (m,): strictly inside each gap, increasing along the path."""
    m = ranks.size
    if m == 0:
        return  # no placed partner: any increasing positions do, its own stay
    n = 0
    while n < gap.size:
        end = n
        while end + 1 < gap.size and gap[end + 1] == gap[n]:
            end += 1
        g = gap[n]
        lo = ranks[g - 1] if g > 0 else ranks[0] - 1.0
        hi = ranks[g] if g < m else ranks[m - 1] + 1.0
        for j in range(n, end + 1):
            pos[start + j] = lo + (hi - lo) * (j - n + 1) / (end - n + 2)
        n = end + 1


@numba.njit(cache=True, nogil=True)
def _pick(
    st: _Static,
    count: int,
    seed_weight: np.ndarray,  # (R,) float, the seed's odds
    blocking: np.ndarray,  # (M,) bool, conflicts whose wait binds
    blocking_weight: float,
    u: np.ndarray,  # (count,) uniform draws
) -> np.ndarray:
    """``count`` robots (fewer if the seed's component is smaller): a seed drawn by
    ``seed_weight``, then each next robot drawn by the conflicts it shares with those
    picked, one whose wait binds counting ``blocking_weight``."""
    n_robots = seed_weight.size
    picked = np.empty(count, dtype=np.int64)
    picked[0] = np.searchsorted(np.cumsum(seed_weight), u[0] * seed_weight.sum(), side="right")
    picked[0] = min(picked[0], n_robots - 1)
    score = np.zeros(n_robots)
    taken = np.zeros(n_robots, dtype=np.bool_)
    taken[picked[0]] = True
    n = 1
    while n < count:
        r = picked[n - 1]
        for j in range(st.rc_start[r], st.rc_start[r + 1]):
            score[st.rc_partner[j]] += blocking_weight if blocking[st.rc_conf[j]] else 1.0
        score[taken] = 0.0
        total = score.sum()
        if total <= 0:
            break
        nxt = np.searchsorted(np.cumsum(score), u[n] * total, side="right")
        picked[n] = min(nxt, n_robots - 1)
        taken[picked[n]] = True
        n += 1
    return picked[:n]


@dataclass(frozen=True, eq=False)
class _Incumbent:
    """A re-insertion search's current answer with its evaluation, positions and clique
    counts, found once per accepted answer (M conflicts, E events, V nodes, Q cliques,
    R robots)."""

    a_first: np.ndarray  # (M,) bool
    following: np.ndarray  # (M,) bool
    cost: float
    delay: np.ndarray  # (E+1,) least delays
    latest: np.ndarray  # (E+1,) latest delays leaving every robot's part of the objective
    slope: float  # the objective's mean rise per unit of an event's delay past its latest
    pos: np.ndarray  # (V,) float, a topological order of the node graph
    counts: np.ndarray  # (Q,) following-type conflicts per clique
    robot_delay: np.ndarray  # (R,) each robot's delay at completion
    blocking: np.ndarray  # (M,) bool, conflicts whose wait binds

    @classmethod
    def of(
        cls,
        ctx: SolveContext,
        answer: Assignments,
        evaluation: Evaluation,
        pos: np.ndarray,
        latest: np.ndarray,
        slope: np.ndarray,
        counts: np.ndarray | None = None,
    ) -> _Incumbent:
        """``answer`` with its evaluation, a topological order ``pos`` (V,) of its node
        graph (re-ranked to 0..V-1: repairs split gaps, which would shrink without end),
        its ``latest`` delays (E+1,) (:meth:`~service.core.evaluate.Evaluator.latest_delays`
        holding the events of :meth:`~service.core.evaluate.Evaluator.held_weights`) and
        its following-type ``counts`` (Q,) per clique (None: counted here)."""
        if counts is None:
            counts = ctx.cliques.following_counts(answer.following)[0]
        return cls(
            answer.a_first[0],
            answer.following[0],
            float(evaluation.costs[ctx.objective][0]),
            evaluation.event_delay[0],
            latest,
            float(slope[:-1].mean()) if slope.size > 1 else 0.0,
            np.argsort(np.argsort(pos, kind="stable")).astype(np.float64),
            counts,
            evaluation.completion[0] - ctx.problem.free_time(),
            _blocking(ctx, answer, evaluation, latest),
        )


def _blocking(
    ctx: SolveContext, answer: Assignments, evaluation: Evaluation, latest: np.ndarray
) -> np.ndarray:
    """(M,) bool: the conflicts of ``answer`` whose wait binds and, with CRITICAL_BLOCKING,
    is critical to what the cost reads (``latest`` (E+1,): its latest delays holding
    those events; :meth:`~service.core.evaluate.Evaluator.critical_waits`)."""
    binding = ctx.evaluator.binding(answer, evaluation)  # (M,)
    if not CRITICAL_BLOCKING:
        return binding
    return binding & ctx.evaluator.critical_waits(answer, evaluation, ctx.objective, latest)


def reinsert_search(
    ctx: SolveContext,
    start: Assignments,
    deadline: float,
    seed: int,
    config: ReinsertConfig | None = None,
    max_steps: int | None = None,
    cooling: tuple[float, float] | None = None,
    stop: threading.Event | None = None,
) -> ReinsertResult:
    """Re-insertion LNS from the valid ``start`` until ``deadline`` (monotonic) or
    ``max_steps`` steps (None: no cap), whichever comes first, or until no robot waits,
    or after ``config.whole_fleet_plateau`` steps without improvement that each
    re-inserted the whole fleet, or once ``stop`` is set (checked before each step).
    Returns the cheapest answer seen.

    ``cooling``: the (monotonic) span over which an annealed search cools, for the
    searches of turns restarted within it (default: from now to ``deadline``; with
    ``max_steps``, by steps). ``config`` None: ReinsertConfig's defaults, read at the
    call (so that ``bench.ab`` can vary them)."""
    config = ReinsertConfig() if config is None else config
    st = _Static.of(ctx)
    weight = ctx.evaluator.objective_weights(ctx.objective)
    held = ctx.evaluator.held_weights(ctx.objective)  # (E+1,) what holds the others
    budget = ctx.cliques.budget.astype(np.int64)
    rng = np.random.default_rng(seed)
    rank = ctx.orientation.topological_rank(start.a_first[0])
    slope = np.empty(weight.size)
    evaluation, latest = ctx.evaluator.evaluate_with_latest(start, held, slope)
    if rank is None or latest is None:
        raise ValueError("the answer to search from closes a cycle")
    current = _Incumbent.of(ctx, start, evaluation, rank, latest, slope)
    best, best_cost = start, current.cost
    n_robots, steps = ctx.problem.n_robots, 0
    count = max(config.robots, min(round(config.fleet_share * n_robots), config.max_robots))
    count, stalled = min(count, n_robots), 0
    most = max(count, min(round(config.max_share * n_robots), config.max_robots, n_robots))
    warm_from, cold_at = (time.monotonic(), deadline) if cooling is None else cooling
    heat = config.heat(n_robots)
    while time.monotonic() < deadline and (max_steps is None or steps < max_steps):
        if stop is not None and stop.is_set():
            break
        if not (current.robot_delay > TOL).any():
            break  # nobody waits (delays never fall along a path): the free cost, optimal
        plateau = config.whole_fleet_plateau
        if count == n_robots and plateau is not None and stalled >= plateau:
            break
        if count < n_robots and stalled * count >= config.stall_cover * n_robots:
            count, stalled = min(int(count * config.growth) + 1, most), 0
        picked = _pick(
            st, count, np.maximum(current.robot_delay, 0.0) + 1e-9, current.blocking,
            config.blocking_weight, rng.random(count),
        )  # fmt: skip
        cooled = (  # the share of the cooling gone: by steps where they are capped
            min((time.monotonic() - warm_from) / max(cold_at - warm_from, 1e-9), 1.0)
            if max_steps is None
            else steps / max_steps
        )
        temperature = heat * best_cost * (1.0 - cooled)
        orders = config.hot_orders if temperature > 0 else config.orders
        rounds = 0 if temperature > 0 else ROOM_ROUNDS  # see ROOM_ROUNDS
        found = _best_repair(
            st, current, picked, budget, weight, _price(config, current), rng, orders, rounds
        )
        steps += 1
        below = current.cost + _tolerated(temperature, rng)
        kept = None if found is None else _kept(ctx, current, *found, held, below)
        if kept is None or kept.cost >= best_cost:
            stalled += 1
            current = current if kept is None else kept
            continue
        best, best_cost, current, stalled = found[0], kept.cost, kept, 0
    return ReinsertResult(best, best_cost, steps)


def _price(config: ReinsertConfig, current: _Incumbent) -> float:
    """What a unit of delay past a held robot's latest costs a repair of ``current``:
    ``config.push`` times its mean slope (inf, not allowed, where push is 0; see PUSH)."""
    return config.push * current.slope if config.push > 0 else np.inf


def _tolerated(temperature: float, rng: np.random.Generator) -> float:
    """How much dearer than the current answer the next one may be: exponential with mean
    ``temperature`` (a repair of excess x is then kept with probability exp(-x / T), the
    Metropolis rule); 0 when cold."""
    return float(rng.exponential(temperature)) if temperature > 0 else 0.0


def planned_starts(
    ctx: SolveContext, orders: int, seed: int, until: float
) -> list[tuple[Assignments, float]]:
    """Up to ``orders`` prioritized plans of the whole fleet -> (answer, cost) each, the
    cheapest first (none where fixed directions left every plan tried without a passage
    for some robot). Plans are made until ``until`` (monotonic), one at least.

    A plan puts every robot back, from none placed, in one order (:func:`_plan`): the
    shortest free route first (the rule that minimises a single machine's summed
    completion), the earliest free finish first, then random orders (``seed``). A plan
    costs ~1-2 ms at 100 robots and ~8-18 ms at 250; on generated warehouses one reads
    0.44-0.80 of the best known where the cheapest blend of FCFS reads 0.23-0.43. ``auto``
    starts a search from each of the cheapest (:mod:`service.solvers.turns`: what a plan
    costs says little of where a search from it ends)."""
    p = ctx.problem
    free_end = p.free_time()  # (R,)
    free_start = np.full(p.n_robots, np.inf)  # (R,) each robot's first time point
    np.minimum.at(free_start, p.tp_robot, p.tp_time)
    rng = np.random.default_rng(seed)
    rules = [np.argsort(free_end - free_start, kind="stable"), np.argsort(free_end, kind="stable")]
    ordered = rules[:orders] + [rng.permutation(p.n_robots) for _ in range(orders - 2)]
    return _plans(ctx, ordered, until, least=1)


def cheapest_plan(
    ctx: SolveContext, orders: list[np.ndarray], until: float, least: int = 0
) -> tuple[Assignments, float] | None:
    """The cheapest prioritized plan of the whole fleet (:func:`_plan`) in the ``orders``
    (each (R,), robots in the order they are placed) tried until ``until`` (monotonic),
    ``least`` of them whatever the time -> (answer, cost), or None where none was made or
    fixed directions left each plan tried without a passage for some robot."""
    found = _plans(ctx, orders, until, least)
    return found[0] if found else None


def _plans(
    ctx: SolveContext, orders: list[np.ndarray], until: float, least: int
) -> list[tuple[Assignments, float]]:
    """The prioritized plans of the whole fleet in ``orders`` (as :func:`cheapest_plan`)
    -> (answer, cost) each, the cheapest first (equals in the order tried)."""
    if not orders or (least < 1 and time.monotonic() >= until):
        return []
    every = np.arange(ctx.problem.n_robots)
    fixed = _fixed_between(_Static.of(ctx), every, True)
    reach = _plan_reach(ctx, fixed)
    weight = ctx.evaluator.objective_weights(ctx.objective)
    found: list[tuple[Assignments, float]] = []
    for k, order in enumerate(orders):
        if k >= least and time.monotonic() >= until:
            break
        plan = _plan(ctx, order, fixed, weight, reach)
        if plan is not None:
            found.append((plan, float(ctx.evaluator.evaluate(plan).costs[ctx.objective][0])))
    return sorted(found, key=lambda made: made[1])


def _plan(
    ctx: SolveContext,
    order: np.ndarray,
    fixed: tuple[np.ndarray, np.ndarray],
    weight: np.ndarray,
    reach: np.ndarray,
) -> Assignments | None:
    """Every robot put back in ``order`` (R,), robots fixed to pass another first (the
    arcs ``fixed`` of :func:`_fixed_between` over the whole fleet) moved ahead of it
    (:func:`_fixed_first`), each on its passage past those placed before it (None: some
    robot had none, against fixed directions); ``weight`` (E+1,) as
    :meth:`~service.core.evaluate.Evaluator.objective_weights`; ``reach`` as
    :func:`_repair`."""
    p, st = ctx.problem, _Static.of(ctx)
    following = p.fixed_type == 1  # (M,) realized types stay, and take their room
    room = ctx.cliques.budget.astype(np.int64) - ctx.cliques.following_counts(following[None])[0]
    a_first = np.zeros(p.n_conflicts, dtype=bool)
    delay = np.zeros(p.events.size + 1)  # (E+1,)
    pos = np.arange(p.n_nodes, dtype=np.float64)  # (V,) increasing along every path
    cost, _ = _repair(
        _fixed_first(order.astype(np.int64), *fixed), st, delay, delay.copy(), pos, room,
        a_first, following, weight, following.copy(), np.inf, 0, False, reach, np.inf,
    )  # fmt: skip
    return Assignments.single(a_first, following) if np.isfinite(cost) else None


def _plan_reach(ctx: SolveContext, fixed: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """What a plan bounds its robots by (see :func:`_repair`): :func:`_fixed_reach` where
    the fixed directions between robots (``fixed``, as :func:`_fixed_between`) close a
    cycle and the fleet has at most REACH_MAX_NODES nodes, else (0, 0) (no bounds)."""
    p = ctx.problem
    if p.n_nodes > REACH_MAX_NODES or is_dag(p.n_robots, *fixed):
        return np.zeros((0, 0), dtype=bool)
    return _fixed_reach(p)


def _fixed_reach(p: Problem) -> np.ndarray:
    """(V, V) bool: node u must come before node v (reach[u, v]) by the fixed directions
    and the robots' paths, through any robots (the transitive closure of that order)."""
    _, first, second = p.forced_arcs
    nodes = nx.DiGraph(zip(first.tolist(), second.tolist(), strict=True))
    nodes.add_nodes_from(range(p.n_nodes))
    nodes.add_edges_from(zip(*(a.tolist() for a in path_arcs(p.node_robot)), strict=True))
    reach = np.zeros((p.n_nodes, p.n_nodes), dtype=bool)
    for v in reversed(list(nx.topological_sort(nodes))):
        for w in nodes.successors(v):
            reach[v] |= reach[w]
            reach[v, w] = True
    return reach


def _best_repair(
    st: _Static,
    current: _Incumbent,
    picked: np.ndarray,
    budget: np.ndarray,
    weight: np.ndarray,
    price: float,
    rng: np.random.Generator,
    orders: int,
    rounds: int,
) -> tuple[Assignments, np.ndarray] | None:
    """The picked robots put back in ``orders`` random orders, pushing held robots past
    their latest at ``price`` a unit: the repair whose picked robots' part of the
    objective with that price paid is least, with its node positions (V,) (None: no
    order found passages for all)."""
    shuffled = np.stack([rng.permutation(picked) for _ in range(orders)])  # (orders, k)
    cost, a_first, following, pos = _best_of_orders(
        st, shuffled, current.a_first, current.following, current.pos, current.delay,
        current.latest, budget - current.counts, weight, price, rounds, ROOM_LAST_MORE,
    )  # fmt: skip
    return (Assignments.single(a_first, following), pos) if np.isfinite(cost) else None


@numba.njit(cache=True, nogil=True)
def _best_of_orders(
    st: _Static,
    shuffled: np.ndarray,  # (n, k) int, the picked robots in n random orders
    a_first: np.ndarray,  # (M,) bool, the incumbent's
    following: np.ndarray,  # (M,) bool
    pos: np.ndarray,  # (V,) float
    delay: np.ndarray,  # (E+1,) float
    latest: np.ndarray,  # (E+1,) float
    room: np.ndarray,  # (Q,) int, each binding clique's room left by the incumbent
    weight: np.ndarray,  # (E+1,) float
    price: float,
    rounds: int,  # ROOM_ROUNDS
    last_more: bool,  # ROOM_LAST_MORE
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_repair` in each order (robots that must pass a picked one first moved ahead,
    :func:`_fixed_first`) -> the cheapest repair's picked part of the objective with the
    ``price`` of its pushes (inf: none found passages for all), directions (M,), types
    (M,) and positions (V,); one compiled call for the step's repairs (their Python
    around them took ~0.1 ms a step). An order stops once its cost reaches the cheapest
    so far (``cap`` of :func:`_repair`)."""
    picked = shuffled[0]
    freed = _freed(st, picked, a_first.size)
    freed &= st.fixed_type < 0  # a realized conflict's type stays, and its room taken
    room = room.copy()
    _give_back(st, np.flatnonzero(following & freed), room)
    base_following = following & ~freed
    tails, heads = _fixed_between(st, picked, False)
    found_cost = np.inf
    found_a_first, found_following, found_pos = a_first, following, pos
    for n in range(shuffled.shape[0]):
        order = shuffled[n]
        for _ in range(RETRIES + 1):
            order = _fixed_first(order, tails, heads)
            mine_a_first, mine_following = a_first.copy(), base_following.copy()
            mine_pos = pos.copy()
            cost, failed = _repair(
                order, st, delay.copy(), latest.copy(), mine_pos, room.copy(), mine_a_first,
                mine_following, weight, following, price, rounds, last_more,
                np.zeros((0, 0), dtype=np.bool_), found_cost,
            )  # fmt: skip
            if failed < 0:
                break
            # Again with the robot that had no passage first (see RETRIES).
            order = np.concatenate(
                (order[failed : failed + 1], order[:failed], order[failed + 1 :])
            )
        if cost < found_cost:
            found_cost = cost
            found_a_first, found_following, found_pos = mine_a_first, mine_following, mine_pos
    return found_cost, found_a_first, found_following, found_pos


@numba.njit(cache=True, nogil=True)
def _fixed_between(
    st: _Static, picked: np.ndarray, realized: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The fixed directions between two ``picked`` robots (k,), realized conflicts' too
    where ``realized``, as robot arcs (first (F,), second (F,)), one per conflict: read
    from the picked robots' slots (a pass over every conflict's direction and a set
    lookup in numpy took ~0.1 ms a step at 22,000 conflicts)."""
    is_picked = np.zeros(st.rc_start.size - 1, dtype=np.bool_)
    is_picked[picked] = True
    tails = np.empty(0, dtype=np.int64)
    heads = np.empty(0, dtype=np.int64)
    for fill in range(2):  # count, then fill
        n = 0
        for r in picked:
            for j in range(st.rc_start[r], st.rc_start[r + 1]):
                if st.rc_force[j] <= 0 or not is_picked[st.rc_partner[j]]:
                    continue  # only the side that must pass first names the arc
                if realized or st.fixed_type[st.rc_conf[j]] < 0:
                    if fill:
                        tails[n], heads[n] = r, st.rc_partner[j]
                    n += 1
        if not fill:
            tails, heads = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    return tails, heads


@numba.njit(cache=True, nogil=True)
def _fixed_first(order: np.ndarray, tails: np.ndarray, heads: np.ndarray) -> np.ndarray:
    """``order`` (k,) changed as little as it takes for a robot that must pass another
    picked robot first (arcs ``tails`` -> ``heads``) to be put back before it: a robot put
    back earlier passes with that robot absent and may take the time the other needed.
    Kahn's order, taking the earliest ready robot of ``order``; robots on a cycle of
    fixed directions (possible between robots, never between nodes) keep their places
    after the rest."""
    k = order.size
    if tails.size == 0 or k == 0:
        return order
    place = np.full(order.max() + 1, -1, dtype=np.int64)  # robot -> its index in order
    place[order] = np.arange(k)
    tail, head = place[tails], place[heads]  # (F,) by index in order
    waiting = np.zeros(k, dtype=np.int64)  # fixed arcs into each
    start = np.zeros(k + 1, dtype=np.int64)  # arcs out of index i: after[start[i]:start[i+1]]
    for a in range(tail.size):
        waiting[head[a]] += 1
        start[tail[a] + 1] += 1
    start = np.cumsum(start)
    after, filled = np.empty(tail.size, dtype=np.int64), start[:-1].copy()
    for a in range(tail.size):
        after[filled[tail[a]]] = head[a]
        filled[tail[a]] += 1
    ready = [i for i in range(k) if waiting[i] == 0]  # a heap: the earliest first
    out, taken, n = np.empty(k, dtype=np.int64), np.zeros(k, dtype=np.bool_), 0
    while len(ready) > 0:
        i = heapq.heappop(ready)
        out[n], taken[i], n = i, True, n + 1
        for j in after[start[i] : start[i + 1]]:
            waiting[j] -= 1
            if waiting[j] == 0:
                heapq.heappush(ready, j)
    for i in range(k):
        if not taken[i]:
            out[n], n = i, n + 1
    return order[out]


@numba.njit(cache=True, nogil=True)
def _freed(st: _Static, picked: np.ndarray, n_conflicts: int) -> np.ndarray:
    """(M,) bool: the conflicts of the picked robots."""
    freed = np.zeros(n_conflicts, dtype=np.bool_)
    for r in picked:
        freed[st.rc_conf[st.rc_start[r] : st.rc_start[r + 1]]] = True
    return freed


@numba.njit(cache=True, nogil=True)
def _give_back(st: _Static, conflicts: np.ndarray, room: np.ndarray) -> None:
    """``room`` (Q,) with the following-type ``conflicts`` made exclusive."""
    for c in conflicts:
        for q in st.cq_clique[st.cq_start[c] : st.cq_start[c + 1]]:
            room[q] += 1


@numba.njit(cache=True, nogil=True)
def _take_room(st: _Static, conflict: int, room: np.ndarray) -> bool:
    """Whether every binding clique of ``conflict`` has room (Q,) for one more
    following-type conflict; if so, that room is taken."""
    cliques = st.cq_clique[st.cq_start[conflict] : st.cq_start[conflict + 1]]
    for q in cliques:
        if room[q] <= 0:
            return False
    for q in cliques:
        room[q] -= 1
    return True


@numba.njit(cache=True, nogil=True)
def _take_rooms(st: _Static, conflicts: np.ndarray, room: np.ndarray) -> bool:
    """Whether room (Q,) holds every one of ``conflicts`` as following-type; if so, it is
    taken, else ``room`` is left as it was."""
    for n in range(conflicts.size):
        if not _take_room(st, conflicts[n], room):
            _give_back(st, conflicts[:n], room)
            return False
    return True


@numba.njit(cache=True, nogil=True)
def _roomier(
    st: _Static,
    pa: _Passing,
    d: np.ndarray,  # (E+1,) float
    gap: np.ndarray,  # (n_nodes,) int
    first: np.ndarray,  # (K,) bool
    chosen: np.ndarray,  # (K,) bool
    pushed: float,  # the passage found (gap, first, chosen, its delays in d) and its price
    room: np.ndarray,  # (Q,) int, its following-type conflicts' room taken
    need: np.ndarray,  # (Q,) int zeros, scratch
    rounds: int,
    more: bool,  # it may take more following-type conflicts (the last robot of an order)
) -> float:
    """The robot's passage where room was short for its following-type: as if every
    binding clique had room (following-type wherever allowed at all), then again without
    the conflicts that overfilled a clique (:func:`_drop_overfilling`), up to ``rounds``
    passages; the first that fits replaces the passage found (outputs as
    :func:`_passage_of`'s, rewritten; its room taken) where it is cheaper for the
    robot and (unless ``more``) takes no more following-type conflicts -> the price of
    the passage kept."""
    js, e0, n, own = pa.js, pa.e0, pa.ev_node.size, max(pa.own, 1e-300)
    was = (gap.copy(), first.copy(), chosen.copy(), d[e0 : e0 + n].copy())
    score = d[e0 + n - 1] + pushed / own
    _give_back(st, st.rc_conf[js[chosen]], room)
    follow = st.rc_may_follow[js].copy()
    for _ in range(rounds):
        found = _passage_of(st, pa, follow, d, gap, first, chosen)
        if found < 0 or d[e0 + n - 1] + found / own >= score - TOL:
            break  # none better (dropping more only makes it dearer)
        if (more or chosen.sum() <= was[2].sum()) and _take_rooms(st, st.rc_conf[js[chosen]], room):
            return found
        if not _drop_overfilling(st, js, chosen, follow, room, need):
            break
    gap[:], first[:], chosen[:], d[e0 : e0 + n] = was
    _take_rooms(st, st.rc_conf[js[chosen]], room)  # it fitted before
    return pushed


@numba.njit(cache=True, nogil=True)
def _drop_overfilling(
    st: _Static,
    js: np.ndarray,  # (K,) the robot's slots
    chosen: np.ndarray,  # (K,) bool, following-type in the passage found
    follow: np.ndarray,  # (K,) bool, following-type allowed; the dropped ones set False
    room: np.ndarray,  # (Q,) int
    need: np.ndarray,  # (Q,) int, zeros (scratch, left zeros)
) -> bool:
    """Following-type no longer allowed on chosen conflicts that overfill a binding
    clique's ``room``, taken from the end of the robot's path (its later waits delay fewer
    of its events) until none overfills -> whether any was dropped."""
    idx = np.flatnonzero(chosen)
    for i in idx:
        c = st.rc_conf[js[i]]
        need[st.cq_clique[st.cq_start[c] : st.cq_start[c + 1]]] += 1
    dropped = False
    for i in idx[np.argsort(st.own_target[js[idx]])[::-1]]:
        c = st.rc_conf[js[i]]
        cliques = st.cq_clique[st.cq_start[c] : st.cq_start[c + 1]]
        if (need[cliques] > room[cliques]).any():
            follow[i], dropped = False, True
            need[cliques] -= 1
    for i in idx:
        c = st.rc_conf[js[i]]
        need[st.cq_clique[st.cq_start[c] : st.cq_start[c + 1]]] = 0
    return dropped


@numba.njit(cache=True, nogil=True)
def _ordered(st: _Static, a_first: np.ndarray, pos: np.ndarray) -> bool:
    """Whether node positions ``pos`` (V,) are a topological order of the node graph of
    directions ``a_first`` (M,) bool: increasing along every path and from the node
    passing first to the other at every conflict (a loop: 0.25 ms in numpy at 250
    robots, re-insertion's guard on every answer it keeps)."""
    for r in range(st.robot_start.size - 1):
        for v in range(st.robot_start[r], st.robot_start[r + 1] - 1):
            if pos[v + 1] <= pos[v]:
                return False
    for c in range(a_first.size):
        first, second = (0, 1) if a_first[c] else (1, 0)
        if pos[st.conf_nodes[c, first]] >= pos[st.conf_nodes[c, second]]:
            return False
    return True


def _kept(
    ctx: SolveContext,
    current: _Incumbent,
    found: Assignments,
    pos: np.ndarray,
    held: np.ndarray,
    below: float,
) -> _Incumbent | None:
    """``found`` (node positions ``pos`` (V,)) as the new incumbent, its latest delays
    holding the ``held`` (E+1,) events (which also weigh its slopes;
    :meth:`~service.core.evaluate.Evaluator.held_weights`), if
    the evaluator finds it cheaper than ``below``;
    None otherwise, and (a guard: repairs exclude both by construction) if ``pos`` is
    not a topological order of its node graph or a density clique holds more
    following-type conflicts than its budget."""
    slope = np.empty(held.size)
    evaluation, latest = ctx.evaluator.evaluate_with_latest(
        found, held, slope, below=(ctx.objective, below)
    )  # no latest (None) where not cheaper than below
    if latest is None or not float(evaluation.costs[ctx.objective][0]) < below:
        return None
    if not _ordered(_Static.of(ctx), found.a_first[0], pos):
        return None
    counts = ctx.orientation.recount(current.counts, current.following, found.following[0])
    if (counts > ctx.cliques.budget).any():
        return None
    return _Incumbent.of(ctx, found, evaluation, pos, latest, slope, counts)


@register("reinsert")
def reinsert(ctx: SolveContext) -> SolverOutput:
    """Re-insertion search from the instant answer (FCFS or its cheapest blend) within the
    time limit; for the objectives it does not search, that answer."""
    deadline = time.monotonic() + ctx.time_limit_s
    start = plain_start(ctx)
    if ctx.objective not in REINSERT_OBJECTIVES:
        return SolverOutput(start, detail=f"no re-insertion for {ctx.objective}")
    found = reinsert_search(ctx, start, deadline, ctx.seed, SOLVER_CONFIG)
    return SolverOutput(found.best, detail=f"{found.steps} re-insertion steps")
