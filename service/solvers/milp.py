"""The exact model as a mixed-integer linear program for HiGHS: a backend measured
against CP-SAT (issue 11, item 4; ``python -m bench.milp``, docs/benchmarks.md "MILP
backend"). It proves every conformance problem within 10 s (CP-SAT: 88 %; none of the
100-robot warehouses) but only 36 % of generated worlds (CP-SAT: 73 %), with far worse
answers where it does not prove. For avg_delay it proves the conformance sets' problems
(posed for it) within 5 s where CP-SAT proves half: there it ends ``auto``'s CP-SAT stage
(:data:`service.solvers.exact.MILP_STAGE_OBJECTIVES`, up to 300 conflicts).

The constraints are the evaluator's own (:class:`~service.core.evaluate.ConstraintGraph`:
slot 2c+s makes side s of conflict c wait for the other side's pair exit, or its pair
enter when the conflict is following-type, once the other side passes first), written
with big-M terms on two binaries per conflict, ``a_first`` and ``following``:

* delays: one continuous variable per event in [0, U] (U: the exact model's horizon H,
  the latest start plus every robot's duration, or less given a cost some answer reaches,
  see :func:`_delay_upper`), never decreasing along a path; times stay in seconds, so
  there is no integer time scaling as in CP-SAT;
* a slot's wait holds when its literals are true and is relaxed by M = U(source) + its
  offset otherwise (the following-level wait when the other side passes first, the
  exclusive-level wait when it also is exclusive-type);
* acyclicity: a continuous position per node, increasing along paths and along every
  conflict arc (continuous suffices: a cycle of +1 steps is infeasible either way);
* density, fixed directions and fixed types as in :mod:`service.solvers.exact`;
* objectives avg_completion, max_completion and avg_delay (monotone in the delays, so
  an optimum's delays can be the least ones). sync_completion is not monotone (its delays
  must be pinned by max-equalities) and is refused.

Solved by HiGHS through ``scipy.optimize.milp`` with presolve off (HiGHS's presolve has
returned wrong optima on these models) and a relative gap of MIP_REL_GAP. The answer is
an assignment: the caller costs it with the one evaluator; where HiGHS proves optimality
its objective value equals that cost (the tests and the benchmark check it).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import coo_array

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.evaluate import Evaluator
from service.core.problem import Problem
from service.core.schemas import Objective

__all__ = ["MILP_OBJECTIVES", "MIP_REL_GAP", "MilpResult", "solve_milp"]

MILP_OBJECTIVES: frozenset[Objective] = frozenset({"avg_completion", "max_completion", "avg_delay"})
# HiGHS stops at this relative gap (its default, 1e-4, would call answers 0.01 % above the
# optimum optimal; the conformance sets hold optima to 1e-6).
MIP_REL_GAP = 1e-7


@dataclass(frozen=True)
class MilpResult:
    """HiGHS's best assignment, whether it proved it optimal, its objective value and
    best bound (in the objective's own units), and the seconds spent building and solving."""

    assignment: Assignments
    optimal: bool
    objective: float
    bound: float
    build_s: float
    solve_s: float


class _Rows:
    """Sparse constraint rows lb <= A x <= ub, appended in blocks."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []
        self.cols: list[np.ndarray] = []
        self.vals: list[np.ndarray] = []
        self.lower: list[np.ndarray] = []
        self.upper: list[np.ndarray] = []
        self.n = 0

    def add(self, terms: list[tuple[np.ndarray, np.ndarray]], lower, upper) -> None:  # noqa: ANN001
        """Rows k = 0..K-1 of sum over ``terms`` (column (K,), coefficient (K,)) in
        [lower, upper] (scalars or (K,)); a column of -1 is a constant zero and dropped."""
        size = len(terms[0][0])
        row = np.arange(self.n, self.n + size)
        for col, coef in terms:
            col = np.asarray(col, dtype=np.int64)
            keep = col >= 0
            self.rows.append(row[keep])
            self.cols.append(col[keep])
            self.vals.append(np.broadcast_to(np.asarray(coef, dtype=np.float64), (size,))[keep])
        self.lower.append(np.broadcast_to(np.asarray(lower, dtype=np.float64), (size,)))
        self.upper.append(np.broadcast_to(np.asarray(upper, dtype=np.float64), (size,)))
        self.n += size

    def add_sums(self, group: np.ndarray, cols: np.ndarray, upper: np.ndarray) -> None:
        """Rows k = 0..K-1 of the sum of the columns whose ``group`` (T,) is k, <= upper (K,)."""
        self.rows.append(self.n + group)
        self.cols.append(np.asarray(cols, dtype=np.int64))
        self.vals.append(np.ones(group.size))
        self.lower.append(np.full(upper.size, -np.inf))
        self.upper.append(np.asarray(upper, dtype=np.float64))
        self.n += upper.size

    def constraint(self, n_vars: int) -> LinearConstraint:
        matrix = coo_array(
            (np.concatenate(self.vals), (np.concatenate(self.rows), np.concatenate(self.cols))),
            shape=(self.n, n_vars),
        ).tocsr()
        return LinearConstraint(matrix, np.concatenate(self.lower), np.concatenate(self.upper))


def solve_milp(
    problem: Problem,
    cliques: Cliques,
    evaluator: Evaluator,
    objective: Objective,
    time_limit_s: float,
    cost_bound: float | None = None,
) -> MilpResult | None:
    """Best assignment HiGHS finds within the time limit (None if it found none).

    ``cost_bound``: a cost some answer reaches (an incumbent's, by the evaluator). For the
    sums it bounds every delay (:func:`_delay_upper`), and with it every big-M term: the
    optimum stays within. HiGHS proved the largest components of wh_100/1 and /2 posed for
    avg_delay (246 and 199 conflicts) in 3.1-4.0 and 2.5 s bounded by ``auto``'s answers,
    in 4.4 and 3.4-3.5 s without (session 53).

    Raises:
        ValueError: an objective outside :data:`MILP_OBJECTIVES`.
    """
    if objective not in MILP_OBJECTIVES:
        raise ValueError(f"the MILP models {sorted(MILP_OBJECTIVES)}, not {objective}")
    start = time.perf_counter()
    m = problem.n_conflicts
    cost, constant, integrality, bounds, rows = _model(
        problem, cliques, evaluator, objective, cost_bound
    )
    built = time.perf_counter()
    res = milp(
        cost,
        integrality=integrality,
        bounds=bounds,
        constraints=rows,
        options={
            "presolve": False,
            "time_limit": max(time_limit_s - (built - start), 1e-3),
            "mip_rel_gap": MIP_REL_GAP,
        },
    )
    solved = time.perf_counter()
    if res.x is None:
        return None
    x = res.x
    return MilpResult(
        Assignments.single(x[:m] > 0.5, x[m : 2 * m] > 0.5),
        optimal=res.status == 0,
        objective=float(res.fun) + constant,
        bound=float(getattr(res, "mip_dual_bound", res.fun)) + constant,
        build_s=built - start,
        solve_s=solved - built,
    )


def _model(
    problem: Problem,
    cliques: Cliques,
    evaluator: Evaluator,
    objective: Objective,
    cost_bound: float | None = None,
) -> tuple[np.ndarray, float, np.ndarray, Bounds, LinearConstraint]:
    """Objective vector and its constant term, integrality, bounds and rows over the
    variables [a_first (M), following (M), delay (E), position (V)] and, for
    max_completion only, the maximum completion (1); delays bounded as
    :func:`_delay_upper` by ``cost_bound`` (None: by the horizon alone)."""
    graph = evaluator.graph
    m, n_events, n_nodes = problem.n_conflicts, graph.chain_next.size, problem.n_nodes
    t = problem.tp_time
    first_tp, last_tp = problem.tp_start[:-1], problem.last_tp
    horizon = float(t[first_tp].max() + (t[last_tp] - t[first_tp]).sum())
    finish = t[last_tp]  # (R,) planned completion
    constant = float(finish.mean()) if objective == "avg_completion" else 0.0
    upper_delay = np.full(n_events, horizon)  # (E,)
    if cost_bound is not None and objective != "max_completion":
        weight = evaluator.objective_weights(objective)[:-1]  # (E,)
        if objective == "avg_completion":  # the mean of completions
            weight = weight / problem.n_robots
        upper_delay = _delay_upper(problem, weight, cost_bound - constant, horizon)
    x_col, f_col = np.arange(m), m + np.arange(m)
    d_base, p_base, top = 2 * m, 2 * m + n_events, 2 * m + n_events + n_nodes
    n_vars = top + (objective == "max_completion")

    def delay_col(events: np.ndarray) -> np.ndarray:  # the zero slot E is no variable: -1
        return np.where(events < n_events, d_base + events, -1)

    rows = _Rows()
    chain = np.flatnonzero(graph.chain_next >= 0)  # (K,) delays never decrease on a path
    rows.add([(delay_col(graph.chain_next[chain]), 1.0), (delay_col(chain), -1.0)], 0.0, np.inf)
    _add_waits(rows, graph, upper_delay, x_col, f_col, delay_col)
    _add_acyclicity(rows, problem, x_col, p_base)
    binding = np.flatnonzero(cliques.binding())  # (Q',) at most h_K following-type in each
    sizes = cliques.start[binding + 1] - cliques.start[binding]  # (Q',)
    member = np.repeat(cliques.start[binding] - (np.cumsum(sizes) - sizes), sizes)
    member += np.arange(sizes.sum())  # (T,) positions in cliques.edge, clique by clique
    group = np.repeat(np.arange(binding.size), sizes)  # (T,)
    rows.add_sums(group, f_col[cliques.edge[member]], cliques.budget[binding])

    lower = np.zeros(n_vars)
    upper = np.concatenate([np.ones(2 * m), upper_delay, np.full(n_nodes, n_nodes)])
    upper = np.append(upper, [np.inf] * (n_vars - top))  # the maximum completion, if any
    forced = problem.forced_arcs[0]
    lower[x_col[forced]] = upper[x_col[forced]] = (problem.forced[forced] > 0).astype(float)
    fixed = np.flatnonzero(problem.fixed_type >= 0)
    lower[f_col[fixed]] = upper[f_col[fixed]] = problem.fixed_type[fixed].astype(float)
    upper[f_col[cliques.forbidden()]] = 0.0

    cost = np.zeros(n_vars)
    last = delay_col(graph.last_event)  # (R,)
    if objective == "avg_completion":
        np.add.at(cost, last[last >= 0], 1.0 / problem.n_robots)
    elif objective == "max_completion":
        cost[top] = 1.0
        rows.add([(np.full(finish.size, top), 1.0), (last, -1.0)], finish, np.inf)
    else:  # avg_delay
        cost[d_base : d_base + n_events] = graph.delay_weight[:-1]
    integrality = np.zeros(n_vars)
    integrality[: 2 * m] = 1
    return cost, constant, integrality, Bounds(lower, upper), rows.constraint(n_vars)


def _delay_upper(problem: Problem, weight: np.ndarray, budget: float, horizon: float) -> np.ndarray:
    """(E,) the most each event's delay can be in an answer whose objective, a sum of event
    delays weighted by ``weight`` (E,) >= 0, is at most ``budget`` (a cost some answer
    reaches, less the objective's constant), and at most ``horizon``: delays never fall
    along a path, so an event's delay times the weights of it and of its robot's later
    events is at most the budget. The optimum keeps within; the budget is widened by a
    relative 1e-6 so that the answer that reaches it does too."""
    robot = problem.event_robot  # (E,) sorted: a robot's events are contiguous
    total = np.cumsum(weight)  # (E,)
    last = np.searchsorted(robot, robot, side="right") - 1  # (E,) its robot's last event
    later = total[last] - total + weight  # (E,) weights of the event and the robot's later ones
    room = max(budget, 0.0) * (1 + 1e-6) + 1e-9
    with np.errstate(divide="ignore"):
        return np.minimum(np.where(later > 0, room / later, horizon), horizon)


def _add_waits(rows: _Rows, graph, upper_delay: np.ndarray, x_col, f_col, delay_col) -> None:  # noqa: ANN001
    """Both waits of every live slot: d[target] >= d[source] + offset when active,
    relaxed by M = the source's most delay (``upper_delay`` (E,); the zero slot's 0) +
    max(offset, 0) per inactive literal."""
    upper = np.append(upper_delay, 0.0)  # (E+1,)
    j = np.flatnonzero(graph.live)  # (K,) slots
    conflict, side = j // 2, j % 2
    target = delay_col(graph.target[j])
    # The other side passes first: a_first = 1 for side 1 (b waits), 0 for side 0.
    sign = np.where(side == 1, -1.0, 1.0)  # coefficient of a_first in "relax * M"
    for kind in (1, 0):  # following-level (pair enter), exclusive-level (pair exit)
        offset = graph.offset[kind, j]
        big = upper[graph.source[kind, j]] + np.maximum(offset, 0.0)
        # d_t - d_s >= offset - big * relax with relax = 1 - x (side 1) or x (side 0), plus
        # f at the exclusive level; moved to the left side:
        # d_t - d_s + sign * big * x (+ big * f) >= offset - big * [side == 1]
        terms = [(target, 1.0), (delay_col(graph.source[kind, j]), -1.0)]
        terms.append((x_col[conflict], sign * big))
        if kind == 0:
            terms.append((f_col[conflict], big))
        rows.add(terms, offset - big * (side == 1), np.inf)


def _add_acyclicity(rows: _Rows, problem: Problem, x_col, p_base: int) -> None:  # noqa: ANN001
    """Node positions increasing along paths and along every conflict arc."""
    same = np.flatnonzero(problem.node_robot[1:] == problem.node_robot[:-1])  # v -> v+1
    rows.add([(p_base + same + 1, 1.0), (p_base + same, -1.0)], 1.0, np.inf)
    a, b = p_base + problem.conf_a, p_base + problem.conf_b
    big = problem.n_nodes + 1.0
    rows.add([(b, 1.0), (a, -1.0), (x_col, -big)], 1.0 - big, np.inf)  # a first: b after a
    rows.add([(a, 1.0), (b, -1.0), (x_col, big)], 1.0, np.inf)  # b first: a after b
