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
by the caller.

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
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from ortools.sat.python import cp_model

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.problem import Problem
from service.core.schemas import Objective
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = [
    "ExactModel",
    "ExactResult",
    "Tuning",
    "add_waits",
    "build_model",
    "build_seconds",
    "delay_weights",
    "exact",
    "improve",
    "integer_times",
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


@dataclass(eq=False)
class ExactModel:
    """A built CP-SAT model with handles to its decision literals."""

    model: cp_model.CpModel
    a_first: list[cp_model.IntVar]  # (M,)
    following: list[cp_model.IntVar]  # (M,)
    scale: float
    linearization: int  # the LP relaxation level its objective searches best with

    def tuning(self) -> dict[str, int]:
        """The CP-SAT parameters this model searches best with (measured, see the module)."""
        return {"linearization_level": self.linearization, "cp_model_probing_level": PROBING_LEVEL}

    def add_hint(self, assignments: Assignments) -> None:
        """Hint the first assignment of the batch (replacing earlier hints)."""
        self.model.clear_hints()
        add_hints(self.model, self.a_first, assignments.a_first[0].tolist())
        add_hints(self.model, self.following, assignments.following[0].tolist())

    def exclude(self, assignments: Assignments) -> None:
        """No-good: forbid exactly the first assignment of the batch."""
        clause = [
            lit.Not() if val else lit
            for lits, vals in (
                (self.a_first, assignments.a_first[0]),
                (self.following, assignments.following[0]),
            )
            for lit, val in zip(lits, vals.tolist(), strict=True)
        ]
        self.model.add_bool_or(clause)


def add_hints(
    model: cp_model.CpModel, variables: Sequence[cp_model.IntVar], values: Sequence
) -> None:
    """Hint ``values`` for ``variables`` (not negated literals) with two calls on the model's
    proto instead of one ``add_hint`` per variable: 0.2 ms instead of 7.6 ms for 2,000."""
    hint = model.proto.solution_hint
    hint.vars.extend([v.index for v in variables])
    hint.values.extend([int(x) for x in values])


# The least search time CP-SAT gets when building its model used up the time limit.
MIN_SEARCH_S = 0.001
# Building the model, measured: 36 ms at 262 conflicts, 2.5 s at 21,835 (~120 us each),
# plus its density constraints: 0.25-0.57 s for 16,384-46,656 binding cliques holding
# 327,680-708,588 conflicts (complete multipartite graphs), ~8 us per clique and
# ~0.5 us per conflict in it.
BUILD_S_PER_CONFLICT = 1.2e-4
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


def build_seconds(problem: Problem, cliques: Cliques) -> float:
    """About how long :func:`build_model` takes on this machine (measured rates above)."""
    binding = cliques.binding()
    return (
        BUILD_S_PER_CONFLICT * problem.n_conflicts
        + BUILD_S_PER_CLIQUE * int(binding.sum())
        + BUILD_S_PER_INCIDENCE * int(cliques.size[binding].sum())
    )


def build_model(problem: Problem, cliques: Cliques, objective: Objective) -> ExactModel:
    """The CP-SAT model of ``problem`` for ``objective`` (see module doc)."""
    # Data.
    scale, ti, horizon = integer_times(problem)
    n_events, tp_event, last_tp = problem.events.size, problem.tp_event, problem.last_tp
    model = cp_model.CpModel()
    m = problem.n_conflicts

    # Variables.
    a_first = [model.new_bool_var(f"a_first_{c}") for c in range(m)]
    following = [model.new_bool_var(f"following_{c}") for c in range(m)]
    delay = [model.new_int_var(0, horizon, f"delay_{e}") for e in range(n_events)]
    delay.append(0)  # the zero-delay slot E

    # Constraints.
    _add_acyclicity(model, problem, a_first)
    _fix_directions(model, problem, a_first, following)
    _add_density(model, cliques, following)
    for e, nxt in enumerate(problem.event_next.tolist()):
        if nxt >= 0:
            model.add(delay[nxt] >= delay[e])
    slots = time_slots(problem, ti, a_first, following, np.flatnonzero(~problem.realized))
    add_waits(model, slots, delay)
    if objective == "sync_completion":
        _pin_delays(model, problem, delay, slots, horizon)

    # Objective.
    completion = [int(ti[t]) + delay[tp_event[t]] for t in last_tp.tolist()]  # (R,) exprs
    _set_objective(model, problem, objective, completion, delay, horizon + int(ti.max()))
    return ExactModel(model, a_first, following, scale, LINEARIZATION_LEVEL[objective])


def _add_acyclicity(model: cp_model.CpModel, problem: Problem, a_first: list) -> None:
    """Integer node positions, increasing along paths and along every conflict arc."""
    n = problem.n_nodes
    pos = [model.new_int_var(0, n - 1, f"pos_{v}") for v in range(n)]
    for v in np.flatnonzero(problem.node_robot[1:] == problem.node_robot[:-1]).tolist():
        model.add(pos[v + 1] >= pos[v] + 1)
    for c, (a, b) in enumerate(zip(problem.conf_a.tolist(), problem.conf_b.tolist(), strict=True)):
        model.add(pos[b] >= pos[a] + 1).only_enforce_if(a_first[c])
        model.add(pos[a] >= pos[b] + 1).only_enforce_if(a_first[c].Not())


def _fix_directions(
    model: cp_model.CpModel, problem: Problem, a_first: list, following: list
) -> None:
    """A fixed direction fixes its conflict's literal (side a first where forced is +1);
    a fixed type (a realized conflict of a re-schedule) fixes its type literal."""
    for c in problem.forced_arcs[0].tolist():
        model.add(a_first[c] == int(problem.forced[c] > 0))
    for c in np.flatnonzero(problem.fixed_type >= 0).tolist():
        model.add(following[c] == int(problem.fixed_type[c]))


def _add_density(model: cp_model.CpModel, cliques: Cliques, following: list) -> None:
    """Conflicts of a zero-budget clique exclusive (once each), and at most h_K
    following-type conflicts in each clique whose positive budget can bind."""
    for c in np.flatnonzero(cliques.forbidden()).tolist():
        model.add(following[c] == 0)
    edge, start, budget = cliques.edge.tolist(), cliques.start.tolist(), cliques.budget.tolist()
    for q in np.flatnonzero(cliques.binding()).tolist():
        terms = [following[c] for c in edge[start[q] : start[q + 1]]]
        model.add(cp_model.LinearExpr.sum(terms) <= budget[q])


def time_slots(
    problem: Problem, ti: np.ndarray, a_first: Sequence, following: Sequence, conflicts: np.ndarray
) -> list[tuple[int, list, int, int]]:
    """(target event, enforcing literals, source event, integer offset) per time constraint
    of the given conflicts (never realized ones: they only relate passed points), whose
    literals ``a_first[c]`` and ``following[c]`` are looked up by conflict index.

    Each conflict gives four: for each side passing second, a following-level
    wait (when the other side passes first) and an exclusive-level wait (when it
    also is exclusive-type).
    """
    enter, leave = problem.tp_pair_enter[conflicts], problem.tp_pair_exit[conflicts]  # (K, 2)
    # The four slots' columns: a second (after b's entry, then exit), b second (after a's).
    target_tp = enter[:, [0, 0, 1, 1]]  # (K, 4)
    source_tp = np.stack([enter[:, 1], leave[:, 1], enter[:, 0], leave[:, 0]], axis=1)
    target, source = problem.tp_event[target_tp].tolist(), problem.tp_event[source_tp].tolist()
    offset = (ti[source_tp] - ti[target_tp]).tolist()
    slots = []
    for k, c in enumerate(conflicts.tolist()):
        a_lit, exclusive = a_first[c], following[c].Not()
        b_lit = a_lit.Not()  # b passes first
        t, s, o = target[k], source[k], offset[k]
        slots += [
            (t[0], [b_lit], s[0], o[0]),
            (t[1], [b_lit, exclusive], s[1], o[1]),
            (t[2], [a_lit], s[2], o[2]),
            (t[3], [a_lit, exclusive], s[3], o[3]),
        ]
    return slots


def add_waits(
    model: cp_model.CpModel, slots: list[tuple[int, list, int, int]], delay: Sequence
) -> None:
    """Each slot as ``delay[target] >= delay[src] + offset`` under its literals.

    A delay is a variable or a known integer (a robot whose times a neighbourhood
    search holds fixed, or the zero-delay slot E); between two known ones the slot
    either always holds (dropped) or never (its literals may not all be true).
    """
    for target, lits, src, off in slots:
        lhs, rhs = delay[target], delay[src]
        if isinstance(lhs, int) and isinstance(rhs, int):
            if lhs < rhs + off:
                model.add_bool_or([lit.Not() for lit in lits])
        elif not (isinstance(rhs, int) and rhs + off <= 0):  # else waits for nothing
            model.add(lhs >= rhs + off).only_enforce_if(lits)


def _pin_delays(
    model: cp_model.CpModel,
    problem: Problem,
    delay: list,
    slots: list[tuple[int, list, int, int]],
    horizon: int,
) -> None:
    """Make every delay equal its least value: max(0, previous event, active waits)."""
    zero = delay[-1]
    terms: list[list] = [[zero] for _ in range(problem.events.size)]
    for e, nxt in enumerate(problem.event_next.tolist()):
        if nxt >= 0:
            terms[nxt].append(delay[e])
    for k, (target, lits, src, off) in enumerate(slots):
        wait = model.new_int_var(-horizon, horizon, f"wait_{k}")
        model.add(wait == delay[src] + off).only_enforce_if(lits)
        for lit in lits:  # inactive: the wait counts as zero (delays are never negative)
            model.add(wait == 0).only_enforce_if(lit.Not())
        terms[target].append(wait)
    for e, parts in enumerate(terms):
        model.add_max_equality(delay[e], parts)


def _set_objective(
    model: cp_model.CpModel,
    problem: Problem,
    objective: Objective,
    completion: list,
    delay: list,
    bound: int,
) -> None:
    """Minimize the integer-scaled objective (constant terms dropped where harmless)."""
    n = problem.n_robots
    if objective == "avg_completion":
        model.minimize(sum(completion))
    elif objective == "max_completion":
        top = model.new_int_var(0, bound, "max_completion")
        model.add_max_equality(top, completion)
        model.minimize(top)
    elif objective == "sync_completion":
        # n^2 * sync = n * sum(c) + sum_i |n c_i - sum(c)|
        total = sum(completion)
        dev = [model.new_int_var(0, 2 * n * n * bound, f"dev_{i}") for i in range(n)]
        for i in range(n):
            model.add_abs_equality(dev[i], n * completion[i] - total)
        model.minimize(n * total + sum(dev))
    else:  # avg_delay: mean over robots of the mean delay over the robot's time points
        model.minimize(sum(int(w) * delay[e] for e, w in enumerate(delay_weights(problem)) if w))


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
    return Assignments.single(
        [solver.boolean_value(x) for x in em.a_first],
        [solver.boolean_value(f) for f in em.following],
    )


def _result(solver: cp_model.CpSolver, em: ExactModel, status: int) -> ExactResult:
    """The answer of a solve that found a solution (status OPTIMAL or FEASIBLE)."""
    optimal = status == cp_model.OPTIMAL
    value, bound = solver.objective_value, solver.best_objective_bound
    gap = 0.0 if optimal or value <= 0 else max(0.0, (value - bound) / value)
    return ExactResult(_read(solver, em), optimal, solver.deterministic_time, gap)


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
    CP-SAT parameters (see :func:`search`).

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
    if deterministic:
        tuning = {
            **(tuning or {}),
            "max_deterministic_time": DTIME_PER_S * time_limit_s,
            "interleave_search": workers > 1,
        }
    left = max(MIN_SEARCH_S, deadline - time.monotonic())
    return search(em, left, seed, workers, on_solution, tuning)


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
    ``hint``, if given). ``time_limit_s`` is per solve; a solve that does not
    prove optimality is kept with ``optimal=False`` and its gap, and ends the
    enumeration.
    """
    em = build_model(problem, cliques, objective)
    if hint is not None:
        em.add_hint(hint)
    results: list[ExactResult] = []
    while len(results) < count:
        solver = _params(time_limit_s, seed, workers, em.tuning())
        status = solver.solve(em.model)
        if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
            break
        results.append(_result(solver, em, status))
        if status != cp_model.OPTIMAL:
            break
        em.exclude(results[-1].assignment)
        em.add_hint(results[-1].assignment)
    return results


def improve(
    ctx: SolveContext, start: SolverOutput, time_limit_s: float
) -> tuple[SolverOutput, str]:
    """``start`` handed to CP-SAT as a hint for ``time_limit_s`` -> the cheaper of the two by
    the one evaluator (the hint may be lost to CP-SAT's integer time scaling), optimal only
    where CP-SAT proved it, and a verdict for the answer's detail."""
    result = solve(
        ctx.problem,
        ctx.cliques,
        ctx.objective,
        time_limit_s,
        seed=ctx.seed,
        workers=ctx.workers,
        hint=start.assignment,
        on_solution=ctx.on_solution,
    )
    if result is None:
        return replace(start, optimal=False), "CP-SAT found nothing"
    costs = ctx.evaluator.evaluate(
        Assignments(
            np.concatenate([result.assignment.a_first, start.assignment.a_first]),
            np.concatenate([result.assignment.following, start.assignment.following]),
        )
    ).costs[ctx.objective]  # (2,) CP-SAT's answer, the hint
    found, hinted = float(costs[0]), float(costs[1])
    if found > hinted:
        return replace(start, optimal=False), "CP-SAT did not improve"
    if result.optimal:
        verdict = "proven optimal by CP-SAT"
    else:
        verdict = "improved by CP-SAT" if found < hinted else "CP-SAT kept it, unproven"
    return replace(start, assignment=result.assignment, optimal=result.optimal), verdict


@register("exact")
def exact(ctx: SolveContext) -> SolverOutput | None:
    """CP-SAT within the request's time limit, warm-started from FCFS, deterministic if the
    policy says so; no answer (None: the dispatcher falls back to FCFS) when building the
    model alone is expected to outlast the limit, instead of overrunning it (a 1 s request
    on a 250-robot warehouse took 2.2 s, building for 2.1 s)."""
    if build_seconds(ctx.problem, ctx.cliques) > ctx.time_limit_s:
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
