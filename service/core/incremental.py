"""Incremental evaluation: the costs of single-move neighbours of one base assignment.

Local search evaluates many assignments one move away from the current one
(move m < M reverses conflict m, move M + m flips its type, as in
:meth:`OrientationGraph.feasible`). A move takes one slot (constraint arc) out
of the event graph the evaluator walks (:mod:`service.core.evaluate`) and puts
one in (the other direction's slot, or the same slot with the other type), so
only events downstream of those two targets can change, and usually few of
them do. From the base's least delays, the kernel makes a move in two halves:

* drop: without the old arc, delays downstream of its target may *fall*.
  Events are recomputed from all their in-arcs in the base's topological
  order (one Kahn pass per base; still an order without an arc), and only
  those whose in-arc or predecessor changed, so each is recomputed once, from
  final predecessors;
* add: the new arc can only raise delays. Raising whatever violates a
  constraint, from lower bounds, ends at the least delays in any order; in the
  base's order it is one pass when the neighbour is acyclic (the new arc is
  the only one that order may run backwards, and it fires again only through
  a cycle), so more pops than events means a cycle.

Each recomputed delay is the full evaluator's maximum of the same sums, so
delays and completions are bit-identical to it and the costs equal to rounding
(``avg_delay`` is the base's plus the weighted changes). A neighbour with a
cycle through the new arc, or every neighbour of a base with a (wait-free)
cycle, goes to the full evaluator (Bellman-Ford, its converged flag): the
costs equal the full evaluator's in every case, +inf where it does not
converge. Tabu never needs that: its moves are acyclic (``feasible``).

Measured on the shared 2-core machine under a background benchmark (load
2.7-3.7; command in docs/benchmarks.md, "Incremental evaluation"), 250-robot
stitched problem (1,000 conflicts, 1,629 events), FCFS base, 100 feasible
moves as tabu lists them (binding conflicts first): full evaluator 4.9-15 ms,
incremental 0.86-1.5 ms (median of 15 calls; 6-12x). Tabu, seed 0, 1 s,
interleaved with the previous evaluation of whole neighbours: 160-240 ->
330-690 iterations/s (about 2.3x; now the feasibility checks and the one full
evaluation per iteration of the new current assignment weigh as much as the
neighbours). On a 250-robot warehouse (wh_two_way, 21,835 conflicts) a move
changes ~1,800 of 6,961 events on average, so the gain is smaller: 100 moves
in 41-86 ms instead of 196-220 ms.
"""

from __future__ import annotations

import numba
import numpy as np

from service.core.assignment import Assignments
from service.core.evaluate import Evaluation, Evaluator, costs_from_completion
from service.core.schemas import OBJECTIVES, Objective

__all__ = ["IncrementalEvaluator", "apply_moves"]

SETTLED, CYCLE, CUT = 0, 1, 2  # how a move's raise ended (_raise)


def apply_moves(base: Assignments, moves: np.ndarray) -> Assignments:
    """The assignments one move away from the single assignment ``base``.

    Shapes: moves (K,) in 0..2M-1 -> K assignments.
    """
    n_conf = base.a_first.shape[1]
    rows = np.arange(moves.size)
    a_first = np.repeat(base.a_first, moves.size, axis=0)  # (K, M)
    following = np.repeat(base.following, moves.size, axis=0)  # (K, M)
    flip_dir, conflict = moves < n_conf, moves % n_conf
    a_first[rows[flip_dir], conflict[flip_dir]] ^= True
    following[rows[~flip_dir], conflict[~flip_dir]] ^= True
    return Assignments(a_first, following)


@numba.njit(cache=True, nogil=True)
def _group(keys: np.ndarray, n_keys: int) -> tuple[np.ndarray, np.ndarray]:
    """Counting sort of ``keys`` in 0..n_keys-1 -> (start (n_keys+1,), positions grouped by key).

    The positions of key k are items[start[k] : start[k + 1]], in their order in ``keys``.
    """
    start = np.zeros(n_keys + 2, dtype=np.int64)
    for key in keys:
        start[key + 2] += 1
    for k in range(n_keys):
        start[k + 2] += start[k + 1]
    items = np.empty(keys.size, dtype=np.int64)
    for i in range(keys.size):
        items[start[keys[i] + 1]] = i
        start[keys[i] + 1] += 1
    return start[: n_keys + 1], items


@numba.njit(cache=True, nogil=True)
def _base_arcs(a_first: np.ndarray, kinds: np.ndarray, graph: tuple) -> tuple:
    """The base's constraint arcs: (out_start (E+1,), out_slot, in_start (E+1,), in_slot).

    Its applying slots grouped by the event they read (not by the constant
    "no event") and by the event they constrain; realized conflicts have none.
    """
    target, source, live = graph[2], graph[3], graph[5]
    n_events = graph[0].size
    slots = 2 * np.arange(a_first.size) + a_first  # (M,) slot 2c+1 when a passes first
    slots = slots[live[slots]]
    read = np.empty(slots.size, dtype=np.int64)  # the event each slot reads
    for i, j in enumerate(slots):
        read[i] = source[kinds[j >> 1], j]
    reading = read < n_events
    out_start, by_source = _group(read[reading], n_events)
    in_start, by_target = _group(target[slots], n_events)
    return out_start, slots[reading][by_source], in_start, slots[by_target]


@numba.njit(cache=True, nogil=True)
def _topological_order(
    chain_next: np.ndarray,  # (E,)
    target: np.ndarray,  # (2M,)
    out_start: np.ndarray,  # (E+1,) the base's slots reading each event: out_slot[...]
    out_slot: np.ndarray,
) -> np.ndarray:
    """Kahn over the base's event graph -> its events in a topological order (fewer than E
    when a cycle keeps some out)."""
    n_events = chain_next.size
    indeg = np.zeros(n_events, dtype=np.int64)
    for j in out_slot:
        indeg[target[j]] += 1
    for e in range(n_events):
        if chain_next[e] >= 0:
            indeg[chain_next[e]] += 1
    order = np.empty(n_events, dtype=np.int64)
    tail = 0
    for e in range(n_events):
        if indeg[e] == 0:
            order[tail] = e
            tail += 1
    head = 0
    while head < tail:
        u = order[head]
        head += 1
        for j in out_slot[out_start[u] : out_start[u + 1]]:
            indeg[target[j]] -= 1
            if indeg[target[j]] == 0:
                order[tail] = target[j]
                tail += 1
        if chain_next[u] >= 0:
            indeg[chain_next[u]] -= 1
            if indeg[chain_next[u]] == 0:
                order[tail] = chain_next[u]
                tail += 1
    return order[:tail]


@numba.njit(cache=True, nogil=True, inline="always")
def _enqueue(v: int, scratch: tuple, rank: np.ndarray, size: int) -> int:
    """Put event v in the heap (keyed by its rank) unless it is there -> the heap's size."""
    heap, queued = scratch[0], scratch[1]
    if queued[v]:
        return size
    queued[v] = True
    i = size
    while i > 0 and heap[(i - 1) >> 1] > rank[v]:
        heap[i] = heap[(i - 1) >> 1]
        i = (i - 1) >> 1
    heap[i] = rank[v]
    return size + 1


@numba.njit(cache=True, nogil=True, inline="always")
def _dequeue(scratch: tuple, order: np.ndarray, size: int) -> tuple[int, int]:
    """Take the event of least rank out of the heap -> (that event, the heap's size)."""
    heap, queued = scratch[0], scratch[1]
    top, size = heap[0], size - 1
    last, i = heap[size], 0
    while 2 * i + 1 < size:
        child = 2 * i + 1
        if child + 1 < size and heap[child + 1] < heap[child]:
            child += 1
        if heap[child] >= last:
            break
        heap[i] = heap[child]
        i = child
    heap[i] = last
    queued[order[top]] = False
    return order[top], size


@numba.njit(cache=True, nogil=True, inline="always")
def _set(v: int, value: float, work: np.ndarray, scratch: tuple, n_changed: int) -> int:
    """work[v] = value, listing v among the changed events (once) -> how many are listed."""
    touched, changed = scratch[2], scratch[3]
    work[v] = value
    if touched[v]:
        return n_changed
    touched[v] = True
    changed[n_changed] = v
    return n_changed + 1


@numba.njit(cache=True, nogil=True)
def _lower(
    seed: int,  # target of the dropped slot
    moved: int,
    kinds: np.ndarray,  # (M,) int, 1 where the base is following-type
    graph: tuple,  # IncrementalEvaluator._graph
    arcs: tuple,  # _base_arcs(), then rank and order
    scratch: tuple,  # heap, queued, touched, changed
    work: np.ndarray,  # (E+1,) the base's delays on entry, without conflict ``moved`` on exit
) -> int:
    """Drop conflict ``moved``'s constraint and recompute what may fall -> events changed.

    Only events whose in-arc or predecessor changed are recomputed, from all their
    in-arcs, in the base's topological order (still one without the dropped arc),
    so each is recomputed once and from final predecessors.
    """
    chain_next, chain_prev, target, source, offset = graph[:5]
    out_start, out_slot, in_start, in_slot, rank, order = arcs
    size, n_changed = _enqueue(seed, scratch, rank, 0), 0
    while size:
        v, size = _dequeue(scratch, order, size)
        value = 0.0  # the full evaluator's maximum over the same in-arcs
        if chain_prev[v] >= 0:
            value = max(value, work[chain_prev[v]])
        for j in in_slot[in_start[v] : in_start[v + 1]]:
            if j >> 1 != moved:
                value = max(value, work[source[kinds[j >> 1], j]] + offset[kinds[j >> 1], j])
        if value == work[v]:
            continue
        n_changed = _set(v, value, work, scratch, n_changed)
        if chain_next[v] >= 0:
            size = _enqueue(chain_next[v], scratch, rank, size)
        for j in out_slot[out_start[v] : out_start[v + 1]]:
            if j >> 1 != moved:
                size = _enqueue(target[j], scratch, rank, size)
    return n_changed


@numba.njit(cache=True, nogil=True)
def _raise(
    added: int,  # the slot the move adds
    kind: int,  # its type: 1 following
    kinds: np.ndarray,  # (M,) int, 1 where the base is following-type
    graph: tuple,  # IncrementalEvaluator._graph
    arcs: tuple,  # _base_arcs(), then rank and order
    scratch: tuple,  # heap, queued, touched, changed
    work: np.ndarray,  # (E+1,) delays without the moved conflict; the neighbour's on exit
    n_changed: int,
    cut: tuple,  # (cut_weight (E+1,) >= 0, change so far, limit): see _move_costs
) -> tuple[int, int, float]:
    """Add the moved slot and raise what it pushes up -> (events changed so far, SETTLED,
    CYCLE (one of positive length, or so it is treated) or CUT (the weighted change
    passed the limit: the neighbour costs more than that, and the raise stops there),
    the weighted change).

    Raising only to satisfy violated constraints, from values that are lower
    bounds, ends at the least delays whatever the order; the base's topological
    order makes it one pass when the neighbour is acyclic (the added arc is the
    only one it may run backwards, and it fires again only through a cycle),
    so more pops than events means a cycle. Delays only rise here, so the weighted
    change only grows: past the limit it stays past it.
    """
    chain_next, target, source, offset = graph[0], graph[2], graph[3], graph[4]
    out_start, out_slot, rank, order = arcs[0], arcs[1], arcs[4], arcs[5]
    cut_weight, change, limit = cut
    moved, reads, held = added >> 1, source[kind, added], target[added]
    if work[reads] + offset[kind, added] <= work[held]:
        return n_changed, SETTLED, change
    change += cut_weight[held] * (work[reads] + offset[kind, added] - work[held])
    n_changed = _set(held, work[reads] + offset[kind, added], work, scratch, n_changed)
    size, pops = _enqueue(held, scratch, rank, 0), 0
    while size:
        u, size = _dequeue(scratch, order, size)
        pops += 1
        if pops > chain_next.size or change > limit:
            while size:
                _, size = _dequeue(scratch, order, size)
            return n_changed, CUT if change > limit else CYCLE, change
        if chain_next[u] >= 0 and work[u] > work[chain_next[u]]:
            change += cut_weight[chain_next[u]] * (work[u] - work[chain_next[u]])
            n_changed = _set(chain_next[u], work[u], work, scratch, n_changed)
            size = _enqueue(chain_next[u], scratch, rank, size)
        for j in out_slot[out_start[u] : out_start[u + 1]]:
            if j >> 1 == moved:
                continue
            value = work[u] + offset[kinds[j >> 1], j]
            if value > work[target[j]]:
                change += cut_weight[target[j]] * (value - work[target[j]])
                n_changed = _set(target[j], value, work, scratch, n_changed)
                size = _enqueue(target[j], scratch, rank, size)
        if u == reads and work[u] + offset[kind, added] > work[held]:
            change += cut_weight[held] * (work[u] + offset[kind, added] - work[held])
            n_changed = _set(held, work[u] + offset[kind, added], work, scratch, n_changed)
            size = _enqueue(held, scratch, rank, size)
    return n_changed, SETTLED if change <= limit else CUT, change


@numba.njit(cache=True, nogil=True)
def _move_costs(
    moves: np.ndarray,  # (K,) int
    a_first: np.ndarray,  # (M,) int, 1 where a passes first in the base
    kinds: np.ndarray,  # (M,) int, 1 where the base is following-type
    base: np.ndarray,  # (E+1,) least delays of the base (last: 0, no event)
    graph: tuple,  # IncrementalEvaluator._graph
    completion: np.ndarray,  # (K, R) the base's completion on entry, each neighbour's on exit
    delay_change: np.ndarray,  # (K,) zeros on entry; weighted delay change (avg_delay) on exit
    unsettled: np.ndarray,  # (K,) False on entry; True where the kernel could not tell
    cutoff: tuple,  # (cut_weight (E+1,) >= 0, tabu (K,) bool, best change, tolerance)
    cut: np.ndarray,  # (K,) False on entry; True where a move was left uncosted (below)
) -> None:
    """Each move as a drop (lower) then an add (raise), costed, then undone.

    Cutoff (tabu search's choice, :meth:`IncrementalEvaluator.best_move`): the cost change
    is sum(cut_weight * delay change); a move is *admissible* if not ``tabu`` or its change
    is below the best change (aspiration). A move's raise stops (``cut``) once its change
    passes the least change of the admissible moves costed before it (for a tabu move,
    also the best change), plus the tolerance: it cannot be the cheapest admissible one.
    All-zero weights and an infinite best cut nothing.
    """
    cut_weight, tabu, best_change, tol = cutoff
    least = np.inf  # least change of an admissible move so far
    chain_next, target, live, last_robot, free, weight = (
        graph[0], graph[2], graph[5], graph[6], graph[7], graph[8],
    )  # fmt: skip
    n_events, n_conf = chain_next.size, a_first.size
    out_start, out_slot, in_start, in_slot = _base_arcs(a_first, kinds, graph)
    order = _topological_order(chain_next, target, out_start, out_slot)
    if order.size < n_events:
        unsettled[:] = True  # a (wait-free) cycle in the base: no order to follow
        return
    rank = np.empty(n_events, dtype=np.int64)
    rank[order] = np.arange(n_events)
    arcs = (out_start, out_slot, in_start, in_slot, rank, order)
    scratch = (
        np.empty(n_events, dtype=np.int64),  # heap of the ranks of the events to process
        np.zeros(n_events, dtype=np.bool_),  # queued: in the heap
        np.zeros(n_events, dtype=np.bool_),  # touched: listed in changed
        np.empty(n_events, dtype=np.int64),  # changed: events whose delay changed
    )
    touched, changed = scratch[2], scratch[3]
    work = base.copy()  # (E+1,)
    for k in range(moves.size):
        moved = moves[k] % n_conf
        dropped = 2 * moved + a_first[moved]
        if not live[dropped]:  # a realized conflict constrains nothing either way
            continue
        reverse = moves[k] < n_conf
        n_changed = _lower(target[dropped], moved, kinds, graph, arcs, scratch, work)
        change = 0.0
        for v in changed[:n_changed]:
            change += cut_weight[v] * (work[v] - base[v])
        limit = (least if not tabu[k] else min(least, best_change)) + tol
        n_changed, status, change = _raise(
            dropped ^ 1 if reverse else dropped,
            kinds[moved] if reverse else 1 - kinds[moved],
            kinds, graph, arcs, scratch, work, n_changed, (cut_weight, change, limit),
        )  # fmt: skip
        unsettled[k] = status == CYCLE
        cut[k] = status == CUT
        if status == SETTLED and (not tabu[k] or change < best_change - tol):
            least = min(least, change)
        for v in changed[:n_changed]:
            if last_robot[v] >= 0:
                completion[k, last_robot[v]] = free[last_robot[v]] + work[v]
            delay_change[k] += (work[v] - base[v]) * weight[v]
            work[v] = base[v]
            touched[v] = False


class IncrementalEvaluator:
    """Costs of single-move neighbours of one evaluated assignment (build once per problem).

    Shares the slot arrays of ``evaluator`` (the constraints are defined once, there).
    """

    def __init__(self, evaluator: Evaluator) -> None:
        self.evaluator = evaluator
        problem = evaluator.problem
        n_events = evaluator.n_events
        graph = evaluator.graph
        chain_next, chain_prev = graph.chain_next, graph.chain_prev()  # (E,) each
        last_robot = np.full(n_events + 1, -1, dtype=np.int64)  # (E+1,) robot ending there
        last_robot[graph.last_event] = np.arange(problem.n_robots)
        last_robot[n_events] = -1  # robots without events never change
        # What every kernel reads: chain_next (E,), chain_prev (E,), target (2M,), source and
        # offset (2, 2M) by type (0 exclusive, 1 following), live (2M,), last_robot (E+1,),
        # completion without delay (R,), avg_delay weight (E+1,).
        self._graph = (
            chain_next, chain_prev, graph.target, graph.source, graph.offset, graph.live,
            last_robot, problem.tp_time[problem.last_tp], graph.delay_weight,
        )  # fmt: skip
        # best_move's cutoff for the costs that are weighted sums of delay changes: per
        # objective (cost units per weighted change, weights (E+1,)). The sum of
        # completions moves with robots' last events; avg_delay has its own weights.
        self._last_weight = (last_robot >= 0).astype(np.float64)
        self._cut_weights = {
            "avg_completion": (float(problem.n_robots), self._last_weight),
            "avg_delay": (1.0, np.asarray(graph.delay_weight, dtype=np.float64)),
        }
        self._no_weight = np.zeros(n_events + 1)

    def costs(
        self, base: Assignments, evaluation: Evaluation, moves: np.ndarray, sample: int = 0
    ) -> dict[Objective, np.ndarray]:
        """All four costs of the neighbours of ``base``'s ``sample`` reached by ``moves``.

        ``evaluation`` is the full evaluator's answer for ``base``; the sample
        must have converged (finite least delays). Equal to
        ``evaluator.evaluate(apply_moves(base.take(sample), moves)).costs``
        (+inf for neighbours whose constraint graph has a positive cycle).
        Shapes: moves (K,) in 0..2M-1 -> costs[objective] (K,).
        """
        moves = np.asarray(moves, dtype=np.int64)
        no_cut = (self._no_weight, np.zeros(moves.size, dtype=np.bool_), np.inf, 0.0)
        return self._costs(base, evaluation, moves, sample, no_cut)[0]

    def best_move(
        self,
        base: Assignments,
        evaluation: Evaluation,
        moves: np.ndarray,
        objective: Objective,
        tabu: np.ndarray,
        best_cost: float,
    ) -> tuple[int, float] | None:
        """Tabu search's choice among the neighbours of the single ``base`` reached by
        ``moves``: the cheapest *admissible* one (not ``tabu`` (K,) bool, or cheaper than
        ``best_cost``: aspiration), the first on ties -> (its index in ``moves``, its
        cost), or None if none is admissible.

        The same choice as :meth:`costs` then the rule, but for avg_completion and
        avg_delay (costs that are weighted sums of delays) a move stops being costed once
        its cost passes the cheapest admissible move costed before it: in the second
        half of a move delays only rise. On a 250-robot warehouse most candidate moves
        cost more than the best of them, and propagating them whole was most of the time.
        """
        moves = np.asarray(moves, dtype=np.int64)
        cost = float(evaluation.costs[objective][0])
        if objective not in self._cut_weights:  # not a weighted sum: cost every move whole
            cutoff = (self._no_weight, tabu, np.inf, 0.0)
        else:
            scale, weight = self._cut_weights[objective]
            best_change = scale * (best_cost - cost)
            tol = 1e-9 * (1.0 + scale * abs(cost) + abs(best_change))
            cutoff = (weight, tabu, best_change, tol)
        costs, cut = self._costs(base, evaluation, moves, 0, cutoff)
        found = np.where(cut, np.inf, costs[objective])  # (K,)
        admissible = ~tabu | (found < best_cost)
        if not admissible.any():
            return None
        k = int(np.flatnonzero(admissible)[np.argmin(found[admissible])])
        return k, float(found[k])

    def _costs(
        self,
        base: Assignments,
        evaluation: Evaluation,
        moves: np.ndarray,
        sample: int,
        cutoff: tuple,
    ) -> tuple[dict[Objective, np.ndarray], np.ndarray]:
        """Every cost of each move's neighbour (K,) and which moves the cutoff left
        uncosted (K,) bool, their costs then meaningless (see :func:`_move_costs`)."""
        if not evaluation.converged[sample]:
            raise ValueError("the base assignment has no least times (a positive cycle)")
        completion = np.repeat(evaluation.completion[sample : sample + 1], moves.size, axis=0)
        delay_change = np.zeros(moves.size)  # (K,)
        unsettled = np.zeros(moves.size, dtype=np.bool_)  # (K,)
        cut = np.zeros(moves.size, dtype=np.bool_)  # (K,)
        _move_costs(
            moves, base.a_first[sample].astype(np.int64), base.following[sample].astype(np.int64),
            evaluation.event_delay[sample], self._graph, completion, delay_change, unsettled,
            cutoff, cut,
        )  # fmt: skip
        costs = costs_from_completion(completion)
        costs["avg_delay"] = evaluation.costs["avg_delay"][sample] + delay_change
        if unsettled.any():  # cycles: the full evaluator's Bellman-Ford tells
            full = self.evaluator.evaluate(apply_moves(base.take(sample), moves[unsettled]))
            for k in OBJECTIVES:
                costs[k][unsettled] = full.costs[k]
        return {k: costs[k] for k in OBJECTIVES}, cut
