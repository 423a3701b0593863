"""Exact solver: OR-Tools CP-SAT on integer-scaled times.

Model (one delay variable per *event*, see :attr:`Problem.events`):

* literals ``a_first[c]`` (side a passes first) and ``following[c]``; a
  conflict with a fixed direction (``Problem.forced``) has its literal fixed;
* acyclicity made explicit: an integer position per node, increasing along
  every path and from the first to the second node of every conflict. Time
  constraints alone do not exclude node cycles: when pair sections lie inside
  merged nodes a cycle of exclusive conflicts can need no waiting at all;
* density: at most h_K following-type conflicts in every binding clique;
* times: delays never decrease along a path; the side passing second waits
  for the first side's pair exit (exclusive) or pair enter (following);
* objectives other than sync_completion are monotone in the delays, so lower
  bounds suffice. sync_completion is not (delaying an early robot can lower
  it), so for it every delay is *pinned* to its least value by max-equalities.

Times are scaled to integers by the coarsest power of ten at which all of them
are whole (1 ms data is exact up to 1000 s), but never finer than
``TIME_DIGITS`` significant digits of the largest time: finer time grids make
CP-SAT much slower. Where data is finer than that, times are rounded to that
resolution, so the assignment is optimal up to it; its cost is always
re-evaluated exactly in floating point by the shared evaluator.
Search (measured on issue 11's conformance sets and generated warehouses by
``python -m bench.cpsat``, docs/benchmarks.md "CP-SAT configurations"): no LP
relaxation but for sync_completion (``LINEARIZATION_LEVEL``), no probing in
presolve (``PROBING_LEVEL``), one worker unless the policy says otherwise, hinted
by the caller; for avg_completion, where the default search has not proven
optimality by 70 % of the time, CP-SAT's core-based search for the rest
(``CORE_SHARE``).

Determinism (measured the same way): the answer depends only on the problem,
the hint and the seed when a proof ends the search, or when the search is
limited in CP-SAT's deterministic time (``deterministic=True``: the time
limit converted at ``DTIME_PER_S``, one worker, or several interleaved) and
that limit, not the wall-clock limit, ends it. A search the wall-clock limit
cuts may return another assignment on the next run; with several workers
(not interleaved) even a proven optimum may be another of equal cost.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np
from ortools.sat.python import cp_model

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.csr import csr, gather
from service.core.problem import Problem
from service.core.schemas import Objective
from service.solvers.cpsat_arrays import (
    INT64_MAX,
    INT64_MIN,
    add_clauses,
    add_hints,
    add_linear,
    add_max,
    add_sums,
    minimize,
    negated,
    new_vars,
    solution_of,
)
from service.solvers.fcfs import fcfs
from service.solvers.milp import MilpResult, solve_milp
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = [
    "CORE_OBJECTIVES",
    "CORE_SHARE",
    "MILP_STAGE_CPSAT_LEAST_S",
    "MILP_STAGE_MAX_CONFLICTS",
    "MILP_STAGE_OBJECTIVES",
    "MILP_STAGE_SHARE",
    "Delays",
    "ExactModel",
    "ExactResult",
    "Slots",
    "Tuning",
    "add_conflict_order",
    "add_path_order",
    "add_waits",
    "build_model",
    "build_seconds",
    "delay_weights",
    "exact",
    "improve",
    "integer_times",
    "literal_domains",
    "milp_staged",
    "search",
    "solve",
    "time_slots",
    "top_assignments",
]

# Significant digits kept of the largest time when scaling to integers. Measured on
# the conformance set: CP-SAT time grows ~10x per extra digit (a 4-robot
# sync_completion problem: 6 digits 0.02 s, 7: 0.14 s, 8: 2.2 s, 9: 18 s).
TIME_DIGITS = 6
# avg_delay weights 1/C_r are made integral by lcm(C_r) up to this, else rounded at this scale.
MAX_DELAY_WEIGHT_SCALE = 10**6

# Further CP-SAT parameters by their ``SatParameters`` field name, e.g. {"linearization_level": 2}.
Tuning = Mapping[str, bool | int | float]

# CP-SAT's LP relaxation per objective. On the conformance sets (25 problems, 42-262
# conflicts, one worker, FCFS hint) avg_completion at level 0 reached a mean cost ratio of
# 0.9927 / 0.9973 at 1 / 3 s and proved 36 / 64 %, at CP-SAT's default level 1 0.9865 /
# 0.9944 and 28 / 56 %, at level 2 0.9740 / 0.9964 and 24 / 56 % (the LP of the
# half-reified time constraints is weak); avg_delay 0.9757 against 0.9344 at 1 s (ratio to
# the better of the two), max_completion proven in both. sync_completion, whose delays are
# pinned by max-equalities, needs the LP: 0.8636 at level 0 against 0.9984 at level 1.
LINEARIZATION_LEVEL: dict[str, int] = {
    "avg_completion": 0,
    "max_completion": 0,
    "sync_completion": 1,
    "avg_delay": 0,
}
# CP-SAT's probing in presolve (its default is 2). Probing cost ~1 s of presolve on a
# 100-robot warehouse (3,898 conflicts) before the search from the hint began; without
# it the search found the same first improvement 2.2 s sooner. Hinted by the first stage
# (bench.cpsat, stage_lin0 vs stage_lin0_probe0): 12 generated warehouses of 50-100
# robots, mean cost ratio 0.9415 -> 0.9515 at 3 s and 0.9714 -> 0.9967 at 5 s (level 1:
# 0.9429 / 0.9773); the 25 conformance problems unchanged at 1, 3 and 5 s, the same
# share proven at each; 100-robot worlds 0.7435 -> 1.0000 (wh_two_way) at 5 s.
PROBING_LEVEL = 0
# Deterministic time per second of the time limit in deterministic mode. CP-SAT did
# 0.17 units per wall second of a one-worker search at linearization level 1, 0.22-0.28 at
# level 0, on the benchmark machine (2-vCPU AMD EPYC; bench.cpsat, "dtime/s"): this uses
# a third to a half of the time limit there, and a machine or a load up to about three
# times slower still ends the search on this limit rather than the wall-clock one.
DTIME_PER_S = 0.09
# Objectives whose search ends with CP-SAT's core-based search (``optimize_with_core``:
# lower bounds from unsatisfiable cores over the objective's terms) for the last
# CORE_SHARE of its time, where the default search has not proven optimality by then. On
# the largest components of the conformance set wh_100 (75-87 robots, 189-246 conflicts,
# one worker) the default search proved none in 10 s (nor with linearization 0 or 2, without
# LNS or with the objective's own lower-bound search), the core-based one each in 0.15-0.41
# s; it proves nothing the default search does not prove faster on the other sets and the
# generated worlds of 25-50 robots, and without the default search's solutions it often
# finds none (so it comes second, hinted). avg_delay (weights 1/C_r) and the other
# objectives: no proof in 3 s either way. It runs on one worker: asked of two, CP-SAT's
# portfolio proved none of wh_100 in 3 s. The datagen's top-L labels search the same way
# (top-3 at 5 s a solve, the sets wh_50, wh_100 and six 25-robot worlds: 30 -> 33 labels
# proven). Measured (session 48): docs/benchmarks.md ("Core-based search").
CORE_OBJECTIVES: frozenset[str] = frozenset({"avg_completion"})
CORE_SHARE = 0.3
# Objectives whose CP-SAT stage in ``auto`` (:func:`improve`) hands the last
# MILP_STAGE_SHARE of its time to the MILP backend (:mod:`service.solvers.milp`: HiGHS,
# presolve off) where CP-SAT has not proven optimality by then. Posed for avg_delay, the
# conformance sets' 25 problems wh_25, wh_50, wh_100 and geo_dense_25 (42-262 conflicts)
# are proven by the MILP within 5 s, all of them (0.06-3.54 s, whole problems, no hint),
# by CP-SAT in 48 % (one worker, FCFS hint), and by ``auto`` at 5 s in 15 of 25 (its
# answers already at the optimum: proofs were what it lacked). Measured (session 49):
# docs/benchmarks.md ("A MILP stage for avg_delay").
# ``auto`` (``python -m bench.ab --objective avg_delay``, the sets and generated 25-50-robot
# worlds, 5 s) proved 19 -> 27 of 32 runs with a share of 0.95, 12 -> 17 of 28 with 0.7;
# without a size cap the MILP took CP-SAT's time where it proves nothing: floor_sparse 50
# (515-540 conflicts) 1.02x dearer at 0.7, 1.03x more at 0.95. Up to
# MILP_STAGE_MAX_CONFLICTS (the sets' largest problem has 262 conflicts) 0.95 against 0.7
# proved 27 / 25 of 36 runs, costs equal; at 1 s 0.95 against none 29 / 27 of 72, even (one
# run cheaper, one dearer). Lost either way: floor_dense/25/6 (172 conflicts), which
# CP-SAT alone proves or improves in its whole stage and the MILP does not (1.002x dearer).
MILP_STAGE_OBJECTIVES: frozenset[str] = frozenset({"avg_delay"})
MILP_STAGE_SHARE = 0.95
MILP_STAGE_MAX_CONFLICTS = 300
# ... but CP-SAT keeps at least this many seconds of the stage (all of a shorter one): at
# 0.2-s budgets (the stage ~0.1 s) the MILP proved nothing and CP-SAT's improvements were
# lost (4 runs of 21 dearer, none cheaper, with 5 % for CP-SAT).
MILP_STAGE_CPSAT_LEAST_S = 0.2
# A MILP proof holds where its objective value and the evaluator's cost of its answer agree
# to this relative tolerance (the conformance sets hold optima to 1e-6).
MILP_COST_TOL = 1e-6


@dataclass(eq=False)
class ExactModel:
    """A built CP-SAT model with the proto indices of its decision literals."""

    model: cp_model.CpModel
    a_first: np.ndarray  # (M,) int64
    following: np.ndarray  # (M,) int64
    scale: float
    linearization: int  # the LP relaxation level its objective searches best with

    def tuning(self) -> dict[str, int]:
        """The CP-SAT parameters this model searches best with (measured, see the module)."""
        return {"linearization_level": self.linearization, "cp_model_probing_level": PROBING_LEVEL}

    def add_hint(self, assignments: Assignments) -> None:
        """Hint the first assignment of the batch (replacing earlier hints)."""
        self.model.clear_hints()
        add_hints(self.model, self.a_first, assignments.a_first[0])
        add_hints(self.model, self.following, assignments.following[0])

    def exclude(self, assignments: Assignments) -> None:
        """No-good: forbid exactly the first assignment of the batch."""
        clause = np.concatenate(
            [
                np.where(values, negated(lits), lits)
                for lits, values in (
                    (self.a_first, assignments.a_first[0]),
                    (self.following, assignments.following[0]),
                )
            ]
        )
        add_clauses(self.model, np.array([0, clause.size]), clause)


@dataclass(frozen=True)
class Delays:
    """Each event's delay in a model: a variable, or a known integer (a robot whose times a
    neighbourhood search holds, and the zero-delay slot E). Shapes (E+1,)."""

    var: np.ndarray  # int64 proto index, -1 where the delay is known
    known: np.ndarray  # int64 the delay where var is -1 (elsewhere unread)
    # int64 the most a known delay may become where a variable one passes first (a held
    # robot delayed up to its latest, see Evaluator.latest_delays); None: the known one.
    latest: np.ndarray | None = None


# The least search time CP-SAT gets when building its model used up the time limit.
MIN_SEARCH_S = 0.001
# Building the model, measured (session 20, constraints written from arrays, see
# cpsat_arrays; 3 builds each, the slowest kept): 29-74 us per conflict for the objectives
# monotone in the delays, 84-174 us for sync_completion (pinned delays) on generated worlds of
# 515-21,835 conflicts (before: 70-113 us and 158-240 us); plus its density constraints:
# 0.25-0.57 s for 16,384-46,656 binding cliques holding 327,680-708,588 conflicts (complete
# multipartite graphs, measured before), ~8 us per clique and ~0.5 us per conflict in it.
BUILD_S_PER_CONFLICT: dict[str, float] = {
    "avg_completion": 8e-5,
    "max_completion": 8e-5,
    "sync_completion": 1.8e-4,
    "avg_delay": 8e-5,
}
BUILD_S_PER_CLIQUE = 8e-6
BUILD_S_PER_INCIDENCE = 5e-7


@dataclass(frozen=True)
class ExactResult:
    """A CP-SAT answer: one assignment, whether its optimality was proven, the work
    done in CP-SAT's deterministic time units (machine-independent "seconds"), and the
    relative gap (objective - best bound) / objective that CP-SAT left (0 when proven;
    every objective is a positive multiple of its cost, so this is the cost's gap up to
    the integer time scaling)."""

    assignment: Assignments
    optimal: bool
    deterministic_time: float
    gap: float = 0.0
    value: float = math.inf  # the objective's value in the model's units (integer-scaled)
    bound: float = -math.inf  # CP-SAT's best bound on it


def time_scale(problem: Problem) -> float:
    """Integer scale of times: the coarsest power of ten at which every time is whole,
    but never finer than ``TIME_DIGITS`` significant digits of the largest time.
    """
    times = problem.tp_time
    top = max(float(times.max()), 1e-9)
    cap = 10.0 ** math.floor(TIME_DIGITS - math.log10(top))
    scale = 10.0**-3
    while scale < cap:
        scaled = times * scale
        if np.all(np.abs(scaled - np.rint(scaled)) <= 1e-9 * np.maximum(1.0, scaled)):
            return scale
        scale *= 10.0
    return cap


def integer_times(problem: Problem) -> tuple[float, np.ndarray, int]:
    """-> (scale, (P,) int64 scaled times, horizon): the time scale, every time point's
    time on it, and a bound on any delay (all robots one after another)."""
    scale = time_scale(problem)
    ti = np.rint(problem.tp_time * scale).astype(np.int64)  # (P,)
    first_tp, last_tp = problem.tp_start[:-1], problem.last_tp
    return scale, ti, int(ti[first_tp].max() + (ti[last_tp] - ti[first_tp]).sum())


def build_seconds(problem: Problem, cliques: Cliques, objective: Objective) -> float:
    """About how long :func:`build_model` takes on this machine (measured rates above)."""
    binding = cliques.binding()
    return (
        BUILD_S_PER_CONFLICT[objective] * problem.n_conflicts
        + BUILD_S_PER_CLIQUE * int(binding.sum())
        + BUILD_S_PER_INCIDENCE * int(cliques.size[binding].sum())
    )


def build_model(problem: Problem, cliques: Cliques, objective: Objective) -> ExactModel:
    """The CP-SAT model of ``problem`` for ``objective`` (see module doc)."""
    # Data.
    scale, ti, horizon = integer_times(problem)
    n_events, m = problem.events.size, problem.n_conflicts
    model = cp_model.CpModel()

    # Variables: the literals (fixed where a direction or a type is), the delays.
    a_lo, a_hi, f_lo, f_hi = literal_domains(problem, cliques.forbidden())
    a_first, following = new_vars(model, m, a_lo, a_hi), new_vars(model, m, f_lo, f_hi)
    delays = Delays(
        np.append(new_vars(model, n_events, 0, horizon), -1),  # the zero-delay slot E
        np.zeros(n_events + 1, dtype=np.int64),
    )

    # Constraints.
    _add_acyclicity(model, problem, a_first)
    _add_density(model, cliques, following)
    add_path_order(model, delays.var, np.flatnonzero(problem.event_next >= 0))
    slots = time_slots(problem, ti, np.flatnonzero(~problem.realized))
    add_waits(model, slots, a_first, following, delays)
    if objective == "sync_completion":
        _pin_delays(model, problem, delays, slots, (a_first, following), horizon)

    # Objective.
    _set_objective(model, problem, objective, ti, delays, horizon + int(ti.max()))
    return ExactModel(model, a_first, following, scale, LINEARIZATION_LEVEL[objective])


def literal_domains(
    problem: Problem, forbidden: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(M,) domains (lo, hi) of the direction literals, then of the type literals: a fixed
    direction fixes a_first (1 where ``forced`` is +1), a fixed type (a realized conflict of
    a re-schedule) fixes following, and else a conflict of a zero-budget clique
    (``forbidden`` (M,)) is exclusive."""
    a_lo, a_hi = (problem.forced > 0).astype(np.int64), (problem.forced >= 0).astype(np.int64)
    fixed = problem.fixed_type.astype(np.int64)
    f_lo = np.where(fixed >= 0, fixed, 0)
    f_hi = np.where(fixed >= 0, fixed, np.where(forbidden, 0, 1))
    return a_lo, a_hi, f_lo, f_hi


def _add_acyclicity(model: cp_model.CpModel, problem: Problem, a_first: np.ndarray) -> None:
    """Integer node positions, increasing along paths and along every conflict arc."""
    pos = new_vars(model, problem.n_nodes, 0, problem.n_nodes - 1)  # (V,)
    along = np.flatnonzero(problem.node_robot[1:] == problem.node_robot[:-1])
    add_linear(model, [pos[along + 1], pos[along]], [1, -1], 1, INT64_MAX)
    add_conflict_order(model, pos[problem.conf_a], pos[problem.conf_b], a_first)


def add_conflict_order(
    model: cp_model.CpModel, pos_a: np.ndarray, pos_b: np.ndarray, a_first: np.ndarray
) -> None:
    """Per conflict (K,): position of side b after side a's where a passes first (literal
    ``a_first``), a's after b's where not. Shapes: position variables pos_a, pos_b (K,)."""
    add_linear(model, [pos_b, pos_a], [1, -1], 1, INT64_MAX, [a_first])
    add_linear(model, [pos_a, pos_b], [1, -1], 1, INT64_MAX, [negated(a_first)])


def add_path_order(model: cp_model.CpModel, delay: np.ndarray, events: np.ndarray) -> None:
    """Delays never decrease along a path: ``delay[e + 1] >= delay[e]`` for ``events`` (N,)
    whose next event is the same robot's. Shapes: delay (E+1,) variables."""
    add_linear(model, [delay[events + 1], delay[events]], [1, -1], 0, INT64_MAX)


def _add_density(model: cp_model.CpModel, cliques: Cliques, following: np.ndarray) -> None:
    """At most h_K following-type conflicts in each clique whose positive budget can bind
    (a zero-budget clique's are exclusive by their domains, see :func:`literal_domains`)."""
    binding = np.flatnonzero(cliques.binding())  # (B,)
    conflicts, _ = gather(cliques.start, cliques.edge, binding)
    start = np.concatenate([[0], np.cumsum(cliques.size[binding])])  # (B+1,)
    add_sums(model, start, following[conflicts], INT64_MIN, cliques.budget[binding])


@dataclass(frozen=True)
class Slots:
    """The time constraints of some conflicts, one row each: ``delay[target] >=
    delay[source] + offset`` when the conflict's direction literal equals ``a_first``
    and, where ``exclusive``, its type is exclusive. Shapes (S,)."""

    conflict: np.ndarray  # int64
    a_first: np.ndarray  # bool
    exclusive: np.ndarray  # bool
    target: np.ndarray  # int64 event
    source: np.ndarray  # int64 event (or E)
    offset: np.ndarray  # int64

    def literals(self, a_first: np.ndarray, following: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(S,) each row's direction literal and (S,) its exclusive-type literal (used
        where ``exclusive``), from the (M,) literal indices of the conflicts."""
        lits = a_first[self.conflict]
        return np.where(self.a_first, lits, negated(lits)), negated(following[self.conflict])

    def enforcing(
        self, a_first: np.ndarray, following: np.ndarray
    ) -> list[tuple[np.ndarray, list[np.ndarray]]]:
        """The rows in two groups by what enforces them: (rows (S,) bool, literal columns
        (S,) each), the direction literal alone, then with the exclusive-type literal."""
        direction, exclusive = self.literals(a_first, following)
        return [(~self.exclusive, [direction]), (self.exclusive, [direction, exclusive])]

    def active(self, a_first: np.ndarray, following: np.ndarray) -> np.ndarray:
        """(S,) bool: the rows whose literals hold in an assignment (``a_first``,
        ``following`` (M,) bool)."""
        return (self.a_first == a_first[self.conflict]) & ~(
            self.exclusive & following[self.conflict]
        )

    def typed(self, f_lo: np.ndarray, f_hi: np.ndarray) -> Slots:
        """The rows that can bind given each conflict's type domain (``f_lo``, ``f_hi``
        (M,)): a conflict never following-type keeps only its exclusive-level rows, enforced
        by its direction alone (each implies its following-level twin: both wait at the same
        entry, and a side's delay plus time at its exit is at least that at its entry); one
        always following-type keeps only its following-level rows. On 250-robot two-way
        warehouses half the conflicts are never following-type: 27 % fewer wait rows (12 %
        fewer rows) to write and parse in each large-neighbourhood step. The whole model
        keeps every row: CP-SAT's proofs on the conformance sets (one worker, 10 s) came
        faster on wh_25 (4.2 -> 2.5 s in all), slower on wh_50 (one of four unproven) and
        geo_dense_25 (16.8 -> 21.4 s)."""
        never, always = f_hi[self.conflict] == 0, f_lo[self.conflict] == 1  # (S,) each
        keep = np.where(self.exclusive, ~always, ~never)
        return Slots(
            self.conflict[keep],
            self.a_first[keep],
            (self.exclusive & ~never)[keep],
            self.target[keep],
            self.source[keep],
            self.offset[keep],
        )


def time_slots(problem: Problem, ti: np.ndarray, conflicts: np.ndarray) -> Slots:
    """The time constraints of ``conflicts`` (K,) (never realized ones: they only relate
    passed points), four each: for each side passing second, a following-level wait (when
    the other side passes first) and an exclusive-level wait (when it also is
    exclusive-type). Times ``ti`` (P,) on the integer grid."""
    enter, leave = problem.tp_pair_enter[conflicts], problem.tp_pair_exit[conflicts]  # (K, 2)
    # The four slots' columns: a second (after b's entry, then exit), b second (after a's).
    target_tp = enter[:, [0, 0, 1, 1]]  # (K, 4)
    source_tp = np.stack([enter[:, 1], leave[:, 1], enter[:, 0], leave[:, 0]], axis=1)
    k = conflicts.size
    return Slots(
        np.repeat(conflicts, 4),
        np.tile([False, False, True, True], k),
        np.tile([False, True, False, True], k),
        problem.tp_event[target_tp].ravel(),
        problem.tp_event[source_tp].ravel(),
        (ti[source_tp] - ti[target_tp]).ravel(),
    )


def add_waits(
    model: cp_model.CpModel,
    slots: Slots,
    a_first: np.ndarray,
    following: np.ndarray,
    delays: Delays,
) -> None:
    """Each slot as a constraint under its literals (``a_first``, ``following`` (M,) literal
    indices): between two delay variables an enforced inequality; with one side known a
    bound on the other (dropped where it waits for nothing: delays are never negative);
    between two known delays nothing where it holds, else a clause forbidding its
    literals."""
    target_var, source_var = delays.var[slots.target], delays.var[slots.source]
    target_known, source_known = delays.known[slots.target], delays.known[slots.source]
    after = source_known + slots.offset  # (S,) least target delay behind a known source
    target_latest = target_known if delays.latest is None else delays.latest[slots.target]
    before = target_latest - slots.offset  # (S,) most source delay ahead of a known target
    for rows, lits in slots.enforcing(a_first, following):
        both = rows & (target_var >= 0) & (source_var >= 0)
        add_linear(
            model, [target_var[both], source_var[both]], [1, -1], slots.offset[both],
            INT64_MAX, [lit[both] for lit in lits],
        )  # fmt: skip
        late = rows & (target_var >= 0) & (source_var < 0) & (after > 0)
        add_linear(
            model, [target_var[late]], [1], after[late], INT64_MAX, [lit[late] for lit in lits]
        )
        early = rows & (target_var < 0) & (source_var >= 0)
        add_linear(
            model, [source_var[early]], [1], INT64_MIN, before[early], [lit[early] for lit in lits]
        )
    direction, exclusive = slots.literals(a_first, following)  # (S,) each
    never = np.flatnonzero((target_var < 0) & (source_var < 0) & (target_known < after))
    width = 1 + slots.exclusive[never]  # (N,) literals per clause
    clause = np.stack([negated(direction[never]), negated(exclusive[never])], axis=1)
    add_clauses(
        model,
        np.concatenate([[0], np.cumsum(width)]),
        clause[np.arange(2) < width[:, None]],
    )


def _pin_delays(
    model: cp_model.CpModel,
    problem: Problem,
    delays: Delays,
    slots: Slots,
    literals: tuple[np.ndarray, np.ndarray],
    horizon: int,
) -> None:
    """Make every delay (all variables but E's) equal its least value: max(0, previous
    event, active waits)."""
    wait = new_vars(model, slots.target.size, -horizon, horizon)  # (S,)
    source_var = delays.var[slots.source]
    value = delays.known[slots.source] + slots.offset  # (S,) where the source is known
    for rows, lits in slots.enforcing(*literals):
        var = rows & (source_var >= 0)
        add_linear(
            model, [wait[var], source_var[var]], [1, -1], slots.offset[var], slots.offset[var],
            [lit[var] for lit in lits],
        )  # fmt: skip
        known = rows & (source_var < 0)
        add_linear(
            model, [wait[known]], [1], value[known], value[known], [lit[known] for lit in lits]
        )
    # Inactive: the wait counts as zero (delays are never negative).
    direction, exclusive = slots.literals(*literals)  # (S,) each
    add_linear(model, [wait], [1], 0, 0, [negated(direction)])
    add_linear(model, [wait[slots.exclusive]], [1], 0, 0, [negated(exclusive[slots.exclusive])])
    n_events = problem.events.size
    follows = np.flatnonzero(problem.event_next >= 0)  # (F,) events with a next one
    start, terms = csr(
        np.concatenate([problem.event_next[follows], slots.target]),
        np.concatenate([delays.var[follows], wait]),
        n_events,
    )
    add_max(model, delays.var[:n_events], start, terms)


def _set_objective(
    model: cp_model.CpModel,
    problem: Problem,
    objective: Objective,
    ti: np.ndarray,
    delays: Delays,
    bound: int,
) -> None:
    """Minimize the integer-scaled objective (constant terms dropped where harmless)."""
    n = problem.n_robots
    last_event = problem.tp_event[problem.last_tp]  # (R,)
    var = delays.var[last_event]  # (R,) each robot's completion: ti + known, or + a variable
    base = ti[problem.last_tp] + np.where(var < 0, delays.known[last_event], 0)
    if objective == "avg_completion":
        minimize(model, var[var >= 0], 1, int(base.sum()))
    elif objective == "avg_delay":  # mean over robots of the mean delay over its time points
        weights = delay_weights(problem)
        used = (weights > 0) & (delays.var[:-1] >= 0)
        minimize(model, delays.var[:-1][used], weights[used])
    else:
        completion = [
            int(b) + (model.get_int_var_from_proto_index(v) if v >= 0 else 0)
            for v, b in zip(var.tolist(), base.tolist(), strict=True)
        ]  # (R,) expressions
        if objective == "max_completion":
            top = model.new_int_var(0, bound, "max_completion")
            model.add_max_equality(top, completion)
            model.minimize(top)
        else:  # sync_completion: n^2 * sync = n * sum(c) + sum_i |n c_i - sum(c)|
            total = sum(completion)
            dev = [model.new_int_var(0, 2 * n * n * bound, f"dev_{i}") for i in range(n)]
            for i in range(n):
                model.add_abs_equality(dev[i], n * completion[i] - total)
            model.minimize(n * total + sum(dev))


def delay_weights(problem: Problem) -> np.ndarray:
    """(E,) integer weight of each event's delay in avg_delay (proportional to the true weights)."""
    counts = np.diff(problem.tp_start)  # (R,) time points per robot
    scale = math.lcm(*np.unique(counts).tolist())
    exact = scale <= MAX_DELAY_WEIGHT_SCALE
    per_tp = scale // counts if exact else np.rint(MAX_DELAY_WEIGHT_SCALE / counts)
    weights = np.zeros(problem.events.size + 1, dtype=np.int64)
    np.add.at(weights, problem.tp_event, per_tp[problem.tp_robot].astype(np.int64))
    return weights[:-1]


def _params(
    time_limit_s: float, seed: int, workers: int, tuning: Tuning | None = None
) -> cp_model.CpSolver:
    """A solver with the request's time limit, seed and worker count, then ``tuning``."""
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = float(time_limit_s)
    solver.parameters.random_seed = int(seed)
    solver.parameters.num_workers = int(workers)
    for name, value in (tuning or {}).items():
        setattr(solver.parameters, name, value)
    return solver


def _read(
    solver: cp_model.CpSolver | cp_model.CpSolverSolutionCallback, em: ExactModel
) -> Assignments:
    """The assignment of the solver's current (or the callback's new) solution."""
    values = solution_of(solver)  # (X,)
    return Assignments.single(values[em.a_first] > 0, values[em.following] > 0)


def _result(solver: cp_model.CpSolver, em: ExactModel, status: int) -> ExactResult:
    """The answer of a solve that found a solution (status OPTIMAL or FEASIBLE)."""
    optimal = status == cp_model.OPTIMAL
    value, bound = solver.objective_value, solver.best_objective_bound
    gap = 0.0 if optimal else _gap(value, bound)
    return ExactResult(_read(solver, em), optimal, solver.deterministic_time, gap, value, bound)


def _gap(value: float, bound: float) -> float:
    """The relative gap (value - bound) / value an unproven search leaves (0 where the
    value is not positive)."""
    return 0.0 if value <= 0 else max(0.0, (value - bound) / value)


class _Incumbents(cp_model.CpSolverSolutionCallback):
    """Reports every improving solution as ``on_solution(wall_time_s, assignment)``."""

    def __init__(self, em: ExactModel, on_solution: Callable[[float, Assignments], None]) -> None:
        super().__init__()
        self._em = em
        self._on_solution = on_solution

    def on_solution_callback(self) -> None:
        self._on_solution(self.wall_time, _read(self, self._em))


def solve(
    problem: Problem,
    cliques: Cliques,
    objective: Objective,
    time_limit_s: float,
    seed: int = 0,
    workers: int = 1,
    hint: Assignments | None = None,
    on_solution: Callable[[float, Assignments], None] | None = None,
    tuning: Tuning | None = None,
    deterministic: bool = False,
) -> ExactResult | None:
    """Best assignment CP-SAT finds within the time limit (None if it found none).

    The time limit counts from the call: building the model (:func:`build_seconds`)
    is part of it, and CP-SAT searches for what is left (at least MIN_SEARCH_S).
    ``on_solution`` (optional) sees every improving solution with its wall time,
    e.g. for measuring how fast CP-SAT reaches a given cost; ``tuning`` sets further
    CP-SAT parameters (see :func:`search`). For CORE_OBJECTIVES the default search
    gets 1 - CORE_SHARE of the search time, and where it has not proven optimality,
    CP-SAT's core-based search the rest on one worker, hinted with its answer (see
    CORE_SHARE): the better answer, and a proof if either reached one.

    Args:
        deterministic: also limit the search in deterministic time, ``DTIME_PER_S``
            per second of ``time_limit_s``, interleaving several workers' search: the
            answer is then the same on every run with the same seed (25 of 25 problems,
            one or two workers) unless the wall-clock limit ends the search first.
    """
    deadline = time.monotonic() + time_limit_s
    em = build_model(problem, cliques, objective)
    if hint is not None:
        em.add_hint(hint)
    dtime = DTIME_PER_S * time_limit_s if deterministic else None
    return _search_then_core(em, objective, deadline, seed, workers, on_solution, tuning, dtime)


def _search_then_core(
    em: ExactModel,
    objective: Objective,
    deadline: float,
    seed: int,
    workers: int,
    on_solution: Callable[[float, Assignments], None] | None = None,
    tuning: Tuning | None = None,
    dtime: float | None = None,
) -> ExactResult | None:
    """``em`` searched until ``deadline`` (monotonic): for CORE_OBJECTIVES the default search
    for 1 - CORE_SHARE of the time and, where it has not proven optimality, the core-based
    search for the rest, hinted with its answer, on one worker (see CORE_SHARE) -> the
    better of the two (:func:`_better`); for other objectives the default search alone.
    ``dtime``: a deterministic-time budget, split the same way (None: none)."""
    began = time.monotonic()
    left = max(MIN_SEARCH_S, deadline - began)
    core_s = CORE_SHARE * left if objective in CORE_OBJECTIVES else 0.0
    phase = {**(tuning or {})}
    if dtime is not None:  # each search's share, interleaving several workers
        phase["interleave_search"] = workers > 1
        phase["max_deterministic_time"] = dtime * (1 - core_s / left)
    found = search(em, left - core_s, seed, workers, on_solution, phase)
    if core_s <= 0 or (found is not None and found.optimal):
        return found
    if found is not None:
        em.add_hint(found.assignment)
    if dtime is not None:
        phase["max_deterministic_time"] = dtime * core_s / left
    shifted = _shifted(on_solution, time.monotonic() - began)
    cored = search(  # one worker: with several, CP-SAT's portfolio left out the core search
        em, max(MIN_SEARCH_S, deadline - time.monotonic()), seed, 1, shifted,
        {**phase, "optimize_with_core": True, "interleave_search": False},
    )  # fmt: skip
    return _better(found, cored)


def _shifted(
    on_solution: Callable[[float, Assignments], None] | None, seconds: float
) -> Callable[[float, Assignments], None] | None:
    """``on_solution`` for a search begun ``seconds`` after the first search of a solve:
    its wall times shifted by them, so that they count from where the first's did."""
    if on_solution is None:
        return None
    return lambda wall_time, assignment: on_solution(wall_time + seconds, assignment)


def _better(first: ExactResult | None, second: ExactResult | None) -> ExactResult | None:
    """The better of two searches of one model: the second where it is proven optimal or
    cheaper, else the first; with the higher of their bounds (and the gap it leaves) and
    the work of both."""
    if first is None or second is None:
        return first if second is None else second
    found = second if second.optimal or second.value < first.value else first
    work = first.deterministic_time + second.deterministic_time
    if found.optimal:
        return replace(found, deterministic_time=work)
    bound = max(first.bound, second.bound)
    return replace(found, deterministic_time=work, bound=bound, gap=_gap(found.value, bound))


def search(
    em: ExactModel,
    time_limit_s: float,
    seed: int = 0,
    workers: int = 1,
    on_solution: Callable[[float, Assignments], None] | None = None,
    tuning: Tuning | None = None,
) -> ExactResult | None:
    """Search a built model for ``time_limit_s`` seconds (None if CP-SAT found nothing).

    ``tuning`` sets further CP-SAT parameters by their field name in
    ``SatParameters``, after the time limit, seed and workers (so it may override
    them), e.g. ``{"linearization_level": 2}``: what ``bench.cpsat`` compares.
    """
    solver = _params(time_limit_s, seed, workers, {**em.tuning(), **(tuning or {})})
    callback = None if on_solution is None else _Incumbents(em, on_solution)
    status = solver.solve(em.model, callback)
    if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        return None
    return _result(solver, em, status)


def top_assignments(
    problem: Problem,
    cliques: Cliques,
    objective: Objective,
    count: int,
    time_limit_s: float,
    seed: int = 0,
    workers: int = 1,
    hint: Assignments | None = None,
) -> list[ExactResult]:
    """The ``count`` best distinct assignments, best first (fewer if fewer exist).

    CP-SAT has no top-k with an objective, so each next one is found by
    re-solving with a no-good clause over the direction and type literals of
    every earlier one, hinted with the previous solution (the first solve with
    ``hint``, if given), each searched as :func:`solve` searches (the core-based
    search last for CORE_OBJECTIVES). ``time_limit_s`` is per solve; a solve that
    does not prove optimality is kept with ``optimal=False`` and its gap, and ends
    the enumeration.
    """
    em = build_model(problem, cliques, objective)
    if hint is not None:
        em.add_hint(hint)
    results: list[ExactResult] = []
    while len(results) < count:
        found = _search_then_core(em, objective, time.monotonic() + time_limit_s, seed, workers)
        if found is None:
            break
        results.append(found)
        if not found.optimal:
            break
        em.exclude(results[-1].assignment)
        em.add_hint(results[-1].assignment)
    return results


def improve(
    ctx: SolveContext, start: SolverOutput, time_limit_s: float
) -> tuple[SolverOutput, str]:
    """``start`` handed to CP-SAT as a hint for ``time_limit_s`` -> the cheapest answer by the
    one evaluator (the hint may be lost to CP-SAT's integer time scaling), optimal only
    where proven, and a verdict for the answer's detail. For MILP_STAGE_OBJECTIVES up to
    MILP_STAGE_MAX_CONFLICTS conflicts, CP-SAT gets 1 - MILP_STAGE_SHARE of the time (at
    least MILP_STAGE_CPSAT_LEAST_S) and, where it has not proven optimality, the MILP
    backend the rest, its delays bounded by the cheapest answer so far (see
    MILP_STAGE_SHARE, :func:`~service.solvers.milp.solve_milp` and
    :func:`_milp_proof_holds`)."""
    deadline = time.monotonic() + time_limit_s
    staged = milp_staged(ctx.problem, ctx.objective)
    cpsat_s = max((1 - MILP_STAGE_SHARE) * time_limit_s, MILP_STAGE_CPSAT_LEAST_S)
    milp_s = max(0.0, time_limit_s - cpsat_s) if staged else 0.0
    result = solve(
        ctx.problem,
        ctx.cliques,
        ctx.objective,
        time_limit_s - milp_s,
        seed=ctx.seed,
        workers=ctx.workers,
        hint=start.assignment,
        on_solution=ctx.on_solution,
    )
    cpsat_proven = result is not None and result.optimal
    found = [] if result is None else [(result.assignment, "CP-SAT")]
    milp = None
    if milp_s > 0 and not cpsat_proven:
        reached = min(ctx.cost(answer) for answer in (start.assignment, *(a for a, _ in found)))
        milp = solve_milp(
            ctx.problem, ctx.cliques, ctx.evaluator, ctx.objective,
            deadline - time.monotonic(), cost_bound=reached,
        )  # fmt: skip
        found += [] if milp is None else [(milp.assignment, MILP_NAME)]
    if not found:
        return replace(start, optimal=False), "CP-SAT found nothing"
    every = [start.assignment, *(answer for answer, _ in found)]
    costs = ctx.evaluator.evaluate(
        Assignments(
            np.concatenate([a.a_first for a in every]),
            np.concatenate([a.following for a in every]),
        )
    ).costs[ctx.objective]  # (1 + F,) the hint, then each answer found
    hinted, mine = float(costs[0]), costs[1:]
    k, proven = int(np.argmin(mine)), cpsat_proven  # ties: CP-SAT's, found first
    if milp is not None and _milp_proof_holds(milp, float(mine[-1]), float(costs.min())):
        k, proven = len(found) - 1, True
    answer, by = found[k]
    cost = float(mine[k])
    if cost > hinted:
        # CP-SAT proves its integer-scaled times' optimum, which may lose the hint's; the
        # MILP's proof (exact times) holds for a hint no dearer than its answer (within
        # MILP_COST_TOL, else the proof was not taken): equal costs to the last bits.
        kept = proven and by == MILP_NAME
        verdict = f"proven optimal by {by}" if kept else f"{by} did not improve"
        return replace(start, optimal=kept), verdict
    if proven:
        verdict = f"proven optimal by {by}"
    else:
        verdict = f"improved by {by}" if cost < hinted else f"{by} kept it, unproven"
    return replace(start, assignment=answer, optimal=proven), verdict


MILP_NAME = "the MILP backend (HiGHS)"


def milp_staged(problem: Problem, objective: Objective) -> bool:
    """Whether :func:`improve` hands the MILP backend most of its time (see
    MILP_STAGE_SHARE): an objective of MILP_STAGE_OBJECTIVES, up to
    MILP_STAGE_MAX_CONFLICTS conflicts."""
    return objective in MILP_STAGE_OBJECTIVES and problem.n_conflicts <= MILP_STAGE_MAX_CONFLICTS


def _milp_proof_holds(milp: MilpResult, cost: float, least: float) -> bool:
    """Whether the MILP's claim of optimality for its answer, of evaluator ``cost``, holds:
    its objective value is that cost (relative MILP_COST_TOL; HiGHS has returned wrong
    optima on these models with presolve on, and the assignment is what the service
    answers, not HiGHS's continuous delays) and no other answer found costs less than
    it (``least``, else HiGHS erred)."""
    agrees = abs(cost - milp.objective) <= MILP_COST_TOL * max(1.0, abs(cost))
    return milp.optimal and agrees and cost <= least * (1 + MILP_COST_TOL)


@register("exact")
def exact(ctx: SolveContext) -> SolverOutput | None:
    """CP-SAT within the request's time limit, warm-started from FCFS, deterministic if the
    policy says so; no answer (None: the dispatcher falls back to FCFS) when building the
    model alone is expected to outlast the limit, instead of overrunning it (a 1 s request
    on a 250-robot warehouse took 2.2 s, building for 2.1 s)."""
    if build_seconds(ctx.problem, ctx.cliques, ctx.objective) > ctx.time_limit_s:
        return None
    result = solve(
        ctx.problem,
        ctx.cliques,
        ctx.objective,
        ctx.time_limit_s,
        seed=ctx.seed,
        workers=ctx.workers,
        hint=fcfs(ctx).assignment,
        on_solution=ctx.on_solution,
        deterministic=ctx.exact_deterministic,
    )
    if result is None:
        return None
    return SolverOutput(result.assignment, optimal=result.optimal)
