"""``auto``: an anytime portfolio that uses the request's whole budget and proves what it can.

It returns when optimality is proven or when the budget is spent, whichever
comes first, improving in stages:

1. **instant**: the cheapest of FCFS, its blends toward robot priorities (each with
   FCFS's types or the types its directions gain most from) and the previous answer of
   a re-schedule (:func:`~service.solvers.tabu.plain_start`;
   valid by construction, milliseconds), unless plans replace it (below);
2. **first stage** (problems above ``exact_max_conflicts``): the policy's large
   solver (default ``priority_tabu``: robot-priority search from that start until it
   stalls, then tabu search; measured better than tabu search alone, which was
   measured better than the GNN-VAE refined by tabu search, ``gnn_vae_refined``), or
   tabu search from the previous answer in a re-schedule, with FIRST_STAGE_SHARE of
   the budget; for max_completion and sync_completion, where time allows, its answer's
   directions then get types by descent (DESCENT_OBJECTIVES). From
   ``lns_min_conflicts`` conflicts (avg_completion, avg_delay) instead the cheapest of
   PLANNED_ORDERS prioritized plans of the whole fleet (milliseconds),
   the instant answer only where no plan is found, then re-insertion search
   (:mod:`service.solvers.reinsert`: neighbourhoods repaired by prioritized planning,
   ~1-4 ms a step) in turns (:mod:`service.solvers.turns`), with
   REINSERT_SHARE of the time left, or to the deadline where no later stage runs. Below
   ``lns_min_conflicts`` too, from MID_TURNS_MIN_CONFLICTS: the plans and the turns, with
   MID_TURNS_SHARE;
3. **large-neighbourhood search** (above ``exact_max_conflicts`` up to
   ``exact_stage_max_conflicts``, for the objectives that are sums): CP-SAT re-plans
   a few robots at a time from the best answer so far (:mod:`service.solvers.lns`).
   From ``lns_min_conflicts`` conflicts until the deadline, instead of the next
   stage: on whole models of this size one CP-SAT worker barely moves from its
   hint; there only where MID_LNS_LEAST_S are left (with less, the turns take the
   time; for avg_completion never since session 58), posed for avg_completion
   whatever the objective (LAST_LNS_POSED); never
   above ``exact_stage_max_conflicts``, where the turns take the budget (measured:
   see ``_staged``). Below
   ``lns_min_conflicts``, posed for the request's objective, until it converges (a
   plateau at its largest neighbourhood), proves optimality (a step that freed every
   robot of a fleet of at most ``lns.MAX_ROBOTS``, proven by CP-SAT) or MID_LNS_SHARE
   of the time left has passed (where the MILP backend follows, on larger fleets also
   once it stalls: MILP_LNS_PATIENCE_S), then
4. **exact**: CP-SAT hinted with the best answer so far, for the rest of the
   budget; it proves optimality where it can (``solver.optimal`` is true only
   then) and never returns worse than its hint (the cheaper is kept, by the one
   evaluator). It is skipped when what is left is less than EXACT_TIME_PER_BUILD
   times its model-building estimate (``exact.build_seconds``), and above
   ``exact_stage_max_conflicts`` (where it was measured to improve nothing within
   seconds); the first stage then gets the whole budget (unless LNS follows it),
   and tabu search polishes its answer with what it leaves, restarted from the best
   with the next seed whenever it stops on its own, so that an unproven answer comes
   at the deadline, not before.

Beside the stages 3 and 4 (and the MILP backend's), which run ``workers`` threads,
re-insertion turns search from the same answer on the cores the solve may take that
they leave idle (a lone request of the service's one worker: the second of two cores),
until those stages end (on fleets where LNS may prove, from stage 4 on); their answer is
kept where cheaper (BESIDE).

Small problems go straight to the exact stage (CP-SAT proves them in milliseconds).
Robots that share no conflict, directly or through others, form independent
components (:mod:`service.core.decompose`); for the objectives that decompose,
each is solved on its own, smallest first, with the time left shared by
conflict count (small components usually finish early and leave their time to
the large ones); the answer is optimal when every component's is.
sync_completion is solved whole.

Trade-off of the budget (the default is ``SCHEDULER_DEFAULT_TIME_LIMIT_S``):
latency is the budget unless optimality is proven sooner; quality grows with
it (docs/benchmarks.md, "Anytime auto").
"""

from __future__ import annotations

import copy
import math
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import replace
from functools import partial
from typing import NamedTuple

import numpy as np

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.decompose import DECOMPOSABLE, Part, join, parts
from service.core.problem import Problem
from service.core.retype import descend_types
from service.core.schemas import Objective
from service.core.threads import cores_per_solve
from service.solvers.exact import build_seconds, improve, milp_staged
from service.solvers.lns import LNS_OBJECTIVES, lns_search
from service.solvers.lns import MAX_ROBOTS as LNS_MAX_ROBOTS
from service.solvers.registry import SolveContext, SolverOutput, get_solver, register
from service.solvers.reinsert import REINSERT_OBJECTIVES, planned_starts
from service.solvers.tabu import plain_start, tabu_search
from service.solvers.turns import TurnsResult, take_turns

__all__ = ["FIRST_STAGE_SHARE", "auto"]

# Share of the budget the first stage (priority and tabu search, or tabu from the previous
# answer) gets before CP-SAT takes the rest.
FIRST_STAGE_SHARE = 0.3
# Least time left worth another tabu search when polishing (one iteration of a
# 22,000-conflict problem takes ~10 ms).
MIN_POLISH_S = 0.02
# CP-SAT's stage runs only when its time is at least this many times its model-building
# estimate (``exact.build_seconds``; it was 2). Measured (docs/benchmarks.md, "Anytime
# auto", session 12) on six warehouses of 100 robots (2,000-3,900 conflicts, building
# ~0.25-0.5 s): CP-SAT never improved the first stage's answer at 1 s, where it ran
# with 2-3x, and the first stage given that time reached 0.97 instead of 0.92 on the
# two-lane ones; with 3 s and more it found the best answers, and still runs there.
EXACT_TIME_PER_BUILD = 4
# What LNS's sub-problems minimise where LNS is the last stage (from ``lns_min_conflicts``
# conflicts up to the cap), for either objective (the lns module's ``posed_for``;
# below, where CP-SAT follows, the request's objective, so that LNS may prove optimality):
# the picked robots' completions, every held robot held by its completion
# alone; an answer is still kept only where the one evaluator finds it cheaper in the
# request's objective. Posed for avg_delay, every event of a held robot stayed held and
# LNS did not pay there (above); ``auto`` posed for avg_completion costs no more in
# avg_delay than posed for it (session 51, six 100-250-robot warehouses, two seeds, 1 s
# and 5 s: within the run-to-run spread either way). Measured (session 51, ``python -m
# bench.ab --objective avg_delay``; wh_two_way, wh_two_lane, wh_one_way, wh_mixed of 250
# robots, two worlds, two seeds, 5 s): the turns to the deadline (as shipped) against
# them then LNS posed for avg_completion under avg_completion's rule 0.9378 / 0.9601 (5
# cheaper, 11 dearer of 16); under that rule, posed for avg_delay against for
# avg_completion (other worlds, ``--seed 500000``) 0.9565 / 0.9792 (4 / 12). At 10 s (where
# the old rule ran LNS posed for avg_delay too; the 250-robot kinds above, one seed) posed
# for avg_delay / for avg_completion 0.9596 / 0.9756 (2 / 6). At 100 robots from session 52
# too: see MID_LNS_LEAST_S.
LAST_LNS_POSED: Objective = "avg_completion"
# LNS's sub-problems keep the held robots in the incumbent's topological order (up to
# ``exact_stage_max_conflicts`` conflicts, where LNS runs; its neighbourhoods start at
# ``lns.LNS_ROBOTS``):
# each held node at a constant position, instead of a position variable for each held
# node a freed conflict touches and the links the held graph makes between them
# (``lns._Neighbourhood._order``). A restriction where the held graph leaves two of those
# nodes unordered, but a smaller model. Measured (session 39; 40 neighbourhoods of 4 robots
# on a two-way warehouse of 250 robots: build 30 -> 22 ms, CP-SAT 49 -> 28 ms, the same
# optimum in 36, worse in 3, better in 1; ``auto`` at 5 s, two seeds, two worlds per kind,
# docs/benchmarks.md "Fewer rows per LNS step"): 100-robot warehouses (2,000-3,900
# conflicts, 8 robots a step) 0.9700 -> 0.9823, better or even in 8 of 8 runs; 250-robot
# ones (11,000-23,000 conflicts, 4 robots; LNS ran there until session 58) 0.9553 -> 0.9464
# (two-lane and wh_mixed worse).
LNS_HELD_IN_ORDER = True
# Share of the time after the first stage that LNS may take, below lns_min_conflicts,
# before the CP-SAT stage (which proves optimality where it can): LNS stops sooner when
# it converges (a plateau at its largest neighbourhood). Measured (session 19, 25
# problems of 83-540 conflicts: conformance wh_50 and geo_dense_25, generated 25-robot
# warehouses and floors, 50-robot sparse floors): at 1 s the optimum on 12 of the 14
# conformance problems against 7 (mean cost ratio 0.9987 against 0.9937), fewer proven
# (5 against 10 of 25); at 5 s as many proven as before (20 of 25), the generated ones
# better on 2 (by 5 %), worse on 2 (by 0.5 %). avg_delay (23 problems: the conformance
# sets' problems and generated 25-robot warehouses, against the better of the two):
# 0.9597 -> 0.9984 at 1 s (proven 4 -> 3), 0.9669 -> 0.9975 at 5 s (proven 7 -> 5).
# Session 40 (0.5 -> 0.8; ``auto`` through the dispatcher, generated wh_two_way and
# wh_two_lane of 25 robots, floor_dense 25 and floor_sparse 50 (128-540 conflicts), three
# worlds each, two seeds, against the best known; at 1 s the two interleaved run by run):
# avg_completion 1 s 0.9825 -> 0.9855 (8 of 22 runs better, 2 worse), 5 s 0.9957 -> 0.9960,
# proven 8 / 14 of 22 either way; avg_delay 1 s 0.9751 -> 0.9886 (9 better, none worse), 5 s
# 0.9895 -> 0.9862 (one run of 22 dearer, the rest equal: LNS converges first at 5 s);
# conformance sets at 1 s 0.9999 -> 1.0000, geo_dense_25 proven at 1 s 30 % -> 55 %, at
# 5 s 26 of the 28 MILP-proven runs proven as before. At 1 s the CP-SAT stage, with half
# of what priority search left, rarely improved LNS's answer. 0.95 read as 0.8.
MID_LNS_SHARE = 0.8
# Where the CP-SAT stage hands most of its time to the MILP backend (``exact.milp_staged``)
# and the fleet has more robots than LNS frees at most (``lns.MAX_ROBOTS``: no step is a
# whole-problem solve, which may prove or find a far cheaper answer late), LNS before it
# also ends once it has gone as long without improving as it took to its last improvement,
# and this many seconds at least (``lns_search``'s ``patience_s``): there the MILP proves,
# from scratch, and needs the time. On wh_100/1 and /2 posed for avg_delay LNS reached its
# final answer within a tenth of its 3.6-4 s (the MILP, bounded, then needs 3.1-3.5 s of the
# largest component's ~4.7). Measured (session 53, ``python -m bench.ab --objective
# avg_delay``, 5 s, two seeds; A as before, B this and the MILP bounded by the incumbent):
# the sets wh_25, wh_50, wh_100, geo_dense_25 and wh_two_way, wh_two_lane, floor_dense 25
# (two worlds, ``--seed 3000``) proven 53 -> 56 of 62 (wh_100 2 -> 6; geo_dense_25/7 lost in
# one run, which A proved at 4.79 s), costs equal; wh_two_way, wh_two_lane, floor_dense,
# wh_one_way, wh_mixed 25 (three worlds, ``--seed 4000``) 0.9911 / 0.9926 (B cheaper in 1 of
# 30, dearer in none), proven 15 / 15; 1 s as before. Tried first: LNS's share before the
# stage 0.2 (for 0.8): the sets proven 53 -> 55 and 53 -> 57, but dearer in 5 of 30 runs on
# those 25-robot worlds (a proof lost) and at 1 s proven 29 -> 21 of 62; patient at every
# fleet size: dearer in 3 of 30 there, and on wh_two_lane/25/3000 5.46 against 5.04 (LNS's
# late whole-fleet steps found the cheaper answer).
MILP_LNS_PATIENCE_S = 0.5
# From ``lns_min_conflicts`` conflicts, re-insertion search (:mod:`service.solvers.reinsert`)
# follows the first stage: with REINSERT_SHARE of the time left when LNS follows it, else
# to the deadline (above ``exact_stage_max_conflicts`` where LNS does not pay, instead of
# tabu polishing). Measured (session 25, ad hoc: priority_tabu, re-insertion, CP-SAT LNS
# called in turn, cost ratio against the 30-s references, three worlds each, one seed):
# 100-robot warehouses at 1 s, 30 % priority then LNS 0.769 (two-lane) / 0.726 (two-way),
# with 30 % of the budget re-inserting before LNS 0.826-0.859 / 0.740-0.764, at 5 s even
# (0.935 -> 0.929 / 0.869 -> 0.882); 250-robot two-lane at 1 s priority alone 0.552,
# then re-insertion 0.673, at 5 s priority then LNS 0.658, priority then re-insertion
# 0.780, then 30 % re-insertion and LNS 0.825; two-way 250 even (1 s 0.671 -> 0.676, 5 s
# 0.788 -> 0.793). Through the dispatcher with the first stage at REINSERT_FIRST_SHARE,
# 0.3 / 0.43 / 0.6 of the time left: 1 s 0.7262 / 0.7310 / 0.7307, 5 s 0.8625 / 0.8674 /
# 0.8697 (flat). avg_delay (the same 12 warehouses, one seed, paired costs without / with
# re-insertion): 1.21x at 1 s, 1.15x at 5 s (better on 8 of 12 at each, two-lane 1.1-1.4x,
# two-way 250 0.97x at 1 s). From session 26 to 50 the stage was re-insertion and priority
# search in turns (:mod:`service.solvers.turns`; through the dispatcher, 100-robot
# warehouses, two seeds, 1 s / 5 s: two-way 0.766 -> 0.832 / 0.874 -> 0.908, two-lane
# 0.850 -> 0.866 / 0.935 -> 0.921), the share left as it was; since session 51 re-insertion
# alone in turns (see the turns module).
REINSERT_SHARE = 0.43
# From ``lns_min_conflicts`` up to ``exact_stage_max_conflicts`` conflicts, LNS follows the
# re-insertion turns only where the time left before the plans is at least this many
# seconds; with less the turns run to the deadline. Measured (session 41, ``python -m
# bench.ab``: ``auto`` through the dispatcher, the two variants interleaved run by run,
# three worlds a kind, two seeds, mean cost ratio against the r5 references; turns to the
# deadline / LNS after REINSERT_SHARE): wh_two_way and wh_two_lane of 100 robots
# (2,000-3,900 conflicts) 1 s 0.9282 / 0.9154 (REINSERT_SHARE 1.0 against 0.7; 0.7 against
# 0.43 0.9251 / 0.8959), 2 s 0.9442 / 0.9352 (5 better, 7 worse), 3 s 0.9399 / 0.9516
# (two-way worse in 6 of 6, two-lane better in 5 of 6), 5 s 0.9545 / 0.9736 (two-way worse
# in 6 of 6); kinds not tuned on (wh_one_way, wh_mixed, wh_parked of 100) at 1 s 0.9776 /
# 0.9617 (11 better, 7 worse); avg_delay at 1 s 0.9499 / 0.8494 (11 / 1), at 5 s 0.9716 /
# 0.9494 (two-lane 0.999 / 0.919, two-way 0.944 / 0.980). LNS pays on the two-way
# warehouses from ~3 s; from 2 s it keeps them. For avg_delay it pays at no budget
# measured (session 42, the same way): 3 s 0.9619 / 0.9330 (8 cheaper, 4 dearer of 12;
# both kinds better), 10 s 0.9894 / 0.9849 (3 / 3; two-way 0.981 / 0.991, two-lane 0.998 /
# 0.979), at 5 s on wh_one_way, wh_mixed and wh_parked of 100 0.9618 / 0.9456 (7 / 5):
# the turns take its budgets whole. (At 5 s for avg_completion, LNS stays: 0.9530 / 0.9819
# on the two-way and two-lane ones, 2 / 10; 0.9548 / 0.9863 on those three kinds.) Again
# in session 50, with both searches' held robots held by their completions
# (``Evaluator.held_weights``), avg_delay at 5 s on wh_two_way, wh_two_lane, wh_one_way and
# wh_mixed of 100 (two worlds, two seeds): 0.9731 / 0.9627 (10 / 6): still none. Posed for
# avg_completion (LAST_LNS_POSED; session 51 above the cap), LNS pays for avg_delay too
# from 5 s (session 52, ``python -m bench.ab --objective avg_delay``, the turns to the
# deadline against LNS posed for avg_completion after them; wh_two_way, wh_two_lane,
# wh_one_way, wh_mixed, wh_parked of 100, 5 s): four worlds a kind, two seeds (``--seed
# 700000``) 0.9453 / 0.9681 (13 cheaper, 27 dearer of 40; two-way 7 / 1, one-way and
# parked 0 / 8); three worlds, two seeds (``--seed 800000``) 0.9393 / 0.9742 (6 / 24; two-way
# 1 / 5); the bench's two-way and two-lane worlds (three, two seeds) even, 0.9317 / 0.9313
# (5 / 7); 10 s, wh_two_way, wh_two_lane, wh_one_way, wh_parked, two worlds, one seed
# (``--seed 900000``) 0.9664 / 0.9850 (2 / 6). At 3 s it read worse (session 51: 0.9493 /
# 0.9428, 11 / 5), so from 4 s left. For avg_completion 2 s until session 58; since then
# (session 57's derivation, session 58's larger re-insertion neighbourhoods:
# ``reinsert.FLEET_SHARE``) the turns to the deadline are better at 5 and 10 s (session 58,
# ``python -m bench.ab``, the 2-s rule against none, wh_two_way, wh_two_lane, floor_dense,
# wh_mixed of 100 robots, cost ratio with / without, runs cheaper / dearer without): 5 s,
# the bench's worlds, one seed, 0.9871 / 0.9924 (5 / 3); other worlds (``--seed 600000``,
# two seeds) 0.9746 / 0.9873 (9 / 7); the sets wh_50, wh_100, geo_dense_25 and the bench's
# two-way and two-lane worlds 0.9952 / 0.9970 (3 / 4; proven 11 / 12); 10 s (``--seed
# 600000``, one seed) 0.9875 / 0.9982 (6 / 2). By kind: two-way warehouses gain (7 / 2 at
# 5 s), two-lane ones lose (2 / 7): LNS still pays there, unmeasured by which rule. The
# avg_delay rule was not measured again.
# Seconds left at least, by objective (inf: never).
MID_LNS_LEAST_S = {"avg_completion": math.inf, "avg_delay": 4.0}
# From MID_TURNS_MIN_CONFLICTS (and above ``exact_max_conflicts``) to below ``lns_min_conflicts``
# (avg_completion, avg_delay; not a re-schedule), the first stage is the plans then the
# re-insertion turns for MID_TURNS_SHARE of the time left, in place of the policy's large solver
# (priority_tabu); LNS and the CP-SAT stage follow as after it. Where LNS converges on a local
# optimum (a plateau at the whole fleet unproven) the CP-SAT stage of one worker rarely leaves it:
# wh_two_way/25/60 read 0.954 at 5 s, LNS done at 0.9 s. Measured (session 42, ``python -m
# bench.ab``, interleaved, 1 s, turns first / not; every problem of 60-700 conflicts turned
# first): generated wh_two_way 25 (210-252 conflicts), wh_two_lane 25 (128-138), floor_dense 25
# (146-172), floor_sparse 50 (515-540), three worlds each, and the conformance sets wh_25, wh_50,
# wh_100, geo_dense_25 (four seeds): avg_completion two-way 0.9852 / 0.9680 (8 cheaper, 2 dearer
# of 12), sparse floors 0.9775 / 0.9754 (7 / 1), two-lane 1.0000 / 0.9991, dense floors 1.0000 /
# 0.9996, the sets 0.9999 - 1.0000 either way (62 / 63 of 144 runs proven); avg_delay (two seeds)
# two-way 0.966 / 0.896, sparse floors 0.984 / 0.967, but two-lane 0.984 / 0.999 (0 / 2) and dense
# floors 0.989 / 1.000 (0 / 2): below 200 conflicts the plain order keeps them. Measured with
# MID_TURNS_SHARE 0.3 in session 41: fewer proofs at 5 s; so short budgets only (until session 55)
# for avg_completion. avg_delay at every budget since re-insertion holds its robots by their
# completions (``Evaluator.held_weights``): measured (session 50, ``python -m bench.ab --objective
# avg_delay``, 5 s, 2.0 against every budget; wh_two_way 25, floor_sparse 50, wh_two_way 50,
# wh_one_way 50, three worlds, and the sets wh_100, geo_dense_25, one seed) 0.9903 / 0.9998 (2
# cheaper, 7 dearer of 24; proven 12 / 12), on other worlds (`--seed 500000`, those kinds,
# wh_two_lane 25, wh_mixed 50, floor_dense 25, two worlds, two seeds) 0.9722 / 0.9863 (5 / 12;
# proven 8 / 8); avg_completion the same way 0.9973 / 0.9972 (3 / 4; proven 14 / 14).
# avg_completion too at every budget since session 55 (the scenario generator's floors of 50
# robots derivable: at 5 s they read no better than at 1 s), measured (``python -m bench.ab``, 5
# s, below 2 s against every budget): floor kinds dense, sparse, passages and mixed of 50 robots,
# wh_two_way 50, wh_one_way 50 (``--seed 500000``, two worlds, two seeds) 0.9875 / 0.9960 (4
# cheaper, 14 dearer of 24; one-way 0.971 -> 0.993, mixed floors 0.986 -> 1.000); floor_dense,
# floor_sparse, wh_two_way, wh_two_lane 50 and the sets wh_50, geo_dense_25 (two seeds) 0.9970 /
# 0.9981 (4 / 7; two-lane 1.000 -> 0.998), proven 28 / 28 either way.
MID_TURNS_SHARE = 0.1
MID_TURNS_MIN_CONFLICTS = 200
# From ``lns_min_conflicts`` conflicts the first stage is the cheapest of PLANNED_ORDERS
# prioritized plans of the whole fleet (:func:`~service.solvers.reinsert.planned_starts`,
# ~1-2 ms a plan at 100 robots, 8-18 ms at 250), not priority search from the blend with
# 15 % of the budget (session 25's REINSERT_FIRST_SHARE, measured then against 5 % and
# 30 %). Measured (session 26, through the dispatcher, the 12 generated warehouses of 100
# and 250 robots, two seeds, two runs side by side, mean cost ratio at 1 s / 5 s): the
# old first stage 0.7673 / 0.8982, 4 plans 0.8073 / 0.9327 (every family better or even),
# 8 plans 0.8098 / 0.9284, 16 plans 0.8024 / 0.9170. The instant answer is sought only
# where no plan is found (fixed directions against every order tried): on 34 generated
# warehouses of 40-160 robots and 700-10,000 conflicts (both objectives; session 28) the
# cheapest plan cost 0.27-0.77 of it, and it costs ~25-55 ms from 5,000 conflicts. Since
# session 67 the other plans start re-insertion lineages of their own (as many as the turns
# run: see :mod:`service.solvers.turns`).
PLANNED_ORDERS = 4
PLANNED_SHARE = 0.1  # of the budget, after which no further plan starts (one at least)
# For these objectives (above ``exact_max_conflicts``) the first stage takes
# FIRST_STAGE_SHARE of the time, and its answer's directions then get the types a descent
# from all-exclusive reaches (``retype.descend_types``, until it converges or the
# deadline), kept where cheaper, before the CP-SAT stage or the polish: priority search's
# types (the decoder's, refitted by spared wait) and tabu's single flips leave them far
# from the best for their directions (``auto`` at 1 s on 100-robot warehouses, its
# directions descended: 1.1-1.47x cheaper). Measured (session 45, ``python -m bench.ab``,
# generated warehouses of 25-250 robots and floors of 25-50, two worlds a kind, two seeds,
# against the best run; docs/benchmarks.md): max_completion 1 s 0.9373 -> 0.9759, 5 s
# 0.9447 -> 0.9819; sync_completion 1 s 0.9469 -> 0.9686, 5 s 0.9214 -> 0.9726 (100-robot
# warehouses 0.87-0.91 -> 0.96-0.98). The sums keep their stages (re-insertion and CP-SAT
# LNS set types with the directions).
DESCENT_OBJECTIVES = ("max_completion", "sync_completion")
# ... where the time left after the first stage is at least this many seconds per conflict
# (else the first stage keeps the whole time, as before): the descents above took
# 3.7e-5-3.1e-4 s per conflict, 1.2e-4 at 250 robots (~2.7 s for 21,500 conflicts). Without
# the rule, at 1 s on the 250-robot warehouses (cut at the deadline, the first stage with
# 30 % of the time) max_completion read 0.8778 against 0.9713.
DESCENT_S_PER_CONFLICT = 1.25e-4
# Whether re-insertion turns run beside the exact stages (CP-SAT LNS, CP-SAT, the MILP) on
# the cores the solve may take that those leave idle (they run ``ctx.workers`` threads: a
# lone request of the service's one worker left one of two cores idle), from the answer
# those start from, until they end; the cheaper answer is kept (avg_completion,
# avg_delay, above ``exact_max_conflicts``). On wh_two_way/25/60 at 1 s (six seeds) the
# turns had 0.1 s (MID_TURNS_SHARE), LNS and CP-SAT then found nothing in 0.8 s, and the
# answers read 28.01-29.70; with the turns beside, 28.01 (the best known) in all six.
# Measured (session 68, ``python -m bench.ab --a service.solvers.portfolio.BESIDE=False``;
# wh_two_way 25, floor_dense, floor_sparse, wh_two_way, wh_two_lane of 50 robots and the
# sets wh_50, wh_100, geo_dense_25; cost ratio without / with, B's gain with its 95 %
# interval, runs cheaper / dearer with, proven without / with): 1 s (six worlds a kind,
# two seeds) 0.9955 / 0.9974, +0.0019 (+0.0001, +0.0039), 18 / 10, proven 18 / 17 (one
# geo_dense_25 proof LNS made at 0.78 s without was not made in time); wh_two_way 25
# 0.9928 / 0.9988, floor_dense 50 0.9937 / 0.9969; 5 s (four worlds) even, 0.9983 /
# 0.9985, +0.0002 (-0.0005, +0.0009), 6 / 3, proven 33 / 33. On other worlds (``--seed
# 600000``: wh_two_way 25, wh_one_way, wh_mixed, floor_passages, floor_mixed, floor_dense
# 50) at 1 s 0.9918 / 0.9933 (+0.0015, interval -0.0030 to +0.0062), but wh_two_way 25
# 0.9960 / 0.9852, proven 7 / 5: beside LNS, the turns' steps (short at 25 robots, much of
# them Python) took the interpreter from LNS's model building, and LNS's whole-fleet step,
# which proves, came later or not at all. So where LNS may prove (fleets of up to
# ``lns.MAX_ROBOTS``) the turns start with the CP-SAT stage, from LNS's answer; on larger
# fleets with LNS (started with the CP-SAT stage everywhere instead, those worlds read
# floor_passages 50 0.9970 -> 0.9824, floor_mixed 50 0.9963 -> 0.9902). With that rule,
# against none, 1 s: those worlds 0.9901 / 0.9930, +0.0028 (-0.0013, +0.0090), 14 / 20 (the
# floor_dense 50 worlds, above lns_min_conflicts, run no exact stage: their 4 / 1 is
# noise), proven 5 / 5; the first worlds and sets 0.9955 / 0.9965, +0.0010 (-0.0003,
# +0.0024), 19 / 13, proven 16 / 16.
BESIDE = True
# The turns beside search with the request's seed plus this (not the turns' own seeds).
BESIDE_SEED = 7_000_003


@register("auto")
def auto(ctx: SolveContext) -> SolverOutput:
    """The best answer the staged portfolio reaches by the deadline (see the module)."""
    deadline = time.monotonic() + ctx.time_limit_s
    pieces = parts(ctx.problem) if ctx.objective in DECOMPOSABLE else []
    if len(pieces) <= 1:
        return _staged(ctx, deadline)
    pieces.sort(key=lambda part: part.problem.n_conflicts)
    label = np.empty(ctx.problem.n_conflicts, dtype=np.int64)  # (M,) each conflict's part
    for k, part in enumerate(pieces):
        label[part.conflicts] = k
    cliques = ctx.cliques.split(label, len(pieces))
    outputs: list[tuple[Part, SolverOutput]] = []
    left_conflicts = sum(part.problem.n_conflicts for part in pieces)
    for part, part_cliques in zip(pieces, cliques, strict=True):
        share = (deadline - time.monotonic()) * part.problem.n_conflicts / left_conflicts
        left_conflicts -= part.problem.n_conflicts
        sub = _part_context(ctx, part, max(share, 0.0), part_cliques)
        outputs.append((part, _staged(sub, time.monotonic() + sub.time_limit_s)))
    optimal = all(out.optimal for _, out in outputs)
    proven = sum(out.optimal for _, out in outputs)
    return SolverOutput(
        join(ctx.problem, [(part, out.assignment) for part, out in outputs]),
        optimal=optimal,
        detail=f"{len(pieces)} independent components, {proven} proven optimal",
    )


def _part_context(
    ctx: SolveContext, part: Part, time_limit_s: float, cliques: Cliques
) -> SolveContext:
    """A context for one component, with the warm start cut to its conflicts and its
    ``cliques`` (split from the whole problem's, not found again)."""
    warm = ctx.warm
    if warm is not None:
        warm = Assignments(warm.a_first[:, part.conflicts], warm.following[:, part.conflicts])
    sub = replace(ctx, problem=part.problem, time_limit_s=time_limit_s, warm=warm, on_solution=None)
    sub.__dict__["cliques"] = cliques  # the cached property, already known
    return sub


def _staged(ctx: SolveContext, deadline: float) -> SolverOutput:
    """Instant answer, first stage, then hinted CP-SAT, within ``deadline`` (monotonic)."""
    problem = ctx.problem
    if problem.n_conflicts == 0:
        return SolverOutput(plain_start(ctx), optimal=True, detail="no conflict")
    too_large = problem.n_conflicts > ctx.exact_stage_max_conflicts  # for CP-SAT to help
    # No LNS above the cap: the turns take the budget. From session 24 to 57 LNS followed
    # them there where 0.015 s per conflict a robot has and 3 s at least were left
    # (docs/benchmarks.md, sessions 24-28, 50-51). Since session 57's derivation and
    # session 58's larger re-insertion neighbourhoods (``reinsert.FLEET_SHARE``) the turns
    # alone are better at every budget measured (session 58, ``python -m bench.ab``, the
    # rule against none; wh_two_way, wh_two_lane, wh_mixed, wh_one_way of 250 robots, two
    # worlds a kind, one seed, cost ratio with / without, runs cheaper / dearer without):
    # 5 s 0.9637 / 0.9995 (7 / 1), other worlds (``--seed 600000``) 0.9673 / 0.9986 (6 / 2),
    # avg_delay 0.9720 / 0.9875 (7 / 1); 10 s 0.9808 / 0.9995 (7 / 1); 30 s (one world a
    # kind) 0.9837 / 1.0000 (4 / 0).
    uses_lns = (
        ctx.objective in LNS_OBJECTIVES
        and ctx.exact_max_conflicts < problem.n_conflicts
        and not too_large
        and (  # from lns_min_conflicts to the cap, with MID_LNS_LEAST_S left at least
            problem.n_conflicts < ctx.lns_min_conflicts
            or deadline - time.monotonic() >= MID_LNS_LEAST_S[ctx.objective]
        )
    )
    lns_only = uses_lns and problem.n_conflicts >= ctx.lns_min_conflicts
    no_cp_sat = too_large or lns_only  # no CP-SAT stage at this size: LNS, if any, is last
    # The least time worth a CP-SAT stage (inf: none at this size).
    exact_min_s = np.inf if no_cp_sat else build_seconds(problem, ctx.cliques, ctx.objective)
    exact_min_s *= EXACT_TIME_PER_BUILD
    reinserts = (  # LNS_OBJECTIVES hold REINSERT_OBJECTIVES: uses_lns or too_large then
        ctx.objective in REINSERT_OBJECTIVES
        and problem.n_conflicts > ctx.exact_max_conflicts
        and problem.n_conflicts >= ctx.lns_min_conflicts
    )
    mid_turns = (  # the turns as the first stage below lns_min_conflicts
        ctx.objective in REINSERT_OBJECTIVES
        and max(ctx.exact_max_conflicts + 1, MID_TURNS_MIN_CONFLICTS)
        <= problem.n_conflicts
        < ctx.lns_min_conflicts
        and ctx.warm is None
    )
    # A re-schedule starts from its previous answer (tabu search, below), not from plans.
    plans = (reinserts or mid_turns) and ctx.warm is None
    planned: list[tuple[Assignments, float]] = []  # cheapest first
    if plans:
        until = time.monotonic() + PLANNED_SHARE * (deadline - time.monotonic())
        planned = planned_starts(ctx, PLANNED_ORDERS, ctx.seed, until)
    if planned:  # the instant answer is not sought (see PLANNED_ORDERS)
        best, cost, stages = SolverOutput(planned[0][0]), planned[0][1], ["planned"]
    else:
        best, stages = SolverOutput(plain_start(ctx)), ["start"]
        cost = ctx.cost(best.assignment)
    if problem.n_conflicts > ctx.exact_max_conflicts and not plans:
        first = "tabu" if ctx.warm is not None else ctx.first_stage
        left = deadline - time.monotonic()
        descends = ctx.objective in DESCENT_OBJECTIVES and (
            (1 - FIRST_STAGE_SHARE) * left >= DESCENT_S_PER_CONFLICT * problem.n_conflicts
        )
        # Whether a stage follows the first: the descent, LNS, or CP-SAT where it fits.
        shared = uses_lns or descends or (1 - FIRST_STAGE_SHARE) * left > exact_min_s
        found = get_solver(first)(_with_time(ctx, FIRST_STAGE_SHARE * left if shared else left))
        found_cost = np.inf if found is None else ctx.cost(found.assignment)
        if found is not None and found_cost <= cost:
            best, cost = found, found_cost
            stages.append(first)
        if descends:
            descended, descended_cost, rounds = descend_types(
                ctx.orientation, ctx.evaluator, ctx.objective, best.assignment.a_first, deadline
            )
            if descended_cost < cost:
                best, cost = replace(best, assignment=descended), descended_cost
                stages.append(f"types by descent x{rounds}")
    if reinserts or mid_turns:
        left = deadline - time.monotonic()
        share = MID_TURNS_SHARE if mid_turns else REINSERT_SHARE
        until = time.monotonic() + share * left if uses_lns else deadline
        # The other plans start lineages of their own (see take_turns' ``others``).
        turned = take_turns(ctx, best.assignment, cost, until, ctx.seed, others=planned[1:])
        if turned.cost < cost:
            best, cost = replace(best, assignment=turned.best), turned.cost
            stages.append(f"re-insertion x{turned.turns} turns")
        if not uses_lns:
            why = (
                f"above {ctx.exact_stage_max_conflicts} conflicts"
                if too_large
                else _lns_from(ctx.objective)
            )
            verdict = f"re-insertion search to the deadline {why}"
            return replace(best, optimal=False, detail=_detail(stages, verdict))
    tail = _Tail(uses_lns, lns_only, no_cp_sat, too_large, exact_min_s)
    if not _beside_lns(problem, uses_lns):
        return _exact_tail(ctx, deadline, best, cost, stages, tail)
    exact_tail = partial(_exact_tail, ctx, deadline, best, cost, stages, tail)
    return _turns_beside(ctx, best.assignment, cost, deadline, exact_tail)


class _Tail(NamedTuple):
    """Which of the exact stages follow the search (see :func:`_staged`)."""

    uses_lns: bool  # CP-SAT LNS runs
    lns_only: bool  # ... and is the last stage
    no_cp_sat: bool  # no CP-SAT stage at this size
    too_large: bool  # above ``exact_stage_max_conflicts``
    exact_min_s: float  # the least time worth a CP-SAT stage (inf: none)


def _exact_tail(
    ctx: SolveContext,
    deadline: float,
    best: SolverOutput,
    cost: float,
    stages: list[str],
    tail: _Tail,
) -> SolverOutput:
    """LNS then hinted CP-SAT (or the tabu polish) from ``best`` (of ``cost``, reached by
    ``stages``) within ``deadline`` (monotonic), as ``tail`` says."""
    problem = ctx.problem
    uses_lns, lns_only, no_cp_sat, too_large, exact_min_s = tail
    if uses_lns:
        left = deadline - time.monotonic()
        last = lns_only or left <= exact_min_s  # no CP-SAT stage follows
        until = (
            deadline if last else min(deadline - left * (1 - MID_LNS_SHARE), deadline - exact_min_s)
        )
        # The MILP follows, and no LNS step frees the whole fleet (which may prove).
        patient = milp_staged(problem, ctx.objective) and not last
        patient &= problem.n_robots > LNS_MAX_ROBOTS
        posed = LAST_LNS_POSED if no_cp_sat else None  # None: the request's objective
        found = lns_search(
            ctx, best.assignment, until, ctx.seed,
            converge=not last, held_in_order=LNS_HELD_IN_ORDER, posed_for=posed,
            patience_s=MILP_LNS_PATIENCE_S if patient else None,
        )  # fmt: skip
        steps = found.steps
        if found.cost < cost or found.optimal:
            best, cost = replace(best, assignment=found.best), found.cost
            stages.append(f"lns x{steps}")
        if found.optimal:
            verdict = "proven optimal by LNS (every robot in a conflict freed)"
            return replace(best, optimal=True, detail=_detail(stages, verdict))
        if last:
            verdict = (
                f"no CP-SAT stage from {ctx.lns_min_conflicts} conflicts ({steps} LNS steps)"
                if lns_only
                else "no time for CP-SAT"
            )
            return replace(best, optimal=False, detail=_detail(stages, verdict))
    left = deadline - time.monotonic()
    if left <= exact_min_s:
        if left > 0 and (too_large or problem.n_conflicts > ctx.exact_max_conflicts):
            polished, polished_cost, restarts = _polish(ctx, best.assignment, cost, deadline)
            if polished_cost < cost:  # the first stage stopped early (its own cap, patience)
                stage = f"tabu x{restarts}" if restarts > 1 else "tabu"
                best, stages = replace(best, assignment=polished), [*stages, stage]
        verdict = (
            f"no CP-SAT stage above {ctx.exact_stage_max_conflicts} conflicts"
            if too_large
            else "no time for CP-SAT"
        )
        return replace(best, optimal=False, detail=_detail(stages, verdict))

    def cp_sat() -> SolverOutput:
        improved, verdict = improve(ctx, best, left)
        return replace(improved, detail=_detail(stages, verdict))

    if _beside_lns(problem, uses_lns):  # already under way
        return cp_sat()
    return _turns_beside(ctx, best.assignment, cost, deadline, cp_sat)


def _beside_lns(problem: Problem, uses_lns: bool) -> bool:
    """Whether the turns beside (BESIDE) start with LNS (or with the CP-SAT stage where no
    LNS runs), not with the CP-SAT stage after it: not where LNS may prove optimality (a
    step that frees a whole fleet of up to LNS_MAX_ROBOTS), whose model building the turns
    would slow."""
    return not uses_lns or problem.n_robots > LNS_MAX_ROBOTS


def _turns_beside(
    ctx: SolveContext,
    start: Assignments,
    cost: float,
    deadline: float,
    stages: Callable[[], SolverOutput],
) -> SolverOutput:
    """What ``stages()`` answers, run with re-insertion turns beside them from ``start``
    (of ``cost``) until they end (within ``deadline``, monotonic), or the turns' answer
    where cheaper (see BESIDE)."""
    beside = _Beside.start(ctx, start, cost, deadline)
    try:
        out = stages()
    finally:
        found = None if beside is None else beside.ended()
    return _with_beside(ctx, out, found)


class _Beside:
    """Re-insertion turns (:func:`~service.solvers.turns.take_turns`) in a thread of their
    own, on the cores the solve may take that its exact stages leave idle (CP-SAT LNS, the
    CP-SAT and MILP stages run ``ctx.workers`` threads), from the best answer so far until
    the deadline or until stopped (see BESIDE)."""

    def __init__(self, pool: ThreadPoolExecutor, run: Future[TurnsResult], stop: threading.Event):
        self._pool, self._run, self._stop = pool, run, stop

    @classmethod
    def start(
        cls, ctx: SolveContext, start: Assignments, cost: float, deadline: float
    ) -> _Beside | None:
        """The turns from ``start`` (of ``cost``) to ``deadline`` (monotonic), started
        (None: BESIDE off, an objective or a size re-insertion does not search, or no core
        left beside the exact stages)."""
        searches = ctx.objective in REINSERT_OBJECTIVES
        searches &= ctx.problem.n_conflicts > ctx.exact_max_conflicts
        if not (BESIDE and searches) or cores_per_solve() <= ctx.workers:
            return None
        stop, pool = threading.Event(), ThreadPoolExecutor(1)
        run = pool.submit(
            take_turns, ctx, start, cost, deadline, ctx.seed + BESIDE_SEED,
            held=ctx.workers, stop=stop,
        )  # fmt: skip
        return cls(pool, run, stop)

    def ended(self) -> TurnsResult:
        """Stops the turns (a search ends at its next step) and returns what they found."""
        self._stop.set()
        try:
            return self._run.result()
        finally:
            self._pool.shutdown()


def _with_beside(ctx: SolveContext, out: SolverOutput, found: TurnsResult | None) -> SolverOutput:
    """``out``, or the answer the turns beside its exact stages ``found`` where cheaper
    (never where ``out`` is proven optimal)."""
    if found is None or out.optimal or found.cost >= ctx.cost(out.assignment):
        return out
    verdict = f"re-insertion beside them cheaper (x{found.turns} turns)"
    return replace(out, assignment=found.best, detail=f"{out.detail}; {verdict}")


def _lns_from(objective: str) -> str:
    """Why the turns took the budget below the CP-SAT cap: MID_LNS_LEAST_S of ``objective``
    (one of LNS_OBJECTIVES) not left."""
    least = MID_LNS_LEAST_S[objective]
    return f"(LNS from {least:g} s)" if math.isfinite(least) else f"(no LNS for {objective})"


def _polish(
    ctx: SolveContext, start: Assignments, cost: float, deadline: float
) -> tuple[Assignments, float, int]:
    """Tabu search from the best so far until ``deadline`` (monotonic): restarted from the
    best with the next seed whenever it stops on its own (patience or its iteration cap),
    so that the budget is used, not left, where no CP-SAT stage follows. -> (best, its
    cost, searches run)."""
    best, best_cost, runs = start, cost, 0
    while (left := deadline - time.monotonic()) > MIN_POLISH_S:
        found, found_cost, _ = tabu_search(ctx, best, budget_s=left, seed=ctx.seed + runs)
        runs += 1
        if found_cost < best_cost:
            best, best_cost = found, found_cost
    return best, best_cost, runs


def _with_time(ctx: SolveContext, time_limit_s: float) -> SolveContext:
    """``ctx`` with another time limit, sharing its cliques, evaluator and decoder."""
    out = copy.copy(ctx)  # the cached properties live in __dict__ and are shared
    out.time_limit_s = max(time_limit_s, 0.0)
    return out


def _detail(stages: list[str], verdict: str) -> str:
    return f"{' -> '.join(stages)}; {verdict}"
