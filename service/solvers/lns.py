"""Large-neighbourhood search (LNS): CP-SAT re-plans a few robots at a time.

On congested warehouses of about 100 robots (2,000-4,000 conflicts) the searches
that change one conflict or one robot's priority at a time stall far above what
CP-SAT's own LNS reaches in 30 s on two cores, and CP-SAT on the whole model with
one worker barely moves from its hint (docs/benchmarks.md, "Large-neighbourhood
search"). This search solves many small exact problems instead. Each step

1. picks a few robots (LNS_ROBOTS at first, more after a plateau, see below): a seed
   drawn with probability growing with its delay, then robots drawn by how many
   conflicts they share with those picked so far, a wait that binds between them (one
   robot's delay set by the other's passage) counting BLOCKING_WEIGHT times more;
2. frees every conflict they take part in (direction and type) and holds every
   other robot's times at their current least values: a conflict with such a
   robot bounds the picked robot's delay (wait until it has passed, or pass
   before it arrives), and each density clique keeps the budget its held
   conflicts leave;
3. solves that sub-problem with CP-SAT, hinted with the current answer, for the
   picked robots' part of the objective, within SUB_TIME_S;
4. keeps the new assignment when the one evaluator finds it cheaper (and, as a
   guard, its node graph is acyclic).

A plateau: steps without improvement that together freed as many robots as the fleet
has (STALL_COVER). Then each step frees GROWTH times as many robots (up to
MAX_ROBOTS): some answers need many robots changed at once (a corridor's whole queue
let through in the other order) and no sequence of small improving steps reaches them.

Cycles can close through held robots: where pair sections lie inside merged nodes
such a cycle needs no waiting, so time bounds alone do not exclude it (every
sub-problem answer on a two-lane warehouse closed one without the following). The
sub-problem orders the picked robots' nodes and the held nodes its conflicts
touch (*boundary* nodes), with one precedence per pair of boundary nodes that
the held graph connects (see ``_Neighbourhood._order``). Where the caller asks
(``auto`` up to its ``exact_stage_max_conflicts``, see ``portfolio.LNS_HELD_IN_ORDER``)
the held nodes instead keep the incumbent's topological order, at constant positions
(``_Neighbourhood._order_in_place``): a smaller model, and a restriction where the held
graph leaves some unordered.

A picked robot waits for a held robot's least times, and may pass one first as long
as that delays it no further than its latest delays
(:meth:`~service.core.evaluate.Evaluator.latest_delays`, which leave every robot's
part of the objective where it was), as in :mod:`service.solvers.reinsert` (except that
for avg_delay every event stays held: re-insertion holds only the completions there,
:meth:`~service.core.evaluate.Evaluator.held_weights`, which LNS's sub-problem, counting
only the picked robots' delays, left unpriced: measured even to worse, session 50): the held
robots' part stays, and the sub-problem's own part is exact unless a picked robot
waits further on for a held robot that a picked robot pushed (the evaluation that
decides counts that). A search may pose its sub-problems for another objective than the
request's (``posed_for``: ``auto`` poses avg_delay's for avg_completion where LNS is its
last stage, see ``portfolio.LAST_LNS_POSED``); the one evaluator still decides by the
request's, and no such search claims a proof. Times are on CP-SAT's integer grid
(:func:`~service.solvers.exact.integer_times`), the held times too (the least and
latest times of the grid-rounded problem, so that the hint is feasible); every
accepted answer is re-evaluated exactly.

Objectives: the sums (avg_completion, avg_delay); max_completion and
sync_completion are not searched this way (a few robots rarely move a maximum,
and the mean couples every robot). Deterministic for a seed when no sub-solve is
cut by its time limit (most prove their optimum within tens of milliseconds) and the
solve has one worker. With more (``SolveContext.workers``), as many sub-problems of
disjoint robots are solved at once, each applied to the incumbent of its return and
checked again there (see :func:`lns_search`): which steps overlap depends on timing.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, replace
from typing import NamedTuple

import numba
import numpy as np
from ortools.sat.python import cp_model
from scipy.sparse import coo_array, csr_array

from service.core.assignment import Assignments
from service.core.csr import csr, gather
from service.core.evaluate import Evaluation, Evaluator
from service.core.orientation import _leads_to
from service.core.schemas import Objective
from service.solvers.cpsat_arrays import (
    INT64_MAX,
    INT64_MIN,
    add_hints,
    add_linear,
    add_sums,
    minimize,
    negated,
    new_vars,
)
from service.solvers.exact import (
    LINEARIZATION_LEVEL,
    Delays,
    ExactModel,
    Slots,
    add_conflict_order,
    add_path_order,
    add_waits,
    delay_weights,
    integer_times,
    literal_domains,
    search,
    time_slots,
)
from service.solvers.pace import Pace
from service.solvers.registry import SolveContext, SolverOutput, register
from service.solvers.tabu import plain_start

__all__ = ["LNS_OBJECTIVES", "LNS_ROBOTS", "SUB_TIME_S", "LnsResult", "lns_search"]

# Objectives a neighbourhood's part of the cost stands for (sums over robots).
LNS_OBJECTIVES = ("avg_completion", "avg_delay")
# Robots re-planned per step, at first, and after a plateau. Measured (session 19, the
# sub-problem tuning below; six 100-robot warehouses, 1.5 s of priority_tabu then LNS,
# mean cost ratio against 30-s references of two CP-SAT workers, one run each, spread
# about 0.01): always 5 robots 0.893 at 5 s, 0.921 at 10 s (two worlds stuck at 0.86
# up to 20 s; 15 robots reached 0.989 there at 20 s); growth by 1.5 after 10 (5) steps
# without improvement 0.898 (0.892) / 0.926 (0.958); from 8 robots after 10 (5) steps
# 0.900 (0.905) / 0.960 (0.969); after a stall covering the fleet (shipped) 0.910 /
# 0.956. A fixed step count grew too soon on 150-200-robot warehouses (10-15 steps in
# 3.5 s, worse than 5 robots on 3 of 4); covering the fleet was the best of the three
# on all 4 and on 50-robot ones better than 5 robots on all 4.
LNS_ROBOTS = 8
STALL_COVER = 1.0  # robots freed without improvement, per robot of the fleet
GROWTH = 1.5
MAX_ROBOTS = 40
# Weight of a wait that binds between two robots when drawing a neighbourhood's robots,
# against 1 per conflict they share: the robots that hold each other up now are freed
# together. Measured (session 20; six 100-robot warehouses, 1.5 s of priority_tabu then
# LNS, mean cost ratio against the 30-s references, three seeds): to 5 s 0.9322 without
# (0.9309 / 0.9302 / 0.9355), 0.9561 with 10 (0.9569 / 0.9524 / 0.9591), 0.954 with 30
# (two seeds); to 10 s 0.9668 -> 0.9815 (seed 0). At 250 robots LNS stays behind
# priority_tabu either way (0.85-0.93 against ~0.96 at 5 s). Re-measured (session 42,
# ``python -m bench.ab``, ``auto`` at 5 s, interleaved run by run, 3 against 10): wh_two_way
# and wh_two_lane of 100 robots, three worlds each, four seeds, 0.9732 / 0.9674 (15 cheaper,
# 9 dearer), again on three other worlds each 0.9816 / 0.9765 (14 / 9); of 250 robots (two
# seeds) 0.9218 / 0.9120 (8 / 4); wh_one_way, wh_mixed, wh_parked of 100 0.9773 / 0.9769
# (5 / 7); the conformance sets and 25-50-robot worlds the same at 5 s (26 / 26 runs
# proven) and at 1 s (0.9975 / 0.9972, 31 / 30 proven).
BLOCKING_WEIGHT = 3.0
# Whether only the binding waits that hold up what the objective reads (critical: their
# latest delay is their least) pair robots there (a wait no robot's part depends on gains
# nothing when freed). Measured (session 46, `python -m bench.ab --b
# service.solvers.lns.CRITICAL_WAITS=False`, ``auto`` at 5 s, avg_completion): warehouses
# of 100 robots (two-way, two-lane, one-way, mixed; three worlds, two seeds) 0.9770 /
# 0.9732 (14 cheaper, 10 dearer of 24); two-way and two-lane of 250 (two worlds) 4 / 0;
# the sets wh_50 and wh_100 even (4 / 4 proven).
CRITICAL_WAITS = True
# Time limit of one sub-problem; most are proven optimal well within it at 100 robots.
SUB_TIME_S = 0.3
# CP-SAT's presolve of a sub-problem took most of its time (0.1-0.2 s of domain
# propagation along the node positions, 80-120 loops, on 100-robot warehouses); without
# it, from the complete hint, the same sub-problems were proven in 0.02-0.15 s. Of what
# was left, two thirds went to CP-SAT's root-level closure of precedences (linear2
# bounds, redone at each improving solution: perf, session 19); without it 20 sub-problems
# of a 100-robot warehouse took 0.32 s instead of 1.30 s (two-lane: 0.62 s, 2.0 s), to the
# same optima; without SAT inprocessing too, 30 others 0.36 s instead of 0.51 s (two-lane:
# 0.46 s, 0.87 s), all proven optimal. Symmetry detection, FIXED_SEARCH and no probing
# were measured and left at CP-SAT's defaults (no gain or slower).
SUB_TUNING = {
    "cp_model_presolve": False,
    "transitive_precedences_work_limit": 0,
    "use_sat_inprocessing": False,
}
# Least time left worth another step, beyond what building the last one took (~10-30 ms
# at 100 robots, 30-50 ms at 250: without it 0.2-s requests there ran 0.24 s).
MIN_STEP_S = 0.03


@dataclass(frozen=True, eq=False)
class _Fleet:
    """What picking and building neighbourhoods reads, built once per search.

    Shapes: R robots, M conflicts, E events.
    """

    conf_robots: np.ndarray  # (M, 2) robot of each side
    robot_conflicts: tuple[np.ndarray, np.ndarray]  # CSR robot -> its conflicts
    shared: csr_array  # (R, R) conflicts between each pair of robots
    event_start: np.ndarray  # (R+1,) events of robot r are event_start[r]:event_start[r+1]
    scale: float
    ti: np.ndarray  # (P,) int64 times on CP-SAT's grid
    horizon: int
    grid: Evaluator  # least delays of the grid-rounded problem
    posed: Objective  # what the sub-problems minimise (the picked robots' part of it)
    held: np.ndarray  # (E+1,) bool events in that objective: their delays bound the latest
    delay_weight: np.ndarray  # (E,) int weight of each event's delay in avg_delay
    domains: tuple[np.ndarray, ...]  # (M,) each: literal_domains' a_lo, a_hi, f_lo, f_hi
    slots: Slots  # (S,) the time constraints of every live conflict
    slot_robots: np.ndarray  # (S, 2) the robot that waits in each slot, the one it waits for

    @classmethod
    def of(cls, ctx: SolveContext, posed: Objective | None = None) -> _Fleet:
        """``ctx``'s fleet, its sub-problems posed for ``posed`` (one of LNS_OBJECTIVES;
        None: the request's objective)."""
        posed = ctx.objective if posed is None else posed
        p = ctx.problem
        n_robots, n_conf = p.n_robots, p.n_conflicts
        conf_robots = np.stack([p.node_robot[p.conf_a], p.node_robot[p.conf_b]], axis=1)
        robot_conflicts = csr(conf_robots.ravel(), np.repeat(np.arange(n_conf), 2), n_robots)
        pairs = coo_array(
            (np.ones(n_conf), (conf_robots[:, 0], conf_robots[:, 1])), shape=(n_robots, n_robots)
        )
        scale, ti, horizon = integer_times(p)
        event_robot = p.event_robot  # (E,) sorted: events go by robot
        event_start = np.searchsorted(event_robot, np.arange(n_robots + 1))
        grid = Evaluator(replace(p, tp_time=ti / scale))
        domains = literal_domains(p, ctx.cliques.forbidden())
        slots = time_slots(p, ti, np.flatnonzero(~p.realized)).typed(*domains[2:])
        waiter = event_robot[slots.target]  # (S,) targets are events (pair entries)
        return cls(
            conf_robots,
            robot_conflicts,
            (pairs + pairs.T).tocsr(),
            event_start,
            scale,
            ti,
            horizon,
            grid,
            posed,
            grid.objective_weights(posed) > 0,
            delay_weights(p),
            domains,
            slots,
            np.stack([waiter, conf_robots[slots.conflict].sum(axis=1) - waiter], axis=1),
        )

    def conflicts_of(self, robots: np.ndarray) -> np.ndarray:
        """(K,) sorted distinct conflicts any of ``robots`` takes part in."""
        return np.unique(gather(*self.robot_conflicts, robots)[0])

    def events_of(self, robots: np.ndarray) -> np.ndarray:
        """(N,) the events of ``robots``, robot by robot, each robot's in path order."""
        return gather(self.event_start, np.arange(self.event_start[-1]), robots)[0]

    def pick(
        self, rng: np.random.Generator, current: _Incumbent, count: int, busy: np.ndarray
    ) -> np.ndarray:
        """``count`` robots (fewer if fewer are not ``busy``), none of the ``busy`` ones
        (R,) bool (not all): a seed drawn by delay, then robots drawn by conflicts shared
        with those picked, a wait that binds between them counting BLOCKING_WEIGHT more;
        where the seed's conflict component runs out, another seed drawn by delay (so
        that a fleet of several components can be freed whole, and proven optimal)."""
        n_robots = current.delay.size
        weight = (np.maximum(current.delay, 0.0) + 1e-9) * ~busy  # (R,)
        picked = [int(rng.choice(n_robots, p=weight / weight.sum()))]
        score = np.zeros(n_robots)  # (R,) conflicts shared with the robots picked
        while len(picked) < count:
            for pairs, scale in ((self.shared, 1.0), (current.waits, BLOCKING_WEIGHT)):
                row = pairs[[picked[-1]]]
                score[row.indices] += scale * row.data
            score[picked] = 0.0
            score[busy] = 0.0
            total = score.sum()
            if total > 0:
                picked.append(int(rng.choice(n_robots, p=score / total)))
                continue
            rest = weight.copy()  # the component is exhausted: a new seed, by delay
            rest[picked] = 0.0
            if rest.sum() <= 0:
                break
            picked.append(int(rng.choice(n_robots, p=rest / rest.sum())))
        return np.array(picked, dtype=np.int64)


@dataclass(frozen=True, eq=False)
class _Incumbent:
    """The current answer and what every step reads of it, found once per accepted answer.

    Shapes: M conflicts, E events, V nodes, Q cliques, R robots.
    """

    a_first: np.ndarray  # (M,) bool
    following: np.ndarray  # (M,) bool
    cost: float
    delay: np.ndarray  # (R,) each robot's delay at completion
    grid_delay: np.ndarray  # (E+1,) int64 least delays on CP-SAT's grid
    grid_latest: np.ndarray  # (E+1,) int64 latest delays keeping each robot's part, on it
    rank: np.ndarray  # (V,) node positions in a topological order
    counts: np.ndarray  # (Q,) following-type conflicts per clique
    waits: csr_array  # (R, R) binding waits between each pair of robots (either way)

    @classmethod
    def of(
        cls,
        ctx: SolveContext,
        fleet: _Fleet,
        answer: Assignments,
        rank: np.ndarray,
        evaluation: Evaluation,
        counts: np.ndarray | None = None,
    ) -> _Incumbent:
        """``answer`` with its topological rank, its evaluation and its following-type
        ``counts`` (Q,) per clique (all already found; None: counted here)."""
        a_first, following = answer.a_first[0], answer.following[0]
        if counts is None:
            counts = ctx.cliques.following_counts(following[None])[0]
        on_grid = fleet.grid.evaluate(answer)
        grid = np.rint(on_grid.event_delay[0] * fleet.scale).astype(np.int64)
        latest = fleet.grid.latest_delays(answer, on_grid, fleet.held)  # (E+1,) inf: unbounded
        grid_latest = np.rint(np.minimum(latest * fleet.scale, fleet.horizon)).astype(np.int64)
        return cls(
            a_first,
            following,
            float(evaluation.costs[ctx.objective][0]),
            evaluation.completion[0] - ctx.problem.free_time(),
            grid,
            grid_latest,
            rank,
            counts,
            _binding_waits(fleet, a_first, following, grid, grid_latest),
        )

    @classmethod
    def start(cls, ctx: SolveContext, fleet: _Fleet, answer: Assignments) -> _Incumbent:
        """The valid ``answer`` a search starts from."""
        rank = ctx.orientation.topological_rank(answer.a_first[0])
        if rank is None:
            raise ValueError("the answer to search from closes a cycle")
        return cls.of(ctx, fleet, answer, rank, ctx.evaluator.evaluate(answer))


def _binding_waits(
    fleet: _Fleet,
    a_first: np.ndarray,
    following: np.ndarray,
    grid_delay: np.ndarray,
    grid_latest: np.ndarray,
) -> csr_array:
    """(R, R) symmetric: the slots of an answer (directions ``a_first``, types
    ``following`` (M,)) whose wait sets their robot's delay (``grid_delay`` (E+1,)) and,
    with CRITICAL_WAITS, holds up what the objective reads (its event's latest delay
    ``grid_latest`` (E+1,) is its least): the robots that hold each other up now, whom a
    neighbourhood should free together."""
    s = fleet.slots
    waited = grid_delay[s.target]
    binding = s.active(a_first, following) & (waited > 0)
    binding &= waited == grid_delay[s.source] + s.offset  # (S,)
    if CRITICAL_WAITS:
        binding &= grid_latest[s.target] <= waited
    waiter, blocker = fleet.slot_robots[binding].T
    n = fleet.event_start.size - 1
    pairs = coo_array((np.ones(waiter.size), (waiter, blocker)), shape=(n, n))
    return (pairs + pairs.T).tocsr()


class _Neighbourhood:
    """The sub-problem of re-planning ``robots`` with every other robot's times held."""

    def __init__(
        self,
        ctx: SolveContext,
        fleet: _Fleet,
        robots: np.ndarray,
        current: _Incumbent,
        held_in_order: bool = False,
    ) -> None:
        # Data.
        problem = ctx.problem
        self.robots = robots  # (k,) re-planned
        self.conflicts = fleet.conflicts_of(robots)  # (K,) freed
        events = fleet.events_of(robots)  # (N,) the picked robots' events, by robot
        model = cp_model.CpModel()
        k = self.conflicts.size

        # Variables: the freed conflicts' literals, the picked robots' delays.
        a_lo, a_hi, f_lo, f_hi = (d[self.conflicts] for d in fleet.domains)
        a_lit = np.full(problem.n_conflicts, -1, dtype=np.int64)  # (M,) -1: held
        f_lit = a_lit.copy()
        a_lit[self.conflicts] = new_vars(model, k, a_lo, a_hi)
        f_lit[self.conflicts] = new_vars(model, k, f_lo, f_hi)
        delay_var = np.full(current.grid_delay.size, -1, dtype=np.int64)  # (E+1,)
        delay_var[events] = new_vars(model, events.size, 0, fleet.horizon)
        # Held robots' delays stay known; a picked robot passing one first may delay it
        # up to its latest.
        delays = Delays(delay_var, current.grid_delay, current.grid_latest)
        self.em = ExactModel(
            model,
            a_lit[self.conflicts],
            f_lit[self.conflicts],
            fleet.scale,
            LINEARIZATION_LEVEL[fleet.posed],
        )
        # Hint: the current answer (add_hint first: it clears earlier hints).
        self.em.add_hint(
            Assignments.single(current.a_first[self.conflicts], current.following[self.conflicts])
        )
        add_hints(model, delay_var[events], current.grid_delay[events])

        # Constraints.
        if held_in_order:
            self._order_in_place(ctx, robots, a_lit, current)
        else:
            self._order(ctx, robots, a_lit, current)
        self._budgets(ctx, fleet, current, f_lit)
        add_path_order(model, delay_var, events[~np.isin(events, fleet.event_start[robots])] - 1)
        live = self.conflicts[~problem.realized[self.conflicts]]
        slots = time_slots(problem, fleet.ti, live).typed(*fleet.domains[2:])
        add_waits(model, slots, a_lit, f_lit, delays)

        # Objective: the picked robots' part (the held robots' is a constant).
        if fleet.posed == "avg_completion":
            last = delay_var[problem.tp_event[problem.last_tp[robots]]]  # (k,) -1: never waits
            minimize(model, last[last >= 0], 1)
        else:  # avg_delay
            minimize(model, delay_var[events], fleet.delay_weight[events])

    def _order(
        self, ctx: SolveContext, robots: np.ndarray, a_lit: np.ndarray, current: _Incumbent
    ) -> None:
        """Acyclicity: node positions increasing along the picked robots' paths, along every
        freed conflict, and from each held node a freed conflict touches (a *boundary* node)
        to the boundary nodes the held graph leads it to. Any cycle leaves the held graph
        through a freed conflict, so these positions exclude every cycle."""
        p, graph, model = ctx.problem, ctx.orientation, self.em.model
        picked_node = np.zeros(p.n_robots, dtype=bool)
        picked_node[robots] = True
        picked_node = picked_node[p.node_robot]  # (V,)
        ends = np.concatenate([p.conf_a[self.conflicts], p.conf_b[self.conflicts]])
        boundary = np.zeros(p.n_nodes, dtype=bool)
        boundary[ends[~picked_node[ends]]] = True
        tails, heads = _held_reach(
            np.flatnonzero(boundary),
            boundary,
            picked_node,
            current.rank,
            *graph.walk_args(current.a_first),
        )
        nodes = np.flatnonzero(boundary | picked_node)  # (N,)
        pos = np.full(p.n_nodes, -1, dtype=np.int64)  # (V,) position variables, -1: none
        pos[nodes] = new_vars(model, nodes.size, 0, nodes.size - 1)
        add_hints(model, pos[nodes], np.argsort(np.argsort(current.rank[nodes])))  # current order
        along = np.flatnonzero(picked_node[1:] & (p.node_robot[1:] == p.node_robot[:-1]))
        add_linear(model, [pos[along + 1], pos[along]], [1, -1], 1, INT64_MAX)
        add_linear(model, [pos[heads], pos[tails]], [1, -1], 1, INT64_MAX)
        conf_a, conf_b = p.conf_a[self.conflicts], p.conf_b[self.conflicts]
        add_conflict_order(model, pos[conf_a], pos[conf_b], a_lit[self.conflicts])

    def _order_in_place(
        self, ctx: SolveContext, robots: np.ndarray, a_lit: np.ndarray, current: _Incumbent
    ) -> None:
        """Acyclicity with the held nodes kept in the incumbent's topological order (see
        ``portfolio.LNS_HELD_IN_ORDER``): each held node at a constant position, its rank
        times the picked nodes plus one (so that all of them fit between two), the picked
        nodes' positions increasing along their paths and along every freed conflict. A
        restriction: the held graph may leave two held nodes unordered that a picked
        robot would put the other way round."""
        p, model = ctx.problem, self.em.model
        picked_node = np.zeros(p.n_robots, dtype=bool)
        picked_node[robots] = True
        picked_node = picked_node[p.node_robot]  # (V,)
        nodes = np.flatnonzero(picked_node)  # (N,)
        spread = nodes.size + 1
        at = spread * current.rank.astype(np.int64)  # (V,) held nodes' positions
        pos = np.full(p.n_nodes, -1, dtype=np.int64)  # (V,) position variables, -1: held
        pos[nodes] = new_vars(model, nodes.size, -spread, spread * p.n_nodes)
        add_hints(model, pos[nodes], at[nodes])  # the current order
        along = np.flatnonzero(picked_node[1:] & (p.node_robot[1:] == p.node_robot[:-1]))
        add_linear(model, [pos[along + 1], pos[along]], [1, -1], 1, INT64_MAX)
        conf_a, conf_b = p.conf_a[self.conflicts], p.conf_b[self.conflicts]  # (K,) each
        a_first = a_lit[self.conflicts]
        both = picked_node[conf_a] & picked_node[conf_b]
        add_conflict_order(model, pos[conf_a[both]], pos[conf_b[both]], a_first[both])
        # One side held: the picked side's position before or after the held one's.
        for picked_side, held_side, sign in ((conf_b, conf_a, 1), (conf_a, conf_b, -1)):
            rows = ~picked_node[held_side]
            var, lit, held_at = pos[picked_side[rows]], a_first[rows], at[held_side[rows]]
            after, before = (lit, negated(lit)) if sign > 0 else (negated(lit), lit)
            add_linear(model, [var], [1], held_at + 1, INT64_MAX, [after])
            add_linear(model, [var], [1], INT64_MIN, held_at - 1, [before])

    def _budgets(
        self, ctx: SolveContext, fleet: _Fleet, current: _Incumbent, f_lit: np.ndarray
    ) -> None:
        """At most what its held conflicts leave of each binding clique's budget, where
        more of its freed conflicts may be following-type than that: on two-lane
        warehouses of 250 robots two thirds of the cliques a step touches (half the terms)
        have room for all of them."""
        cliques = ctx.cliques
        # (N,) pairs of a freed conflict and a binding clique holding it
        clique, conflict = gather(*cliques.binding_by_conflict, self.conflicts)
        _, _, _, f_hi = fleet.domains  # (M,) each; f_hi 0: never following-type
        # Others: forbidden (see literal_domains) or never following-type.
        kept = f_hi[conflict] > 0
        order = np.argsort(clique[kept], kind="stable")
        clique, conflict = clique[kept][order], conflict[kept][order]
        touched, first = np.unique(clique, return_index=True)  # (T,)
        if touched.size == 0:
            return
        sizes = np.diff(np.append(first, conflict.size))  # (T,)
        freed_following = np.add.reduceat(current.following[conflict].astype(np.int64), first)
        room = cliques.budget[touched] - (current.counts[touched] - freed_following)  # (T,)
        tight = room < sizes  # (T,) room for fewer than all
        start = np.append(0, np.cumsum(sizes[tight]))  # (T'+1,)
        terms = conflict[np.repeat(tight, sizes)]
        add_sums(self.em.model, start, f_lit[terms], INT64_MIN, room[tight])

    def solve(self, time_limit_s: float, seed: int) -> _Solved | None:
        """The freed conflicts as CP-SAT decides them (None if it found nothing within the
        limit). Runs in a worker thread: CP-SAT releases the GIL while it searches."""
        result = search(self.em, time_limit_s, seed, tuning=SUB_TUNING)
        if result is None:
            return None
        return _Solved(result.assignment.a_first[0], result.assignment.following[0], result.optimal)

    def onto(self, current: _Incumbent, solved: _Solved) -> Assignments:
        """``current`` (the incumbent this was built on, or a later one) with the freed
        conflicts set as ``solved`` decided them."""
        a_first, following = current.a_first.copy(), current.following.copy()
        a_first[self.conflicts] = solved.a_first
        following[self.conflicts] = solved.following
        return Assignments(a_first[None], following[None])


class _Solved(NamedTuple):
    """A sub-problem's answer: its freed conflicts' directions and types (K,), and whether
    CP-SAT proved them optimal."""

    a_first: np.ndarray
    following: np.ndarray
    optimal: bool


@numba.njit(cache=True)
def _held_reach(
    starts: np.ndarray,
    boundary: np.ndarray,
    picked: np.ndarray,
    rank: np.ndarray,
    orient: np.ndarray,
    succ: np.ndarray,
    inc_start: np.ndarray,
    inc_conf: np.ndarray,
    conf_a: np.ndarray,
    conf_b: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Arcs (tails (K,), heads (K,)) from each boundary node in ``starts`` (S,) to the
    boundary nodes it reaches through held nodes only (path arcs and conflicts oriented by
    ``orient``, never into a picked node), stopping at the first boundary node on each way.

    One sweep against ``rank`` (V,), a topological order of the held graph: a node's set
    (a bitset over ``starts``) is its held successors, each a boundary node itself or,
    if not, its set. A depth-first search from each start instead took 12 ms a step on
    250-robot warehouses (150 starts, ~90 conflicts a node), an eighth of the step.

    Shapes: boundary, picked (V,) bool; orient (M,) int8 (1: a -> b).
    """
    n_nodes = succ.size
    index = np.full(n_nodes, -1, dtype=np.int64)  # (V,) each start's bit
    index[starts] = np.arange(starts.size)
    reach = np.zeros((n_nodes, (starts.size + 63) // 64), dtype=np.uint64)  # (V, words)
    for v in np.argsort(rank)[::-1]:  # successors first
        if picked[v]:
            continue
        for k in range(inc_start[v] - 1, inc_start[v + 1]):  # the path's arc, then conflicts
            w = succ[v] if k < inc_start[v] else _leads_to(inc_conf[k], v, orient, conf_a, conf_b)
            if w < 0 or picked[w]:
                continue
            if boundary[w]:
                reach[v, index[w] // 64] |= np.uint64(1) << np.uint64(index[w] % 64)
            else:
                for j in range(reach.shape[1]):
                    reach[v, j] |= reach[w, j]
    tails = np.empty(16, dtype=np.int64)
    heads = np.empty(16, dtype=np.int64)
    count = 0
    for u in starts:  # the set bits only: a test of every start per start grows as S^2
        for word in range(reach.shape[1]):
            bits, j = reach[u, word], word * 64
            while bits != 0:
                if bits & np.uint64(1):
                    if count == tails.size:
                        tails = np.concatenate((tails, np.empty(count, dtype=np.int64)))
                        heads = np.concatenate((heads, np.empty(count, dtype=np.int64)))
                    tails[count], heads[count] = u, starts[j]
                    count += 1
                bits >>= np.uint64(1)
                j += 1
    return _without_shortcuts(starts, tails[:count], heads[:count], n_nodes)


@numba.njit(cache=True)
def _without_shortcuts(
    starts: np.ndarray, tails: np.ndarray, heads: np.ndarray, n_nodes: int
) -> tuple[np.ndarray, np.ndarray]:
    """The arcs (grouped by tail, in ``starts`` order) without those that two others imply
    (u -> w where u -> v -> w): fewer constraints, the same order.

    Each node's heads as a bitset: a tail's implied heads are the union of its heads'
    sets, S / 64 words an arc. Walking each head's heads instead grew as S^3 on dense
    boundaries: 5 ms of a 25-ms step on 250-robot two-way warehouses (4 robots picked,
    ~240 boundary nodes linked nearly all to all)."""
    index = np.full(n_nodes, -1, dtype=np.int64)  # (V,) each node's bit, -1: none
    count = 0
    for nodes in (starts, heads):
        for v in nodes:
            if index[v] < 0:
                index[v] = count
                count += 1
    words = (count + 63) // 64
    out = np.zeros((count, words), dtype=np.uint64)  # (N, words) each node's heads
    for k in range(tails.size):
        j = index[heads[k]]
        out[index[tails[k]], j // 64] |= np.uint64(1) << np.uint64(j % 64)
    keep = np.ones(tails.size, dtype=np.bool_)
    implied = np.zeros(words, dtype=np.uint64)
    first = 0
    while first < tails.size:  # one tail's arcs at a time
        last = first
        while last < tails.size and tails[last] == tails[first]:
            last += 1
        implied[:] = 0
        for k in range(first, last):
            v = index[heads[k]]
            for word in range(words):
                implied[word] |= out[v, word]
        for k in range(first, last):
            j = index[heads[k]]
            keep[k] = (implied[j // 64] >> np.uint64(j % 64)) & np.uint64(1) == 0
        first = last
    return tails[keep], heads[keep]


class LnsResult(NamedTuple):
    """What a search ended with: the best answer, its cost, the steps taken, and whether it
    is proven optimal (a step that freed every robot in a conflict, proven by CP-SAT)."""

    best: Assignments
    cost: float
    steps: int
    optimal: bool


def lns_search(
    ctx: SolveContext,
    start: Assignments,
    deadline: float,
    seed: int,
    converge: bool = False,
    robots: int = LNS_ROBOTS,
    held_in_order: bool = False,
    posed_for: Objective | None = None,
    patience_s: float | None = None,
) -> LnsResult:
    """LNS from the valid ``start`` until ``deadline`` (monotonic), or with ``converge``
    until a plateau at the largest neighbourhood (min(MAX_ROBOTS, fleet)), or with
    ``patience_s`` once it has gone as long without improving as it took to its last
    improvement, and ``patience_s`` at least; at once when a step that freed every robot
    in a conflict (the whole problem: nothing held that could wait) is proven optimal.
    The first neighbourhoods free ``robots`` robots; with ``held_in_order`` they keep the
    held robots in the incumbent's order. Its sub-problems are posed for ``posed_for``
    (one of LNS_OBJECTIVES; None: the request's objective), its answers kept by the
    request's; posed for another, it proves nothing.

    ``ctx.workers`` sub-problems are solved at once, each in a thread (CP-SAT releases
    the GIL): while one is solved the next is built, from robots that no running one
    re-plans. Each is built on the incumbent of its time and applied to the incumbent of
    its return, which another may have changed meanwhile; the one evaluator and the
    checks of :func:`_cheaper` decide then. With one worker every step sees the
    incumbent it was built on, as a sequential search would. Measured (session 23; six
    100-robot warehouses, ``auto`` with two workers, cost ratio against the committed
    30-s references): two at once against one, 2 s 0.8741 vs 0.8728 (three seeds) with
    overlapping robots allowed, 0.8833 with robots in flight excluded; 5 s 0.9534 vs
    0.9322 (two seeds, better on five of six). 1.4-1.7x the steps: the main thread builds
    (~14 ms) while CP-SAT solves (~10-20 ms).
    """
    fleet = _Fleet.of(ctx, posed_for)
    rng = np.random.default_rng(seed)
    n_robots = ctx.problem.n_robots
    involved = np.flatnonzero(np.diff(fleet.robot_conflicts[0]))  # robots in a conflict
    best, current = start, _Incumbent.start(ctx, fleet, start)
    sizes, steps = _Sizes(n_robots, converge, robots), 0
    pace = Pace(deadline, time.monotonic)  # steps: building a sub-problem
    began_search = improved_at = pace.clock()
    # Each running sub-problem and the incumbent it was built on.
    running: dict[Future[_Solved | None], tuple[_Neighbourhood, _Incumbent]] = {}
    with ThreadPoolExecutor(max_workers=ctx.workers) as pool:
        while True:
            idle = pace.clock() - improved_at
            patient = patience_s is None or idle < max(patience_s, improved_at - began_search)
            while patient and len(running) < ctx.workers and pace.fits(margin_s=MIN_STEP_S):
                busy = _in_flight(running.values(), n_robots)
                count = None if busy.all() else sizes.next()
                if count is None:
                    break
                began = pace.clock()
                picked = fleet.pick(rng, current, count, busy)
                neighbourhood = _Neighbourhood(ctx, fleet, picked, current, held_in_order)
                pace.record(began)
                left = pace.left()
                if left <= 0:
                    break
                job = pool.submit(neighbourhood.solve, min(SUB_TIME_S, left), seed + steps)
                running[job] = (neighbourhood, current)
                steps += 1
            if not running:
                break
            job = next(iter(wait(running, return_when=FIRST_COMPLETED).done))
            neighbourhood, base = running.pop(job)
            solved = job.result()
            # A proof holds only for the incumbent the whole problem was built on; robots
            # in no conflict need not be freed (nothing couples their times to others').
            whole = bool(np.isin(involved, neighbourhood.robots).all())
            proven = solved is not None and solved.optimal and whole and base is current
            proven &= fleet.posed == ctx.objective  # a proof holds for the objective posed
            found = None if solved is None else neighbourhood.onto(current, solved)
            better = None if found is None else _cheaper(ctx, fleet, current, found, proven)
            sizes.record(better is not None)
            if better is None:
                continue
            best, current, improved_at = found, better, pace.clock()
            if proven:
                wait(running)  # at most ctx.workers - 1 others, each within the deadline
                return LnsResult(best, current.cost, steps, True)
    return LnsResult(best, current.cost, steps, False)


@dataclass
class _Sizes:
    """How many robots the next step frees: ``count`` at first (LNS_ROBOTS unless the
    search is told otherwise), GROWTH times as many (up to MAX_ROBOTS) after a plateau,
    i.e. steps without improvement that together freed STALL_COVER times the fleet; with
    ``converge``, none from a plateau at the largest size (min(MAX_ROBOTS, fleet)) on:
    the search ends."""

    n_robots: int
    converge: bool
    count: int = LNS_ROBOTS
    stalled: int = 0  # steps without improvement at this size
    ended: bool = False

    def next(self) -> int | None:
        """The next step's robot count (None: converged)."""
        if not self.ended and self.stalled * self.count >= STALL_COVER * self.n_robots:
            largest = min(MAX_ROBOTS, self.n_robots)
            self.ended = self.converge and self.count >= largest
            if not self.ended:
                self.count, self.stalled = min(int(self.count * GROWTH) + 1, MAX_ROBOTS), 0
        return None if self.ended else self.count

    def record(self, improved: bool) -> None:
        """A step's outcome: an improvement restarts the stall count."""
        self.stalled = 0 if improved else self.stalled + 1


def _in_flight(running: Iterable[tuple[_Neighbourhood, _Incumbent]], n_robots: int) -> np.ndarray:
    """(R,) bool: the robots the ``running`` sub-problems re-plan."""
    busy = np.zeros(n_robots, dtype=bool)
    for neighbourhood, _ in running:
        busy[neighbourhood.robots] = True
    return busy


def _cheaper(
    ctx: SolveContext, fleet: _Fleet, current: _Incumbent, found: Assignments, ties: bool
) -> _Incumbent | None:
    """``found`` as the new incumbent if the evaluator finds it cheaper (or, with ``ties``,
    as cheap); None otherwise, and if its node graph closes a cycle or a density clique
    holds more following conflicts than its budget. A sub-problem applied to the
    incumbent it was built on excludes both; applied to a later one (several workers) it
    may not: its held robots' decisions changed meanwhile."""
    rank = ctx.orientation.topological_rank(found.a_first[0])
    if rank is None:
        return None
    counts = ctx.orientation.recount(current.counts, current.following, found.following[0])
    if (counts > ctx.cliques.budget).any():
        return None
    evaluation = ctx.evaluator.evaluate(found)
    cost = float(evaluation.costs[ctx.objective][0])
    if cost > current.cost or (cost == current.cost and not ties):
        return None
    return _Incumbent.of(ctx, fleet, found, rank, evaluation, counts)


@register("lns")
def lns(ctx: SolveContext) -> SolverOutput:
    """LNS from the instant answer (FCFS or its cheapest blend) within the time limit; for
    the objectives it does not search, that answer."""
    deadline = time.monotonic() + ctx.time_limit_s
    start = plain_start(ctx)
    if ctx.objective not in LNS_OBJECTIVES:
        return SolverOutput(start, detail=f"no LNS for {ctx.objective}")
    found = lns_search(ctx, start, deadline, ctx.seed)
    verdict = "; proven optimal (every robot in a conflict freed)" if found.optimal else ""
    return SolverOutput(
        found.best, optimal=found.optimal, detail=f"{found.steps} LNS steps{verdict}"
    )
