"""The constraint-guaranteed decoder shared by the learned model and the baselines.

From positive node bids b (S, V) and per-conflict following scores (S, M) it
builds assignments that are acyclic and density-feasible for *any* input:

* rank r_v = b_v + sum of the bids of v's predecessors on its robot's path, so
  ranks strictly increase along every path; every conflict points from the
  lower to the higher (rank, node index), a strict total order that agrees with
  every path, hence the node graph is a DAG;
* following-type conflicts are chosen greedily by descending score (ties by
  conflict index) while every density clique containing the conflict still has
  budget, hence every clique stays within its budget.

Fixed directions (``Problem.forced``) are honoured by repairing the ranks
before directions are read (:meth:`Decoder.repair`): a longest-path pass over
the DAG of path order and fixed arcs raises the second node of every fixed
conflict just above its first and shifts the rest of that robot's path by the
same amount (the robot waits), so ranks stay non-decreasing along every path
and the fixed first node always comes first. Ranks that already put every
fixed first node strictly below its second are left as they are; without fixed
directions nothing runs at all. Fixed types (``Problem.fixed_type``, the
realized conflicts of a re-schedule) are taken first (following) or never
(exclusive) by the greedy type choice.

The converse also holds (tested): every acyclic assignment comes from the bids
``bids_from_ranks(topological positions)`` and every density-feasible type
choice from scores 1 (following) / 0 (exclusive) with threshold 0.5.
"""

from __future__ import annotations

import copy

import numba
import numpy as np

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.csr import csr
from service.core.problem import Problem
from service.core.schemas import Objective

__all__ = ["MONOTONE", "Decoder", "bids_from_ranks", "decode_candidates", "following_gain"]

# Objectives that never get worse when a conflict turns following-type (its wait is
# weaker); for them the decoder fills every clique budget greedily by score.
MONOTONE = frozenset({"avg_completion", "max_completion", "avg_delay"})


@numba.njit(cache=True)
def _topological_order(start: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """(V,) nodes in an order every arc goes forward in (Kahn); arcs as CSR start (V+1,), dst.

    The graph must be a DAG (path order plus fixed arcs, validated by the problem).
    """
    n_nodes = start.size - 1
    indeg = np.zeros(n_nodes, dtype=np.int64)
    for k in range(dst.size):
        indeg[dst[k]] += 1
    order = np.empty(n_nodes, dtype=np.int64)
    tail = 0
    for v in range(n_nodes):
        if indeg[v] == 0:
            order[tail] = v
            tail += 1
    for head in range(n_nodes):
        v = order[head]
        for k in range(start[v], start[v + 1]):
            w = dst[k]
            indeg[w] -= 1
            if indeg[w] == 0:
                order[tail] = w
                tail += 1
    return order


@numba.njit(cache=True, nogil=True)
def _push_forced(
    ranks: np.ndarray,  # (S, V) float, non-decreasing along each path
    order: np.ndarray,  # (V,) int, topological order of path order + fixed arcs
    prev: np.ndarray,  # (V,) int, previous node on the path or -1
    in_start: np.ndarray,  # (V+1,) int, fixed arcs into each node (CSR)
    in_first: np.ndarray,  # (F,) int, their first nodes
) -> np.ndarray:  # (S, V) float, ranks >= the input, honouring every fixed arc
    """Longest-path repair: each node keeps its path predecessor's shift, and a fixed
    second node goes just above (next float up) its first node."""
    out = np.empty_like(ranks)
    for s in range(ranks.shape[0]):
        r, o = ranks[s], out[s]
        for v in order:
            best = r[v]
            p = prev[v]
            if p >= 0:
                best = max(best, r[v] + (o[p] - r[p]), o[p])
            for k in range(in_start[v], in_start[v + 1]):
                best = max(best, np.nextafter(o[in_first[k]], np.inf))
            o[v] = best
    return out


def bids_from_ranks(problem: Problem, ranks: np.ndarray) -> np.ndarray:
    """Bids whose chain sums give back ``ranks`` (strictly increasing along each path).

    Shapes: ranks (S, V) or (V,) -> bids of the same shape. The first node's bid
    is its rank, so ranks must be positive.
    """
    ranks = np.asarray(ranks, dtype=np.float64)
    bids = ranks.copy()
    first = np.zeros(problem.n_nodes, dtype=bool)
    first[problem.robot_start[:-1]] = True
    bids[..., ~first] = np.diff(ranks, axis=-1)[..., ~first[1:]]
    return bids


@numba.njit(cache=True, nogil=True)
def _greedy_kernel(
    order: np.ndarray,  # (S, B') int, each sample's bound conflicts that may be candidates,
    # best score first (as positions 0..B-1)
    cand: np.ndarray,  # (S, B) bool, candidates for following-type
    start: np.ndarray,  # (B+1,) int, bound conflict b's cliques are cliques[start[b]:start[b+1]]
    cliques: np.ndarray,  # (E',) int, binding cliques of the bound conflicts
    budget: np.ndarray,  # (Q,) int, each clique's budget
) -> np.ndarray:  # (S, B) bool, chosen following-type
    """Per sample, take candidates in order while every clique they are in has budget.

    A numba loop: the same greedy vectorized over samples in numpy measured seconds
    on 250-robot path graphs (tens of thousands of bound conflicts).
    """
    n_samples, n_bound = order.shape
    chosen = np.zeros(cand.shape, dtype=np.bool_)
    left = np.empty_like(budget)
    for s in range(n_samples):
        left[:] = budget
        for k in range(n_bound):
            e = order[s, k]
            if not cand[s, e]:
                continue
            ok = True
            for q in cliques[start[e] : start[e + 1]]:
                if left[q] <= 0:
                    ok = False
                    break
            if ok:
                for q in cliques[start[e] : start[e + 1]]:
                    left[q] -= 1
                chosen[s, e] = True
    return chosen


@numba.njit(cache=True, nogil=True)
def _directions(ranks: np.ndarray, conf_a: np.ndarray, conf_b: np.ndarray) -> np.ndarray:
    """(S, M) bool: side a first where its rank is lower (ties: the lower node index).
    One pass instead of two gathered (S, M) rank tables (23 ms for 100 samples of 21,000
    conflicts, ~4 ms here)."""
    n_samples, n_conf = ranks.shape[0], conf_a.size
    out = np.empty((n_samples, n_conf), dtype=np.bool_)
    a_low = conf_a < conf_b  # (M,) the tie-break
    for s in range(n_samples):
        r = ranks[s]
        for c in range(n_conf):
            ra, rb = r[conf_a[c]], r[conf_b[c]]
            out[s, c] = (ra < rb) | ((ra == rb) & a_low[c])  # branch-free
    return out


def following_gain(
    problem: Problem,
    a_first: np.ndarray,
    enter: np.ndarray | None = None,
    exit_: np.ndarray | None = None,
) -> np.ndarray:
    """Type scores (S, M) from directions (S, M): the wait that following-type spares the
    side passing second against exclusive (it may enter once the first side has entered,
    not only once it has left), at pair enter and exit times ``enter`` and ``exit_``
    ((M, 2), column 0 side a; default: the planned ones).

    Where a clique's budget admits only some following-type conflicts, FCFS's scores
    give it to the earliest ones; on congested warehouses of 100 robots the budget
    spent where it spares the most lowered the cheapest blend by 5-10 % and robot-priority
    search (which keeps the start's types) from there by 4-8 % (docs/benchmarks.md,
    "Following-type where it spares most").
    """
    enter = problem.pair_enter if enter is None else enter
    exit_ = problem.pair_exit if exit_ is None else exit_
    first = np.where(a_first, 0, 1)  # (S, M) side passing first
    rows = np.arange(problem.n_conflicts)  # (M,)
    first_enter, first_exit = enter[rows, first], exit_[rows, first]  # (S, M) each
    second_enter = enter[rows, 1 - first]
    return np.maximum(first_exit - second_enter, 0.0) - np.maximum(first_enter - second_enter, 0.0)


class Decoder:
    """Decodes bids and scores of one problem into valid assignments."""

    def __init__(self, problem: Problem, cliques: Cliques) -> None:
        self.problem = problem
        self.cliques = cliques
        counts = np.diff(problem.robot_start)
        self._chain_width = int(counts.max())  # L, longest path in nodes
        rank_in_robot = np.arange(problem.n_nodes) - problem.robot_start[problem.node_robot]
        self._chain_slot = problem.node_robot * self._chain_width + rank_in_robot  # (V,)
        self._forbidden = cliques.forbidden()  # (M,)
        self._build_binding_table()
        if problem.has_forced:
            self._build_forced_graph()

    def scored(self) -> np.ndarray:
        """(M',) int: the conflicts whose score :meth:`types` reads: those free to be
        following-type (no zero budget forbids it, no fixed type). Any score elsewhere is
        ignored, so a model need not compute it (44-88 % of the conflicts are read on
        250-robot warehouses)."""
        return np.flatnonzero(self._may_follow() & (self.problem.fixed_type < 0))

    def _may_follow(self) -> np.ndarray:
        """(M,) bool: conflicts that can be following-type at all: in no zero-budget clique
        and not fixed exclusive (a re-schedule's realized conflicts)."""
        return ~self._forbidden & (self.problem.fixed_type != 0)

    def for_problem(self, problem: Problem) -> Decoder:
        """This decoder for another problem on the same graph and cliques (a re-schedule's
        residual problem): the clique tables are shared, only the fixed-direction graph
        is rebuilt (the binding table took 85 ms of a 250-robot re-schedule)."""
        out = copy.copy(self)
        out.problem = problem
        if problem.has_forced:
            out._build_forced_graph()
        return out

    def _build_forced_graph(self) -> None:
        """Path predecessors, fixed in-arcs and a topological order, for :meth:`repair`."""
        p = self.problem
        _, first, second = p.forced_arcs  # (F,) each
        same = p.node_robot[1:] == p.node_robot[:-1]  # (V-1,) v -> v+1 is a path arc
        self._prev = np.where(np.append(False, same), np.arange(p.n_nodes) - 1, -1)  # (V,)
        self._in_start, self._in_first = csr(second, first, p.n_nodes)
        path_src = np.flatnonzero(same)
        start, dst = csr(
            np.concatenate([path_src, first]), np.concatenate([path_src + 1, second]), p.n_nodes
        )
        self._order = _topological_order(start, dst)  # (V,)

    def repair(self, ranks: np.ndarray) -> np.ndarray:
        """Ranks (S, V) non-decreasing along paths -> ranks that also put every fixed
        first node strictly before its second (the same ranks without fixed directions).

        Samples whose repaired ranks are not finite (chain sums that overflowed) are
        repaired from their ordinal positions in the (rank, node index) order instead,
        which order the nodes as the ranks do but leave room above every rank.
        """
        if not self.problem.has_forced:
            return np.atleast_2d(ranks)
        # C order: a column-indexed batch arrives in Fortran order, which compiled the
        # kernel a second time.
        ranks = np.ascontiguousarray(np.atleast_2d(ranks), dtype=np.float64)  # (S, V)
        graph = (self._order, self._prev, self._in_start, self._in_first)
        out = _push_forced(ranks, *graph)
        bad = ~np.all(np.isfinite(out), axis=1)  # (S,)
        if bad.any():
            position = np.argsort(np.argsort(ranks[bad], axis=1, kind="stable"), axis=1)
            out[bad] = _push_forced(position.astype(np.float64), *graph)
        return out

    def _build_binding_table(self) -> None:
        """Conflicts inside binding cliques, each with the list of those cliques (CSR).

        A list per conflict, not a table padded to the longest: one conflict can sit in
        thousands of cliques (20,000 within the service's bound) while the others sit in
        one, and the padded table then took gigabytes.
        """
        start, cliques = self.cliques.binding_by_conflict  # (M+1,), (E',)
        self._bound_edges = np.flatnonzero(np.diff(start))  # (B,)
        self._bound_start = np.append(start[self._bound_edges], start[-1])  # (B+1,)
        self._bound_cliques = cliques  # (E',) conflict b's: start[b]:start[b+1], ascending

    def ranks(self, bids: np.ndarray) -> np.ndarray:
        """Chain sums of bids. Shapes: bids (S, V) positive -> ranks (S, V)."""
        bids = np.atleast_2d(np.asarray(bids, dtype=np.float64))
        if not np.all(np.isfinite(bids) & (bids > 0)):
            raise ValueError("bids must be positive and finite")
        n_samples = bids.shape[0]
        padded = np.zeros((n_samples, self.problem.n_robots * self._chain_width))
        padded[:, self._chain_slot] = bids
        shape = (n_samples, self.problem.n_robots, self._chain_width)
        return np.cumsum(padded.reshape(shape), axis=2).reshape(n_samples, -1)[:, self._chain_slot]

    def directions(self, ranks: np.ndarray) -> np.ndarray:
        """a_first (S, M) bool from node ranks (S, V) non-decreasing along each path.

        Ranks are first repaired to honour the fixed directions (:meth:`repair`).
        """
        ranks = np.ascontiguousarray(self.repair(ranks), dtype=np.float64)
        return _directions(ranks, self.problem.conf_a, self.problem.conf_b)

    def types(self, scores: np.ndarray, threshold: float | None = None) -> np.ndarray:
        """following (S, M) bool: greedy by descending score within every clique budget.

        Only conflicts scoring above ``threshold`` are candidates (all, if None).
        """
        scores = np.atleast_2d(np.asarray(scores, dtype=np.float64))
        # Realized types come first, or never.
        scores = np.where(self.problem.fixed_type == 1, np.inf, scores)
        may_follow = self._may_follow()  # (M,)
        candidate = may_follow & ~np.isnan(scores)
        if threshold is not None:
            candidate &= scores > threshold
        following = candidate.copy()
        if self._bound_edges.size:
            following[:, self._bound_edges] = self._greedy(scores, candidate, may_follow)
        return following

    def _greedy(
        self, scores: np.ndarray, candidate: np.ndarray, may_follow: np.ndarray
    ) -> np.ndarray:
        """Greedy budgeted choice over the binding conflicts -> (S, B) bool."""
        bound = self._bound_edges
        # Only those that can be candidates are sorted: half of them on two-way warehouses.
        may = np.flatnonzero(may_follow[bound])  # (B',) positions in bound
        # Descending score, ties by conflict index (stable sort of the negated score).
        order = may[np.argsort(-scores[:, bound[may]], axis=1, kind="stable")]  # (S, B')
        cand = np.ascontiguousarray(candidate[:, bound])
        return _greedy_kernel(
            order, cand, self._bound_start, self._bound_cliques, self.cliques.budget
        )

    def gain_types(
        self, a_first: np.ndarray, enter: np.ndarray | None = None, exit_: np.ndarray | None = None
    ) -> np.ndarray:
        """following (S, M) bool for directions (S, M): every clique budget filled greedily
        by the wait following-type spares (:func:`following_gain`) at pair times ``enter``
        and ``exit_`` ((M, 2); default: planned)."""
        return self.types(following_gain(self.problem, a_first, enter, exit_))

    def decode(
        self, bids: np.ndarray, scores: np.ndarray, threshold: float | None = None
    ) -> Assignments:
        """Assignments (S of them) from bids (S, V) > 0 and scores (S, M)."""
        return self.decode_ranks(self.ranks(bids), scores, threshold)

    def decode_ranks(
        self, ranks: np.ndarray, scores: np.ndarray, threshold: float | None = None
    ) -> Assignments:
        """Assignments from ranks (S, V) non-decreasing along each path and scores (S, M)."""
        return Assignments(self.directions(ranks), self.types(scores, threshold))


def decode_candidates(
    decoder: Decoder, bids: np.ndarray, scores: np.ndarray, objective: Objective
) -> Assignments:
    """Valid assignments from bids (S, V) > 0 and scores (S, M), or (1, M) shared by every
    row (types are then decoded once): S of them, or 2S.

    For a monotone objective every clique budget is filled greedily by score.
    For the others (sync_completion) filling can hurt, so each row is decoded
    twice: rows 0..S-1 only take conflicts scoring above 0.5 (the learned
    probability's threshold), rows S..2S-1 fill the budgets like the monotone case.
    """
    ranks = decoder.ranks(bids)
    a_first = decoder.directions(ranks)  # (S, M)
    rows = len(a_first)

    def types(threshold: float | None = None) -> np.ndarray:  # (S, M)
        following = decoder.types(scores, threshold)  # (S, M) or (1, M)
        return np.repeat(following, rows, axis=0) if len(following) < rows else following

    if objective in MONOTONE:
        return Assignments(a_first, types())
    following = np.concatenate([types(0.5), types()])
    return Assignments(np.concatenate([a_first, a_first]), following)
