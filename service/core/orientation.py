"""Searching assignments directly: feasibility of single moves and backtracking enumeration.

The decoder makes valid assignments from continuous bids; tabu search and
backtracking instead change or fix one conflict at a time, so they need to
know whether one more decision keeps the assignment valid:

* direction: orienting conflict (a, b) as a -> b closes a cycle exactly when
  b already reaches a in the node graph (path arcs plus the oriented
  conflicts); a depth-first search answers it;
* type: a conflict may turn following-type only if it is not forbidden and
  every density clique holding it is still under budget;
* a fixed direction (``Problem.forced``) is never reversed: tabu never flips
  it, and backtracking starts from the fixed arcs already oriented and only
  chooses the type of a fixed conflict;
* a fixed type (``Problem.fixed_type``, realized conflicts of a re-schedule) is
  never changed either.

A partial acyclic orientation always extends (at least one direction of a new
conflict is safe, and exclusive is always allowed); the fixed arcs alone are
acyclic (validated), so backtracking never dead-ends: every leaf it reaches is
a valid assignment. The kernels are
numba-compiled because both searches call them thousands of times per request.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numba
import numpy as np

from service.core.assignment import Assignments
from service.core.cliques import Cliques
from service.core.csr import csr
from service.core.problem import Problem

__all__ = ["Enumeration", "OrientationGraph"]

UNSET = -1  # orientation of a conflict not decided yet (backtracking)
NO_MOVE_LIMIT = int(np.iinfo(np.int64).max)  # an enumeration step without a move budget


@numba.njit(cache=True, inline="always")
def _leads_to(e: int, v: int, orient: np.ndarray, conf_a: np.ndarray, conf_b: np.ndarray) -> int:
    """The node conflict ``e``'s arc leads to from node ``v``, or -1 (not oriented out of v)."""
    if orient[e] == 1 and conf_a[e] == v:
        return conf_b[e]
    if orient[e] == 0 and conf_b[e] == v:
        return conf_a[e]
    return -1


@numba.njit(cache=True)
def _reaches(
    src: int,
    dst: int,
    orient: np.ndarray,
    succ: np.ndarray,
    inc_start: np.ndarray,
    inc_conf: np.ndarray,
    conf_a: np.ndarray,
    conf_b: np.ndarray,
    seen: np.ndarray,
    stack: np.ndarray,
    rank: np.ndarray,
) -> bool:
    """Whether ``dst`` is reachable from ``src`` (orient (M,) int8: 1 a->b, 0 b->a, -1 unset).

    ``rank`` (V,) prunes the search: nodes ranked above ``dst`` are not entered. With the
    positions of a topological order of the graph (or of a graph with more arcs) that
    loses no path, since ranks increase along every path; all zeros prune nothing.
    """
    limit = rank[dst]
    seen[:] = False
    seen[src] = True
    stack[0] = src
    top = 1
    while top > 0:
        top -= 1
        v = stack[top]
        if v == dst:
            return True
        w = succ[v]
        if w >= 0 and not seen[w] and rank[w] <= limit:
            seen[w] = True
            stack[top] = w
            top += 1
        for k in range(inc_start[v], inc_start[v + 1]):
            w = _leads_to(inc_conf[k], v, orient, conf_a, conf_b)
            if w >= 0 and not seen[w] and rank[w] <= limit:
                seen[w] = True
                stack[top] = w
                top += 1
    return False


@numba.njit(cache=True)
def _topological_rank(
    orient: np.ndarray,
    succ: np.ndarray,
    inc_start: np.ndarray,
    inc_conf: np.ndarray,
    conf_a: np.ndarray,
    conf_b: np.ndarray,
) -> np.ndarray:
    """(V,) int64: each node's position in a topological order of the node graph (path arcs
    plus the oriented conflicts; Kahn). All zeros if the graph has a cycle (then the
    ranks prune nothing in :func:`_reaches`)."""
    n_nodes = succ.size
    indegree = np.zeros(n_nodes, dtype=np.int64)
    for v in range(n_nodes):
        if succ[v] >= 0:
            indegree[succ[v]] += 1
    for e in range(orient.size):
        if orient[e] == 1:
            indegree[conf_b[e]] += 1
        elif orient[e] == 0:
            indegree[conf_a[e]] += 1
    queue = np.empty(n_nodes, dtype=np.int64)
    tail = 0
    for v in range(n_nodes):
        if indegree[v] == 0:
            queue[tail] = v
            tail += 1
    rank = np.zeros(n_nodes, dtype=np.int64)
    head = 0
    while head < tail:
        v = queue[head]
        rank[v] = head
        head += 1
        w = succ[v]
        if w >= 0:
            indegree[w] -= 1
            if indegree[w] == 0:
                queue[tail] = w
                tail += 1
        for k in range(inc_start[v], inc_start[v + 1]):
            w = _leads_to(inc_conf[k], v, orient, conf_a, conf_b)
            if w < 0:
                continue
            indegree[w] -= 1
            if indegree[w] == 0:
                queue[tail] = w
                tail += 1
    if head < n_nodes:
        rank[:] = 0
    return rank


@numba.njit(cache=True)
def _budget_left(e: int, counts: np.ndarray, budget: np.ndarray, cq_start, cq_clique) -> bool:
    """Whether every clique holding conflict ``e`` can take one more following-type conflict."""
    for k in range(cq_start[e], cq_start[e + 1]):
        q = cq_clique[k]
        if counts[q] >= budget[q]:
            return False
    return True


@numba.njit(cache=True)
def _moves_feasible(
    moves: np.ndarray,
    orient: np.ndarray,
    following: np.ndarray,
    counts: np.ndarray,
    graph: tuple,
) -> np.ndarray:
    """(K,) bool: which moves keep the assignment valid (see :meth:`OrientationGraph.feasible`).

    One topological order of the (acyclic) assignment serves every direction check: a
    path from v to u runs through nodes ranked between them only. Type flips need none
    (2 ms at 250 robots): it is found only where a direction is checked.
    """
    budget, cq_start, cq_clique, succ, inc_start, inc_conf, conf_a, conf_b, base, ftype = graph
    n_nodes = succ.size
    n_conf = orient.size
    seen = np.zeros(n_nodes, dtype=np.bool_)
    stack = np.empty(n_nodes, dtype=np.int64)
    rank = np.zeros(n_nodes, dtype=np.int64)
    if (moves < n_conf).any():
        rank = _topological_rank(orient, succ, inc_start, inc_conf, conf_a, conf_b)
    out = np.zeros(moves.size, dtype=np.bool_)
    for i in range(moves.size):
        move = moves[i]
        if move >= n_conf:  # type flip, never of a fixed type
            e = move - n_conf
            out[i] = ftype[e] < 0 and (
                following[e] or _budget_left(e, counts, budget, cq_start, cq_clique)
            )
        elif base[move] != UNSET:  # a fixed direction is never reversed
            out[i] = False
        else:  # direction flip: the new arc u -> v must not close a cycle without the old arc
            e = move
            u, v = (conf_b[e], conf_a[e]) if orient[e] == 1 else (conf_a[e], conf_b[e])
            old = orient[e]
            orient[e] = UNSET
            out[i] = not _reaches(
                v, u, orient, succ, inc_start, inc_conf, conf_a, conf_b, seen, stack, rank
            )
            orient[e] = old
    return out


@numba.njit(cache=True)
def _enumerate(
    order: np.ndarray,
    prefer_a: np.ndarray,
    may_follow: np.ndarray,
    follow_first: bool,
    state: np.ndarray,
    orient: np.ndarray,
    following: np.ndarray,
    counts: np.ndarray,
    graph: tuple,
    out_a: np.ndarray,
    out_f: np.ndarray,
    max_moves: int,
) -> tuple[int, int]:
    """Depth-first enumeration of valid assignments, resumable -> (leaves written, moves
    made: values tried or undone at one depth each).

    ``state`` (M + 1,) holds the value index tried at each depth (-1: none) and,
    in its last slot, the current depth; ``orient``/``following``/``counts``
    are the partial assignment. Fills ``out_a``/``out_f`` (K, M) with the next
    leaves, fewer than K when the tree is exhausted (depth -1) or after ``max_moves``
    moves (the state is then where the next call goes on: a first leaf of 23,000
    conflicts takes seconds, and its caller's time limit is checked between calls).
    Value k in 0..3 at a conflict: direction = preferred for k < 2, the other
    for k >= 2; type = ``follow_first`` for even k, the other for odd k. A fixed
    conflict stays oriented as ``base`` says (its preferred direction): k < 2 only.
    """
    budget, cq_start, cq_clique, succ, inc_start, inc_conf, conf_a, conf_b, base, ftype = graph
    n_conf = order.size
    seen = np.zeros(succ.size, dtype=np.bool_)
    stack = np.empty(succ.size, dtype=np.int64)
    no_rank = np.zeros(succ.size, dtype=np.int64)  # the partial orientation changes each step
    found, moves = 0, 0
    depth = state[n_conf]
    while depth >= 0 and found < out_a.shape[0] and moves < max_moves:
        moves += 1
        e = order[depth]
        if state[depth] >= 0:  # undo this depth's current value before trying the next
            if following[e]:
                following[e] = False
                for k in range(cq_start[e], cq_start[e + 1]):
                    counts[cq_clique[k]] -= 1
            orient[e] = base[e]
        k = state[depth] + 1
        last = 4 if base[e] == UNSET else 2  # a fixed conflict only chooses its type
        placed = False
        while k < last:
            a_first = prefer_a[e] if k < 2 else not prefer_a[e]
            follow = follow_first if k % 2 == 0 else not follow_first
            if ftype[e] >= 0 and follow != (ftype[e] == 1):  # a fixed type is never changed
                k += 1
                continue
            if follow and not (
                may_follow[e] and _budget_left(e, counts, budget, cq_start, cq_clique)
            ):
                k += 1
                continue
            u, v = (conf_a[e], conf_b[e]) if a_first else (conf_b[e], conf_a[e])
            if base[e] == UNSET and _reaches(
                v, u, orient, succ, inc_start, inc_conf, conf_a, conf_b, seen, stack, no_rank
            ):
                k = 4 if k >= 2 else 2  # this direction closes a cycle: skip both its types
                continue
            orient[e] = 1 if a_first else 0
            if follow:
                following[e] = True
                for j in range(cq_start[e], cq_start[e + 1]):
                    counts[cq_clique[j]] += 1
            placed = True
            break
        if not placed:
            state[depth] = -1
            depth -= 1
            continue
        state[depth] = k
        if depth == n_conf - 1:
            for j in range(n_conf):
                out_a[found, j] = orient[j] == 1
                out_f[found, j] = following[j]
            found += 1
        else:
            depth += 1
    state[n_conf] = depth
    return found, moves


@dataclass
class Enumeration:
    """A resumable depth-first enumeration of valid assignments (``OrientationGraph.enumerate``)."""

    graph: OrientationGraph
    order: np.ndarray  # (M,) conflicts in branching order
    prefer_a: np.ndarray  # (M,) bool, the direction tried first (the fixed one, if fixed)
    follow_first: bool
    state: np.ndarray  # (M + 1,) value index per depth, then the current depth
    orient: np.ndarray  # (M,) int8, starts as the fixed directions (graph.base)
    following: np.ndarray  # (M,) bool
    counts: np.ndarray  # (Q,) following-type conflicts per clique
    moves: int = 0  # made so far (see _enumerate)

    @property
    def done(self) -> bool:
        """Whether every valid assignment has been produced."""
        return bool(self.state[-1] < 0)

    def next(self, count: int, max_moves: int = NO_MOVE_LIMIT) -> Assignments:
        """Up to ``count`` further leaves, depth first: fewer once the tree is exhausted,
        or after ``max_moves`` moves (none, possibly, before the first leaf)."""
        n_conf = self.order.size
        if self.done:
            return Assignments(np.zeros((0, n_conf), dtype=bool), np.zeros((0, n_conf), dtype=bool))
        if n_conf == 0:  # one valid assignment: the empty one
            self.state[-1] = -1
            return Assignments(np.zeros((1, 0), dtype=bool), np.zeros((1, 0), dtype=bool))
        out_a = np.zeros((count, n_conf), dtype=bool)
        out_f = np.zeros((count, n_conf), dtype=bool)
        found, moves = _enumerate(
            self.order, self.prefer_a, self.graph.may_follow, self.follow_first,
            self.state, self.orient, self.following, self.counts,
            self.graph.kernel_args(), out_a, out_f, max_moves,
        )  # fmt: skip
        self.moves += moves
        return Assignments(out_a[:found], out_f[:found])


class OrientationGraph:
    """One problem's node graph and clique incidences, for move-by-move searches."""

    def __init__(self, problem: Problem, cliques: Cliques) -> None:
        self.problem = problem
        self.cliques = cliques
        n_nodes, n_conf = problem.n_nodes, problem.n_conflicts
        same = problem.node_robot[1:] == problem.node_robot[:-1]
        self.succ = np.full(n_nodes, -1, dtype=np.int64)  # (V,) next node on the path, or -1
        self.succ[:-1][same] = np.arange(1, n_nodes)[same]
        self.inc_start, self.inc_conf = csr(
            np.concatenate([problem.conf_a, problem.conf_b]),
            np.tile(np.arange(n_conf), 2),
            n_nodes,
        )  # node -> incident conflicts
        self.cq_start, self.cq_clique = cliques.by_conflict  # conflict -> its cliques
        self.may_follow = ~cliques.forbidden()  # (M,)
        self.base = _fixed_orientation(problem)

    def for_problem(self, problem: Problem) -> OrientationGraph:
        """This graph for another problem on the same graph and cliques (a re-schedule's
        residual problem): only the fixed directions are read anew."""
        out = copy.copy(self)
        out.problem = problem
        out.base = _fixed_orientation(problem)
        return out

    def kernel_args(self) -> tuple[np.ndarray, ...]:
        """The static arrays every kernel takes, as one tuple (unpacked inside the kernel)."""
        p = self.problem
        return (
            self.cliques.budget.astype(np.int64), self.cq_start, self.cq_clique,
            self.succ, self.inc_start, self.inc_conf,
            p.conf_a.astype(np.int64), p.conf_b.astype(np.int64), self.base,
            p.fixed_type,
        )  # fmt: skip

    def feasible(
        self,
        a_first: np.ndarray,
        following: np.ndarray,
        moves: np.ndarray,
        counts: np.ndarray | None = None,
    ) -> np.ndarray:
        """Which single moves keep the valid assignment (a_first (M,), following (M,)) valid.

        Move m < M reverses conflict m; move M + m flips conflict m's type. ``counts``:
        the assignment's following-type conflicts per clique (Q,), if the caller keeps them
        (:meth:`count_type_move`; counting anew reads every clique incidence).
        Shapes: moves (K,) int -> (K,) bool.
        """
        if counts is None:
            counts = self.cliques.following_counts(following[None])[0]  # (Q,)
        return _moves_feasible(
            np.asarray(moves, dtype=np.int64),
            a_first.astype(np.int8),
            following.astype(np.bool_),
            counts,
            self.kernel_args(),
        )

    def topological_rank(self, a_first: np.ndarray) -> np.ndarray | None:
        """Each node's position in a topological order of the node graph that the directions
        a_first (M,) bool make, or None where they close a cycle. Shapes: -> (V,) int64."""
        rank = _topological_rank(*self.walk_args(a_first))
        n_nodes = self.problem.n_nodes
        return rank if n_nodes <= 1 or int(rank.max()) == n_nodes - 1 else None

    def walk_args(self, a_first: np.ndarray) -> tuple[np.ndarray, ...]:
        """What a kernel walking the node graph of the directions a_first (M,) bool takes:
        (orient (M,) int8, succ, inc_start, inc_conf, conf_a, conf_b)."""
        p = self.problem
        return (
            a_first.astype(np.int8), self.succ, self.inc_start, self.inc_conf,
            p.conf_a.astype(np.int64), p.conf_b.astype(np.int64),
        )  # fmt: skip

    def recount(self, counts: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        """(Q,) following-type conflicts per clique of the types ``after`` (M,) bool, from
        the ``counts`` (Q,) of ``before`` (M,) bool: a search step changes the types of a
        few robots' conflicts, and a full count
        (:meth:`~service.core.cliques.Cliques.following_counts`) takes 1.2 ms at 250 robots."""
        return _recount(counts, before, after, self.cq_start, self.cq_clique)

    def count_type_move(self, counts: np.ndarray, conflict: int, now_following: bool) -> None:
        """Update ``counts`` (Q,) in place for ``conflict`` having turned following-type (or
        exclusive, if not ``now_following``)."""
        cliques = self.cq_clique[self.cq_start[conflict] : self.cq_start[conflict + 1]]
        counts[cliques] += 1 if now_following else -1

    def enumerate(self, order: np.ndarray, prefer_a: np.ndarray, follow_first: bool) -> Enumeration:
        """Depth-first enumeration of every valid assignment (lazily, see :class:`Enumeration`).

        Conflicts are decided in ``order`` (M,); at each, the direction
        ``prefer_a`` (M,) bool is tried before the other, and following-type
        before exclusive when ``follow_first``. Fixed conflicts keep their fixed
        direction whatever ``prefer_a`` says.
        """
        n_conf = self.problem.n_conflicts
        state = np.full(n_conf + 1, -1, dtype=np.int64)
        state[n_conf] = 0
        return Enumeration(
            graph=self,
            order=np.asarray(order, dtype=np.int64),
            prefer_a=np.where(self.base == UNSET, prefer_a, self.base == 1),
            follow_first=bool(follow_first),
            state=state,
            orient=self.base.copy(),
            following=np.zeros(n_conf, dtype=np.bool_),
            counts=np.zeros(self.cliques.budget.size, dtype=np.int64),
        )


def _fixed_orientation(problem: Problem) -> np.ndarray:
    """(M,) int8 orientation of the fixed conflicts (1 a->b, 0 b->a), UNSET elsewhere."""
    return np.where(problem.forced == 0, UNSET, problem.forced > 0).astype(np.int8)


@numba.njit(cache=True, nogil=True)
def _recount(
    counts: np.ndarray,  # (Q,) int, following-type conflicts per clique of ``before``
    before: np.ndarray,  # (M,) bool, following-type
    after: np.ndarray,  # (M,) bool
    cq_start: np.ndarray,  # (M+1,) conflict c's cliques: cq_clique[cq_start[c]:cq_start[c+1]]
    cq_clique: np.ndarray,
) -> np.ndarray:
    """(Q,) following-type conflicts per clique of ``after``, from those of ``before``."""
    out = counts.copy()
    for c in range(before.size):
        if before[c] != after[c]:
            step = 1 if after[c] else -1
            for k in range(cq_start[c], cq_start[c + 1]):
                out[cq_clique[k]] += step
    return out
