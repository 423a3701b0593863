"""Density cliques of a problem and their budgets of following-type conflicts.

The contract limits crowding per clique of the conflict graph: for every
maximal clique K, rho_K = min density of its nodes and at most
h_K = rho_K (rho_K + 1) / 2 - 1 of the conflicts inside K may be following-type;
each explicit ``density_limits`` entry adds the same kind of clique with
rho = its ``max_robots``. Only maximal cliques of more members than their least density
are listed: a clique of k <= rho_K members holds k (k - 1) / 2 <= h_K conflicts, so no
assignment can exceed its budget (those that can are exactly the ones whose budget
binds, :meth:`Cliques.binding`, or is zero, :meth:`Cliques.forbidden`).

Maximal cliques can be exponentially many (a complete multipartite conflict
graph of k robots with n nodes each has n^k), so the enumeration stops with
:class:`TooManyCliques` once there are more cliques, or they hold more conflicts,
than the bound set by :func:`clique_budget`; the service sets it per request, CLIs
leave it unbounded. What a solve costs follows both: each clique is a density
constraint, each of its conflicts a term in it (a 250-robot warehouse as paths were derived
until session 57 held 936,000 conflicts in only 209 cliques and solved in time; 19,683
cliques holding 708,588 do not; graphs derived from paths now list none).

The enumeration is compiled (Bron-Kerbosch with Tomita's pivot, vertices in degeneracy
order, each neighbourhood as a bitset matrix: Eppstein, Loffler and Strash 2010);
networkx's took 0.48 s for a 250-robot warehouse's 2,860 cliques. Cliques are listed in
a canonical order (members sorted, cliques sorted), whatever the enumeration's order.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from itertools import pairwise

import numba
import numpy as np
from numba import types
from numba.typed import List

from service.core.csr import csr, gather, select, transpose
from service.core.lazy import cached_property
from service.core.problem import Problem

__all__ = [
    "CliqueBound",
    "Cliques",
    "TooManyCliques",
    "budget_for",
    "clique_budget",
    "find_cliques",
]


@dataclass(frozen=True)
class CliqueBound:
    """Work bound of one enumeration: at most ``cliques`` maximal cliques holding at most
    ``incidences`` conflicts in all (the CSR's Q and E); None: unbounded."""

    cliques: int | None = None
    incidences: int | None = None


_BOUND: ContextVar[CliqueBound] = ContextVar("clique_bound", default=CliqueBound())  # noqa: B039 (frozen)
# What the enumeration kernel reports (:func:`_maximal_cliques`).
_COMPLETE, _OVER_INCIDENCES, _OVER_CLIQUES = 0, 1, 2


class TooManyCliques(ValueError):
    """The conflict graph has more maximal cliques, or they hold more conflicts, than the
    bound allows. ``setting`` names the bound that was exceeded."""

    def __init__(self, setting: str, budget: int) -> None:
        what = (
            f"it has more than {budget} maximal cliques"
            if setting == "max_cliques"
            else f"its maximal cliques hold more than {budget} conflicts in all"
        )
        super().__init__(f"conflict graph too dense: {what} ({setting})")
        self.setting = setting
        self.budget = budget


@contextmanager
def clique_budget(bound: CliqueBound) -> Iterator[None]:
    """Bound :func:`find_cliques` in this context (thread or task) by ``bound``.

    A context variable rather than a parameter: the enumeration runs deep inside
    whichever solver first needs the cliques, and requests run concurrently.
    """
    token = _BOUND.set(bound)
    try:
        yield
    finally:
        _BOUND.reset(token)


def budget_for(rho: int) -> int:
    """h = rho (rho + 1) / 2 - 1: following-type conflicts allowed in a clique of density rho."""
    return rho * (rho + 1) // 2 - 1


@dataclass(frozen=True, eq=False)
class Cliques:
    """Every density clique as a compressed list of its conflicts (CSR layout).

    Shapes: Q cliques, E clique-conflict incidences.
    """

    budget: np.ndarray  # (Q,) int, following-type conflicts allowed in each clique
    edge: np.ndarray  # (E,) int, conflict indices, grouped by clique
    start: np.ndarray  # (Q+1,) int, clique q holds edge[start[q]:start[q+1]]
    n_conflicts: int

    @property
    def size(self) -> np.ndarray:
        """(Q,) int: conflicts inside each clique."""
        return np.diff(self.start)

    @cached_property
    def by_conflict(self) -> tuple[np.ndarray, np.ndarray]:
        """Each conflict's cliques: (start (M+1,), cliques (E,) ascending within a conflict),
        conflict c's are ``cliques[start[c]:start[c + 1]]``. Cached: the orientation graph
        and, through :attr:`binding_by_conflict`, the decoder, re-insertion and LNS read
        it (0.26 s for the 14 million incidences of a 250-robot warehouse)."""
        return transpose(self.start, self.edge, self.n_conflicts)

    @cached_property
    def binding_by_conflict(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`by_conflict` restricted to the :meth:`binding` cliques, the only ones
        whose budget a search must count (same layout)."""
        return select(*self.by_conflict, self.binding())

    def split(self, part: np.ndarray, n_parts: int) -> list[Cliques]:
        """The cliques of each part of the problem, whose conflicts are those labelled
        with it in ``part`` (M,) int in 0..n_parts-1, renumbered in ascending order.

        Parts must be unions of components (every clique then lies in one part): each
        part's cliques are then exactly what :func:`find_cliques` finds on its own
        problem, in its order, without enumerating again (at 1,000 robots in four
        components, 0.17 s for the four parts)."""
        clique_part = part[self.edge[self.start[:-1]]]  # (Q,) every clique holds a conflict
        order = np.argsort(clique_part, kind="stable")  # (Q,) cliques by part, order kept
        edge, _ = gather(self.start, self.edge, order)  # (E,) their conflicts, in that order
        by_conflict = np.argsort(part, kind="stable")  # (M,) conflicts by part, ascending
        first = np.searchsorted(part[by_conflict], np.arange(n_parts + 1))  # (n_parts+1,)
        renumber = np.empty(self.n_conflicts, dtype=np.int64)  # (M,) index within its part
        renumber[by_conflict] = np.arange(self.n_conflicts) - np.repeat(first[:-1], np.diff(first))
        size = self.size[order]  # (Q,)
        bounds = np.searchsorted(clique_part[order], np.arange(n_parts + 1))  # cliques by part
        ends = np.concatenate([[0], np.cumsum(size)])  # (Q+1,) where each clique's edges begin
        return [
            Cliques(
                budget=self.budget[order[lo:hi]],
                edge=renumber[edge[ends[lo] : ends[hi]]],
                start=ends[lo : hi + 1] - ends[lo],
                n_conflicts=int(first[k + 1] - first[k]),
            )
            for k, (lo, hi) in enumerate(pairwise(bounds.tolist()))
        ]

    def forbidden(self) -> np.ndarray:
        """(M,) bool: conflicts inside a zero-budget clique, which must be exclusive."""
        mask = np.zeros(self.n_conflicts, dtype=bool)
        mask[self.edge[np.repeat(self.budget <= 0, self.size)]] = True
        return mask

    def binding(self) -> np.ndarray:
        """(Q,) bool: cliques whose budget is positive but below their conflict count."""
        return (self.budget > 0) & (self.budget < self.size)

    def following_counts(self, following: np.ndarray) -> np.ndarray:
        """Following-type conflicts inside each clique, for a batch of assignments.

        Shapes: following (S, M) bool -> (S, Q) int.
        """
        following = np.ascontiguousarray(np.atleast_2d(following), dtype=np.bool_)
        return _count_following(following, self.edge, self.start)


@numba.njit(cache=True, nogil=True)
def _count_following(following: np.ndarray, edge: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(S, Q) following-type conflicts of each clique: a loop, not a gather of the (S, E)
    incidences (2,000,000 incidences within the service's bound: gigabytes for 100
    samples as int64)."""
    n_samples, n_cliques = following.shape[0], start.size - 1
    out = np.zeros((n_samples, n_cliques), dtype=np.int64)
    for s in range(n_samples):
        for q in range(n_cliques):
            count = 0
            for k in range(start[q], start[q + 1]):
                count += following[s, edge[k]]
            out[s, q] = count
    return out


def find_cliques(problem: Problem) -> Cliques:
    """Maximal cliques of the conflict graph of more members than their least density
    (the others can never bind) plus explicit limits, with budgets.

        Raises:
            TooManyCliques: the cliques exceed the budget of :func:`clique_budget`.
    """
    adjacency = _adjacency(problem)
    members, member_start = _conflict_cliques(adjacency, problem.node_density, _BOUND.get())
    first = member_start[:-1]  # (Q,) every clique has two or more members
    rho = np.minimum.reduceat(problem.node_density[members], first) if first.size else first
    limits = problem.density_limits
    members = np.concatenate([members, limits.nodes])
    member_start = np.concatenate([member_start, member_start[-1] + limits.start[1:]])
    budgets = np.concatenate([budget_for(rho), budget_for(limits.max_robots)])
    edge, start = _incidences(adjacency, members, member_start)
    return Cliques(
        budget=budgets.astype(np.int64),
        edge=edge,
        start=start,
        n_conflicts=problem.n_conflicts,
    )


@dataclass(frozen=True, eq=False)
class _Adjacency:
    """The conflict graph in CSR layout: node v's neighbours are ``neighbours[start[v]:
    start[v + 1]]``, ascending, joined to v by the conflicts at the same positions.

    Shapes: start (V+1,), neighbours (2M,), conflict (2M,).
    """

    start: np.ndarray
    neighbours: np.ndarray
    conflict: np.ndarray


def _adjacency(problem: Problem) -> _Adjacency:
    """The problem's conflict graph, both directions of every conflict."""
    n, m = problem.node_robot.size, problem.n_conflicts
    a = np.concatenate([problem.conf_a, problem.conf_b])  # (2M,) both directions
    b = np.concatenate([problem.conf_b, problem.conf_a])
    order = np.lexsort((b, a))
    start = np.searchsorted(a[order], np.arange(n + 1))  # (V+1,)
    conflict = np.concatenate([np.arange(m), np.arange(m)])[order]
    return _Adjacency(start.astype(np.int64), b[order].astype(np.int64), conflict)


def _conflict_cliques(
    adjacency: _Adjacency, density: np.ndarray, bound: CliqueBound
) -> tuple[np.ndarray, np.ndarray]:
    """Every maximal clique of the conflict graph that holds more members than its least
    ``density`` (V,), members ascending, cliques in lexicographic order of their members
    (whatever the enumeration's order).

    Shapes: -> members (K,) int, member_start (Q+1,) int: clique q is
    ``members[member_start[q]:member_start[q + 1]]``.

    Raises:
        TooManyCliques: there are more than ``bound.cliques`` or they hold more than
            ``bound.incidences`` conflicts in all.
    """
    limits = np.array(
        [-1 if b is None else b for b in (bound.incidences, bound.cliques)], dtype=np.int64
    )
    flat, ends, status = _maximal_cliques(
        adjacency.start, adjacency.neighbours, density.astype(np.int64), limits
    )
    if status == _OVER_INCIDENCES:
        assert bound.incidences is not None
        raise TooManyCliques("max_clique_incidences", bound.incidences)
    if status == _OVER_CLIQUES:
        assert bound.cliques is not None
        raise TooManyCliques("max_cliques", bound.cliques)
    bounds = np.concatenate([[0], ends]).astype(np.int64)  # (Q+1,)
    _sort_segments(flat, bounds)
    order = _lexicographic_order(flat, bounds)  # (Q,)
    sizes = np.diff(bounds)[order]  # (Q,)
    member_start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    shift = np.repeat(bounds[:-1][order] - member_start[:-1], sizes)  # (K,)
    return flat[np.arange(flat.size) + shift], member_start


@numba.njit(cache=True, nogil=True)
def _sort_segments(values: np.ndarray, bounds: np.ndarray) -> None:
    """Sort ``values[bounds[i]:bounds[i + 1]]`` for every i, in place; a segment already
    in order is only scanned (a clique's conflicts arrive in order when the conflicts are
    listed by node pair, as derived paths list them: 0.17-0.28 s of sorting skipped for
    the 14 million incidences of a 250-robot warehouse)."""
    for i in range(bounds.size - 1):
        segment = values[bounds[i] : bounds[i + 1]]
        for k in range(1, segment.size):
            if segment[k] < segment[k - 1]:
                segment.sort()
                break


@numba.njit(cache=True, nogil=True)
def _lexicographic_order(values: np.ndarray, bounds: np.ndarray) -> np.ndarray:
    """(Q,) the segments ``values[bounds[q]:bounds[q + 1]]`` in lexicographic order (a
    prefix first), by a bottom-up merge sort: the order Python gives lists of them, without
    building millions of Python ints (0.26 s for a 250-robot warehouse's cliques)."""
    n = bounds.size - 1
    order, spare = np.arange(n), np.empty(n, dtype=np.int64)
    width = 1
    while width < n:
        for lo in range(0, n, 2 * width):
            mid, hi = min(lo + width, n), min(lo + 2 * width, n)
            i, j = lo, mid
            for k in range(lo, hi):
                if j >= hi or (i < mid and not _precedes(values, bounds, order[j], order[i])):
                    spare[k] = order[i]
                    i += 1
                else:
                    spare[k] = order[j]
                    j += 1
        order, spare = spare, order
        width *= 2
    return order


@numba.njit(cache=True, nogil=True)
def _precedes(values: np.ndarray, bounds: np.ndarray, p: int, q: int) -> bool:
    """Whether segment p comes strictly before segment q in lexicographic order."""
    lp, lq = bounds[p + 1] - bounds[p], bounds[q + 1] - bounds[q]
    for k in range(min(lp, lq)):
        a, b = values[bounds[p] + k], values[bounds[q] + k]
        if a != b:
            return a < b
    return lp < lq


@numba.njit(cache=True, nogil=True)
def _maximal_cliques(
    start: np.ndarray, neighbours: np.ndarray, density: np.ndarray, limits: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int]:
    """Maximal cliques of a graph in CSR form (vertex v's sorted neighbours are
    ``neighbours[start[v]:start[v + 1]]``) that hold more vertices than the least
    ``density`` (V,) among them: their members (flat), the end of each clique in them,
    and a status: _COMPLETE, or _OVER_INCIDENCES / _OVER_CLIQUES when they hold more
    than ``limits[0]`` vertex pairs or are more than ``limits[1]`` cliques (the
    enumeration stops there; a limit of -1: none).

    The others are never listed: their budget is at least their conflicts (see
    :func:`budget_for`), so no assignment can exceed it, and on graphs of dense nodes
    they are nearly all (a 250-robot floor of density 50 nodes: 390,050 maximal cliques
    holding 101 million conflicts, not one of them able to bind).

    Each vertex v, in degeneracy order, starts the cliques whose earliest vertex it is:
    candidates are its later neighbours, excluded its earlier ones, and its
    neighbourhood's adjacency is a bitset matrix (:func:`_cliques_through`).
    """
    n = start.size - 1
    rank = _degeneracy_rank(start, neighbours)  # (V,) position in degeneracy order
    members = List.empty_list(types.int64)
    ends = List.empty_list(types.int64)
    pairs = np.zeros(1, dtype=np.int64)  # vertex pairs inside the cliques so far
    sink = (members, ends, pairs)  # where the cliques go (:func:`_report`)
    status = _COMPLETE
    local = np.full(n, -1, dtype=np.int64)  # (V,) vertex -> its index among v's neighbours
    for v in np.argsort(rank):
        universe = neighbours[start[v] : start[v + 1]]  # (d,) v's neighbours
        d = universe.size
        if d == 0:
            continue
        words = (d + 63) // 64
        later = np.zeros(words, dtype=np.uint64)
        for k in range(d):
            if rank[universe[k]] > rank[v]:
                later[k // 64] |= np.uint64(1) << np.uint64(k % 64)
        if not _may_bind(density[v], 1, later, universe, density):
            continue
        for k in range(d):
            local[universe[k]] = k
        adj = np.zeros((d, words), dtype=np.uint64)  # (d, W) bitsets
        for k in range(d):
            w = universe[k]
            for u in neighbours[start[w] : start[w + 1]]:
                if local[u] >= 0:
                    adj[k, local[u] // 64] |= np.uint64(1) << np.uint64(local[u] % 64)
        status = _cliques_through(v, later, adj, universe, density, sink, limits)
        for k in range(d):
            local[universe[k]] = -1
        if status != _COMPLETE:
            break
    # Typed lists read element by element from Python (0.75 s for 177,000 members).
    return _array(members), _array(ends), status


@numba.njit(cache=True, nogil=True)
def _array(values: List) -> np.ndarray:
    """(N,) int64 copy of a typed list."""
    out = np.empty(len(values), dtype=np.int64)
    for k in range(len(values)):
        out[k] = values[k]
    return out


@numba.njit(cache=True, nogil=True)
def _cliques_through(
    v: int,
    later: np.ndarray,
    adj: np.ndarray,
    universe: np.ndarray,
    density: np.ndarray,
    sink: tuple[List, List, np.ndarray],
    limits: np.ndarray,
) -> int:
    """The maximal cliques holding v and, otherwise, only v's ``later`` neighbours, of
    more members than their least ``density`` (V,): Bron-Kerbosch with Tomita's pivot,
    iterative (an explicit stack of candidate, excluded and still-to-try bitsets per
    depth), not descending where no such clique can lie (:func:`_may_bind`). Shapes:
    later (W,), adj (d, W) over the d neighbours ``universe``. The status of
    :func:`_report` once a limit is exceeded, else _COMPLETE."""
    d, words = adj.shape
    cand = np.zeros((d + 1, words), dtype=np.uint64)
    excl = np.zeros((d + 1, words), dtype=np.uint64)
    todo = np.zeros((d + 1, words), dtype=np.uint64)
    chosen = np.full(d + 1, -1, dtype=np.int64)  # the vertex being tried at each depth
    clique = np.empty(d + 1, dtype=np.int64)  # universe indices; v itself is implied
    least = np.empty(d + 1, dtype=np.int64)  # least density of v and clique[:level + 1]
    cand[0] = later
    excl[0] = ~later & _all_bits(d, words)
    if not later.any():  # v's cliques all hold an earlier vertex: found from there
        return _COMPLETE
    todo[0] = later & ~adj[_pivot(cand[0], excl[0], adj)]
    level = 0
    while level >= 0:
        u = chosen[level]
        if u >= 0:  # u was tried: it moves from the candidates to the excluded
            bit = np.uint64(1) << np.uint64(u % 64)
            cand[level, u // 64] &= ~bit
            excl[level, u // 64] |= bit
            chosen[level] = -1
        u = _first_bit(todo[level])
        if u < 0:
            level -= 1
            continue
        todo[level, u // 64] &= ~(np.uint64(1) << np.uint64(u % 64))
        chosen[level] = u
        clique[level] = u
        above = density[v] if level == 0 else least[level - 1]
        least[level] = min(above, density[universe[u]])
        next_cand = cand[level] & adj[u]
        next_excl = excl[level] & adj[u]
        if not next_cand.any():
            if not next_excl.any() and least[level] < level + 2:  # maximal, may bind
                status = _report(v, clique, level + 1, universe, sink, limits)
                if status != _COMPLETE:
                    return status
            continue
        if not _may_bind(least[level], level + 2, next_cand, universe, density):
            continue
        level += 1
        cand[level], excl[level] = next_cand, next_excl
        todo[level] = next_cand & ~adj[_pivot(next_cand, next_excl, adj)]
    return _COMPLETE


@numba.njit(cache=True, nogil=True)
def _may_bind(
    least: int, size: int, cand: np.ndarray, universe: np.ndarray, density: np.ndarray
) -> bool:
    """Whether a clique of ``size`` members of least density ``least``, grown from the
    candidates ``cand`` (W,) over ``universe``, could hold more members than its least
    density: some member or candidate is less dense than all of them together."""
    total = size
    for w in range(cand.size):
        total += _popcount(cand[w])
    if least < total:
        return True
    for w in range(cand.size):
        pool = cand[w]
        while pool:
            low = pool & (~pool + np.uint64(1))
            if density[universe[w * 64 + _bit_index(low)]] < total:
                return True
            pool ^= low
    return False


@numba.njit(cache=True, nogil=True)
def _report(
    v: int,
    clique: np.ndarray,
    size: int,
    universe: np.ndarray,
    sink: tuple[List, List, np.ndarray],
    limits: np.ndarray,
) -> int:
    """Record the clique of v and ``clique[:size]`` in ``sink`` (members, clique ends,
    vertex pairs so far); the limit that exceeds (see :func:`_maximal_cliques`) or
    _COMPLETE."""
    members, ends, pairs = sink
    pairs[0] += (size + 1) * size // 2
    if 0 <= limits[0] < pairs[0]:
        return _OVER_INCIDENCES
    if 0 <= limits[1] <= len(ends):
        return _OVER_CLIQUES
    members.append(v)
    for k in range(size):
        members.append(universe[clique[k]])
    ends.append(len(members))
    return _COMPLETE


@numba.njit(cache=True, nogil=True)
def _pivot(cand: np.ndarray, excl: np.ndarray, adj: np.ndarray) -> int:
    """The vertex of ``cand | excl`` with the most neighbours among ``cand`` (Tomita)."""
    pivot, best = -1, -1
    for w in range(cand.size):
        pool = cand[w] | excl[w]
        while pool:
            low = pool & (~pool + np.uint64(1))
            u = w * 64 + _bit_index(low)
            pool ^= low
            count = 0
            for x in range(cand.size):
                count += _popcount(cand[x] & adj[u, x])
            if count > best:
                pivot, best = u, count
    return pivot


@numba.njit(cache=True, nogil=True)
def _first_bit(bits: np.ndarray) -> int:
    """Index of the lowest set bit of a bitset (W,), -1 if none."""
    for w in range(bits.size):
        if bits[w]:
            return w * 64 + _bit_index(bits[w] & (~bits[w] + np.uint64(1)))
    return -1


@numba.njit(cache=True, nogil=True)
def _all_bits(d: int, words: int) -> np.ndarray:
    """(W,) the bitset of indices 0..d-1."""
    out = np.zeros(words, dtype=np.uint64)
    for k in range(d):
        out[k // 64] |= np.uint64(1) << np.uint64(k % 64)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def _popcount(x: np.uint64) -> int:
    count = 0
    while x:
        x &= x - np.uint64(1)
        count += 1
    return count


@numba.njit(cache=True, nogil=True, inline="always")
def _bit_index(low: np.uint64) -> int:
    """Index of the one set bit of ``low``."""
    k = 0
    while low > np.uint64(1):
        low >>= np.uint64(1)
        k += 1
    return k


@numba.njit(cache=True, nogil=True)
def _degeneracy_rank(start: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """(V,) each vertex's position when repeatedly removing a vertex of least remaining
    degree (Batagelj-Zaversnik bucket queue, O(V + E))."""
    n = start.size - 1
    degree = start[1:] - start[:-1]
    bucket = np.zeros(n + 2, dtype=np.int64)  # where each degree's bucket starts
    for v in range(n):
        bucket[degree[v] + 1] += 1
    bucket = np.cumsum(bucket)
    order = np.empty(n, dtype=np.int64)  # vertices by current degree
    where = np.empty(n, dtype=np.int64)  # each vertex's place in order
    fill = bucket.copy()
    for v in range(n):
        where[v] = fill[degree[v]]
        order[where[v]] = v
        fill[degree[v]] += 1
    rank = np.empty(n, dtype=np.int64)
    for k in range(n):
        v = order[k]
        rank[v] = k
        for u in neighbours[start[v] : start[v + 1]]:
            du = degree[u]
            if du > degree[v]:  # u moves to the front of its bucket, then one bucket down
                first = max(bucket[du], k + 1)
                w = order[first]
                if w != u:
                    order[where[u]], order[first] = w, u
                    where[w], where[u] = where[u], first
                bucket[du] = first + 1
                degree[u] = du - 1
    return rank


def _incidences(
    adjacency: _Adjacency, members: np.ndarray, member_start: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The conflicts inside each clique (members ascending and pairwise in conflict;
    clique q is ``members[member_start[q]:member_start[q + 1]]``), in CSR layout.

    Compiled, node by node: each node's row of the conflict graph is spread over a
    scratch table once, and every clique holding the node reads its later members'
    conflicts there (a vectorized lookup in a table of every conflict took 0.9 s for the
    14 million incidences of a 250-robot warehouse, a walk through each member's sorted
    neighbours 0.35 s).

    Shapes: -> edge (E,) int sorted within each clique, start (Q+1,) int.
    """
    sizes = np.diff(member_start)  # (Q,)
    start = np.concatenate([[0], np.cumsum(sizes * (sizes - 1) // 2)]).astype(np.int64)
    members = members.astype(np.int64)
    n_nodes = adjacency.start.size - 1
    occ_start, occurrence = csr(members, np.arange(members.size), n_nodes)  # node -> slots
    edge = _pair_conflicts(
        members, np.repeat(np.arange(sizes.size), sizes), member_start, start, occ_start,
        occurrence, adjacency.start, adjacency.neighbours, adjacency.conflict,
    )  # fmt: skip
    _sort_segments(edge, start)
    return edge, start


@numba.njit(cache=True, nogil=True)
def _pair_conflicts(
    members: np.ndarray,  # (K,) int, every clique's members
    owner: np.ndarray,  # (K,) int, the clique of each member slot
    member_start: np.ndarray,  # (Q+1,) int
    start: np.ndarray,  # (Q+1,) int, each clique's first pair
    occ_start: np.ndarray,  # (V+1,) int, CSR of each node's member slots
    occurrence: np.ndarray,  # (K,) int, member slots by node
    adj_start: np.ndarray,  # (V+1,) int, the conflict graph (:class:`_Adjacency`)
    neighbours: np.ndarray,  # (2M,) int
    conflict: np.ndarray,  # (2M,) int
) -> np.ndarray:
    """(E,) the conflict of every member pair, in each clique's pair order ((0, 1), (0, 2),
    ..., (1, 2), ...); -1 where two members are not in conflict."""
    edge = np.empty(start[-1], dtype=np.int64)
    scratch = np.full(adj_start.size - 1, -1, dtype=np.int64)  # (V,) conflict with u, or -1
    for u in range(adj_start.size - 1):
        for k in range(adj_start[u], adj_start[u + 1]):
            scratch[neighbours[k]] = conflict[k]
        for o in range(occ_start[u], occ_start[u + 1]):
            slot = occurrence[o]
            q = owner[slot]
            lo, hi = member_start[q], member_start[q + 1]
            i, size = slot - lo, hi - lo
            k = start[q] + i * size - i * (i + 1) // 2  # pair (i, i + 1)
            for j in range(slot + 1, hi):
                edge[k] = scratch[members[j]]
                k += 1
        for k in range(adj_start[u], adj_start[u + 1]):
            scratch[neighbours[k]] = -1
    return edge
