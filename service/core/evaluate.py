"""The one evaluator: least updated times and all four costs, for many assignments at once.

Updated times T~ are the least values with T~(1) >= T(1), a robot's delay
D = T~ - T never decreasing along its path, and T~_to(pair_enter) >= T~_from(pair_exit)
(exclusive) or >= T~_from(pair_enter) (following) for every conflict: a longest
path on a DAG. Delays only rise at *events*, the distinct pair-enter time
points of each robot (the only targets of conflict constraints), so the graph
the evaluator walks has one vertex per event: chain arcs along each robot and
one arc per conflict, from the event at or before the source time point of the
side passing first to the pair-enter event of the other side.

The published GNN-VAE was bottlenecked by evaluating its 100 samples per
request; a vectorized numpy relaxation measured 89 ms for 100 assignments of a
250-robot, 1000-conflict graph on this project's 2-core machine (target
20 ms), so the walk is a numba-compiled topological sort (Kahn), run per
sample without the GIL. It reads each sample's directions and types as they are
(S, M) and builds its arcs itself: building (S, 2M) source and offset arrays in
numpy first cost 20-30 % of a batch of 8 on 250-robot warehouses, and walking
one arc per conflict instead of filtering 2M slots made the walk 1.3-2x faster
(8 samples of a two-way warehouse of 250 robots, 21,835 conflicts: 9.6 -> 4.7 ms).
Grouping each arc's target and offset by source event (not its slot), so that the
walk reads them in order, made it 1.4-1.6x faster again on warehouses of 100-250
robots (the same 8 samples: 4.4 -> 2.8 ms). Candidates that each reverse a few
conflicts of one assignment (:meth:`Evaluator.evaluate_flips`) share its grouped
arcs: 1.6 ms for those 8 when each is one robot's priority shift.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from service.core.assignment import Assignments
from service.core.problem import Problem
from service.core.schemas import OBJECTIVES, Objective
from service.core.threads import in_parts

__all__ = [
    "MONOTONE_OBJECTIVES",
    "ConstraintGraph",
    "Evaluation",
    "Evaluator",
    "costs_from_completion",
]

# Objectives that never fall when a delay rises (sync_completion, the mean completion plus
# the spread, may: a robot delayed toward the mean narrows the spread).
MONOTONE_OBJECTIVES: tuple[Objective, ...] = ("avg_completion", "max_completion", "avg_delay")

# Least work (conflicts x samples) worth a thread of its own: below it, handing a share
# of the samples to another thread costs more than walking them here.
MIN_THREAD_WORK = 16_384

# What :func:`_least_and_latest` walked: the constraint graph has a cycle; the least delays
# only (their sum reached the bound it was given); the least and the latest delays.
CYCLIC, WALKED_FORWARD, WALKED_BOTH = 0, 1, 2
# A sum's bound in :meth:`Evaluator.evaluate_with_latest` is raised by this share of its
# size (and as much again absolute), so that the kernel's sum, added in another order
# than the cost's, skips the latest only of answers that the cost finds not cheaper.
SUM_MARGIN = 1e-9


@dataclass(frozen=True, eq=False)
class Evaluation:
    """Least updated times of S assignments.

    Shapes: event_delay (S, E+1) delay at every event (last column: the zero
    delay of time points before any event); completion (S, R);
    costs[objective] (S,); converged (S,) bool, False only for assignments whose
    constraint graph has a cycle (their costs are +inf).
    """

    event_delay: np.ndarray
    completion: np.ndarray
    costs: dict[Objective, np.ndarray]
    converged: np.ndarray


@dataclass(frozen=True, eq=False)
class ConstraintGraph:
    """The event graph the evaluator walks, for evaluators that re-walk part of it
    (:mod:`service.core.incremental`) with the same constraint definitions.

    Shapes: E events, M conflicts (slot 2c+s constrains side s of conflict c), R robots.
    """

    chain_next: np.ndarray  # (E,) next event of the same robot, or -1
    target: np.ndarray  # (2M,) event each slot constrains
    source: np.ndarray  # (2, 2M) event each slot reads, by type (0 exclusive, 1 following)
    offset: np.ndarray  # (2, 2M) T(source) - T(target), by type
    live: np.ndarray  # (2M,) bool, False for the slots of realized conflicts
    last_event: np.ndarray  # (R,) each robot's completion event (E: none)
    delay_weight: np.ndarray  # (E+1,) avg_delay = event delays @ delay_weight

    def chain_prev(self) -> np.ndarray:
        """(E,) each event's previous event of the same robot, or -1."""
        prev = np.full(self.chain_next.size, -1, dtype=np.int64)
        has_next = self.chain_next >= 0
        prev[self.chain_next[has_next]] = np.flatnonzero(has_next)
        return prev


def costs_from_completion(completion: np.ndarray) -> dict[str, np.ndarray]:
    """avg, max and sync completion from (S, R) completion times -> (S,) each, a row's
    the same whatever the batch around it (see :func:`_completion_sums`)."""
    completion = np.ascontiguousarray(completion, dtype=np.float64)
    avg, spread = _completion_sums(completion)
    return {
        "avg_completion": avg,
        "max_completion": completion.max(axis=1),
        "sync_completion": avg + spread,
    }


@numba.njit(cache=True, nogil=True)
def _completion_sums(completion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(S, R) completions -> their mean (S,) and mean absolute deviation from it (S,),
    each summed in index order as :func:`_row_sums` (one compiled call: the sums and
    their temporaries in numpy took ~15 us of every re-insertion step's evaluation)."""
    n_samples, n_robots = completion.shape
    avg, spread = np.zeros(n_samples), np.zeros(n_samples)
    for s in range(n_samples):
        for r in range(n_robots):
            avg[s] += completion[s, r]
        avg[s] /= max(n_robots, 1)
        for r in range(n_robots):
            spread[s] += abs(completion[s, r] - avg[s])
        spread[s] /= max(n_robots, 1)
    return avg, spread


@numba.njit(cache=True, nogil=True)
def _row_sums(x: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """(S,) each row of ``x`` (S, N) weighed by ``weight`` (N,), summed in index order: the
    same number for a row whatever the batch around it (a matrix product's summation order
    depends on the batch's shape, and a sample's cost then differed in its last bit from
    the same answer's alone)."""
    out = np.zeros(x.shape[0])
    for s in range(x.shape[0]):
        for n in range(x.shape[1]):
            out[s] += x[s, n] * weight[n]
    return out


@numba.njit(cache=True, nogil=True)
def _group_arcs(
    target: np.ndarray,  # (2M,) int, event constrained by slot j
    source: np.ndarray,  # (2, 2M) int, event read by slot j, by type (E = zero delay)
    offset: np.ndarray,  # (2, 2M) float, T(source time point) - T(target time point)
    live: np.ndarray,  # (2M,) bool, False for the slots of realized conflicts
    a_first: np.ndarray,  # (M,) uint8 of one sample
    following: np.ndarray,  # (M,) uint8 of one sample
    chain_indeg: np.ndarray,  # (E,) int, 1 for every event with a previous one, else 0
    indeg: np.ndarray,  # (E+1,) int, out: in-degrees (chain and conflict arcs)
    out_start: np.ndarray,  # (E+3,) int, out: arcs of source e at out_start[e]:out_start[e+1]
    out_to: np.ndarray,  # (M,) int, out: each arc's target event, grouped by source
    out_off: np.ndarray,  # (M,) float, out: each arc's offset, in the same order
    arc_of: np.ndarray,  # (M,) int, out: conflict c's arc position (-1: realized, no arc)
) -> None:
    """One sample's conflict arcs grouped by source event (a counting sort): conflict c
    constrains through slot 2c + a_first[c] with type following[c].

    Source E is the zero delay of time points before any event (walked first), so every
    conflict is one arc, and an evaluation that reverses a few conflicts of this sample
    (:func:`_longest_paths_flipped`) can take exactly their arcs out. The walk then reads
    each arc's target and offset in order, not through its slot: 1.4-1.6x faster on
    warehouses of 100-250 robots than reading target[j] and offset[t, j] while walking.
    """
    n_conflicts = a_first.size
    indeg[:-1] = chain_indeg
    indeg[-1] = 0
    out_start[:] = 0
    for c in range(n_conflicts):  # count arcs per source; arc_of holds each one's source
        j = 2 * c + a_first[c]
        arc_of[c] = -1
        if live[j]:
            src = source[following[c], j]
            arc_of[c] = src
            indeg[target[j]] += 1
            out_start[src + 2] += 1
    for e in range(out_start.size - 2):
        out_start[e + 2] += out_start[e + 1]
    for c in range(n_conflicts):
        src = arc_of[c]
        if src >= 0:
            j = 2 * c + a_first[c]
            pos = out_start[src + 1]
            out_to[pos] = target[j]
            out_off[pos] = offset[following[c], j]
            out_start[src + 1] = pos + 1
            arc_of[c] = pos


@numba.njit(cache=True, nogil=True)
def _arc_arrays(n_events: int, n_conflicts: int) -> tuple:
    """Empty outputs of :func:`_group_arcs`: indeg (E+1,), out_start (E+3,), out_to (M,),
    out_off (M,), arc_of (M,)."""
    return (
        np.empty(n_events + 1, dtype=np.int64),
        np.empty(n_events + 3, dtype=np.int64),
        np.empty(n_conflicts, dtype=np.int64),
        np.empty(n_conflicts, dtype=np.float64),
        np.empty(n_conflicts, dtype=np.int64),
    )


@numba.njit(cache=True, nogil=True)
def _walk_arcs(
    chain_next: np.ndarray,  # (E,) int, next event of the same robot or -1
    indeg: np.ndarray,  # (E+1,) int, consumed
    out_start: np.ndarray,  # (E+3,) int, from _group_arcs
    out_to: np.ndarray,  # (M,) int
    out_off: np.ndarray,  # (M,) float
    removed: np.ndarray,  # (M,) int, arc k is left out where removed[k] == stamp
    stamp: int,
    extra_head: np.ndarray,  # (E+1,) int, first extra arc of each source, -1: none
    extra_next: np.ndarray,  # (X,) int, next extra arc of the same source, -1: none
    extra_to: np.ndarray,  # (X,) int
    extra_off: np.ndarray,  # (X,) float
    d: np.ndarray,  # (E+1,) float, zeros (or lower bounds) on entry, least delays on exit
    queue: np.ndarray,  # (E+1,) int, scratch
) -> bool:  # every event reached (the constraint graph is acyclic)
    """Kahn's walk from the zero-delay source E over the grouped arcs (less the removed,
    plus the extra) and the robots' chains."""
    n_events = chain_next.size
    queue[0] = n_events
    tail = 1
    for e in range(n_events):
        if indeg[e] == 0:
            queue[tail] = e
            tail += 1
    head = 0
    while head < tail:
        e = queue[head]
        head += 1
        de = d[e]
        # Out of e: its grouped arcs (k), then its extra ones (i), then its chain arc.
        k, end, i = out_start[e], out_start[e + 1], extra_head[e]
        chain = chain_next[e] if e < n_events else -1
        while True:
            if k < end:
                k += 1
                if removed[k - 1] == stamp:
                    continue
                u, value = out_to[k - 1], de + out_off[k - 1]
            elif i >= 0:
                u, value, i = extra_to[i], de + extra_off[i], extra_next[i]
            elif chain >= 0:
                u, value, chain = chain, de, -1
            else:
                break
            d[u] = max(d[u], value)  # every arc into u raises it; u goes once all are in
            indeg[u] -= 1
            if indeg[u] == 0:
                queue[tail] = u
                tail += 1
    return tail == n_events + 1


@numba.njit(cache=True, nogil=True)
def _longest_paths(
    chain_next: np.ndarray,  # (E,) int, next event of the same robot or -1
    chain_indeg: np.ndarray,  # (E,) int, 1 for every event with a previous one, else 0
    target: np.ndarray,  # (2M,) int, event constrained by slot j
    source: np.ndarray,  # (2, 2M) int, event read by slot j, by type (E = zero delay)
    offset: np.ndarray,  # (2, 2M) float, T(source time point) - T(target time point)
    live: np.ndarray,  # (2M,) bool, False for the slots of realized conflicts
    a_first: np.ndarray,  # (S, M) uint8, side a of conflict c passes first in sample s
    following: np.ndarray,  # (S, M) uint8, conflict c is following in sample s
    delay: np.ndarray,  # (S, E+1) float, zeros on entry; least delays on exit
) -> np.ndarray:  # (S,) bool, every event reached (the constraint graph is acyclic)
    """Kahn's walk per sample over the arcs of its conflicts' slots and types."""
    n_samples, n_conflicts = a_first.shape
    n_events = chain_next.size
    converged = np.ones(n_samples, dtype=np.bool_)
    indeg, out_start, out_to, out_off, arc_of = _arc_arrays(n_events, n_conflicts)
    removed = np.full(n_conflicts, -1, dtype=np.int64)  # nothing left out
    extra_head = np.full(n_events + 1, -1, dtype=np.int64)  # nothing added
    no_extra = np.empty(0, dtype=np.int64)
    queue = np.empty(n_events + 1, dtype=np.int64)
    for s in range(n_samples):
        _group_arcs(
            target, source, offset, live, a_first[s], following[s], chain_indeg,
            indeg, out_start, out_to, out_off, arc_of,
        )  # fmt: skip
        reached = _walk_arcs(
            chain_next, indeg, out_start, out_to, out_off, removed, 0,
            extra_head, no_extra, no_extra, out_off[:0], delay[s], queue,
        )  # fmt: skip
        if not reached:  # least times exist only if no cycle forces a wait
            converged[s] = _relax_cyclic(
                chain_next, target, source, offset, live, a_first[s], following[s], delay[s]
            )
    return converged


@numba.njit(cache=True, nogil=True)
def _longest_paths_flipped(
    chain_next: np.ndarray,  # (E,) int
    chain_indeg: np.ndarray,  # (E,) int
    target: np.ndarray,  # (2M,) int
    source: np.ndarray,  # (2, 2M) int
    offset: np.ndarray,  # (2, 2M) float
    live: np.ndarray,  # (2M,) bool
    a_first: np.ndarray,  # (M,) uint8, the base sample's directions
    following: np.ndarray,  # (M,) uint8, the base sample's types (every candidate's)
    start: np.ndarray,  # (C+1,) int, candidate s reverses flipped[start[s]:start[s+1]]
    flipped: np.ndarray,  # (K,) int, conflicts, distinct within each candidate
    delay: np.ndarray,  # (C, E+1) float, zeros on entry; least delays on exit
) -> np.ndarray:  # (C,) bool, every event reached
    """:func:`_longest_paths` of candidates that each reverse a few conflicts of one base
    sample: the base's arcs are grouped once, and each candidate's walk leaves out the
    arcs of its reversed conflicts and adds their other slots' arcs (the same arcs, so
    the same numbers, as grouping the candidate's own)."""
    n_conflicts = a_first.size
    n_events = chain_next.size
    n_candidates = start.size - 1
    converged = np.ones(n_candidates, dtype=np.bool_)
    base_indeg, out_start, out_to, out_off, arc_of = _arc_arrays(n_events, n_conflicts)
    _group_arcs(
        target, source, offset, live, a_first, following, chain_indeg,
        base_indeg, out_start, out_to, out_off, arc_of,
    )  # fmt: skip
    most = 0
    for s in range(n_candidates):
        most = max(most, start[s + 1] - start[s])
    removed = np.full(n_conflicts, -1, dtype=np.int64)
    extra_head = np.full(n_events + 1, -1, dtype=np.int64)
    extra_next = np.empty(most, dtype=np.int64)
    extra_to = np.empty(most, dtype=np.int64)
    extra_off = np.empty(most, dtype=np.float64)
    indeg = np.empty(n_events + 1, dtype=np.int64)
    queue = np.empty(n_events + 1, dtype=np.int64)
    for s in range(n_candidates):
        indeg[:] = base_indeg
        n_extra = 0
        for i in range(start[s], start[s + 1]):
            c = flipped[i]
            old = 2 * c + a_first[c]
            if not live[old]:  # realized: neither slot constrains
                continue
            if removed[arc_of[c]] == s:
                raise ValueError("a candidate lists a conflict twice")
            removed[arc_of[c]] = s
            indeg[target[old]] -= 1
            j, t = old ^ 1, following[c]
            extra_to[n_extra] = target[j]
            extra_off[n_extra] = offset[t, j]
            extra_next[n_extra] = extra_head[source[t, j]]
            extra_head[source[t, j]] = n_extra
            indeg[target[j]] += 1
            n_extra += 1
        reached = _walk_arcs(
            chain_next, indeg, out_start, out_to, out_off, removed, s,
            extra_head, extra_next, extra_to, extra_off, delay[s], queue,
        )  # fmt: skip
        for i in range(start[s], start[s + 1]):
            c = flipped[i]
            extra_head[source[following[c], 2 * c + 1 - a_first[c]]] = -1
        if not reached:
            own = a_first.copy()
            for i in range(start[s], start[s + 1]):
                own[flipped[i]] ^= 1
            converged[s] = _relax_cyclic(
                chain_next, target, source, offset, live, own, following, delay[s]
            )
    return converged


@numba.njit(cache=True, nogil=True)
def _relax_cyclic(
    chain_next: np.ndarray,  # (E,)
    target: np.ndarray,  # (2M,)
    source: np.ndarray,  # (2, 2M) by type
    offset: np.ndarray,  # (2, 2M) by type
    live: np.ndarray,  # (2M,)
    a_first: np.ndarray,  # (M,) of one sample
    following: np.ndarray,  # (M,) of one sample
    d: np.ndarray,  # (E+1,) lower bounds on entry, least delays on exit if they exist
) -> bool:
    """Bellman-Ford sweeps for a cyclic constraint graph: True if a fixpoint is reached.

    Only invalid (node-cyclic) assignments get here; it reports their least
    times when every cycle is wait-free, as the contract defines them.
    """
    n_events = chain_next.size
    for _ in range(n_events + 1):
        changed = False
        for c in range(a_first.size):
            j = 2 * c + a_first[c]
            if live[j]:
                t = following[c]
                value = d[source[t, j]] + offset[t, j]
                if value > d[target[j]]:
                    d[target[j]] = value
                    changed = True
        for e in range(n_events):
            nxt = chain_next[e]
            if nxt >= 0 and d[e] > d[nxt]:
                d[nxt] = d[e]
                changed = True
        if not changed:
            return True
    return False


@numba.njit(cache=True, nogil=True)
def _least_and_latest(
    chain_next: np.ndarray,  # (E,) int
    chain_indeg: np.ndarray,  # (E,) int
    target: np.ndarray,  # (2M,) int
    source: np.ndarray,  # (2, 2M) int
    offset: np.ndarray,  # (2, 2M) float
    live: np.ndarray,  # (2M,) bool
    a_first: np.ndarray,  # (M,) uint8 of one sample
    following: np.ndarray,  # (M,) uint8 of one sample
    held: np.ndarray,  # (E+1,) float, > 0: events whose latest delay is their least; weights
    d: np.ndarray,  # (E+1,) float, zeros on entry; least delays on exit
    latest: np.ndarray,  # (E+1,) float, out: latest delays
    slope: np.ndarray,  # (E+1,) float, out: held weight pushed per unit past the latest
    tol: float,  # a successor within this of the latest is pushed with it
    weight: np.ndarray,  # (E+1,) float, the weights of a sum ...
    bound: float,  # ... at or above which the latest are not sought (inf: always sought)
) -> int:  # WALKED_BOTH, or WALKED_FORWARD (over the bound), or CYCLIC (part-walked)
    """One sample's least delays by the forward walk (:func:`_walk_arcs`), then, unless
    their ``weight``-ed sum reaches ``bound`` (a search that keeps only cheaper answers
    needs no more of a dearer one: the backward pass is ~40 % of the call), its latest
    delays by a backward pass in the reverse of that walk's topological order: an
    event's latest is the least of its cap (its least delay if held, else none), its
    chain successor's latest and each arc target's latest less the arc's offset. One
    grouping of the arcs serves both (re-insertion search needs both of every answer it
    keeps: 0.95 + 0.85 ms at 250 robots walked apart). In the same pass each event's
    slope: its held weight plus the slopes of the successors its latest binds (those a
    delay past it pushes past theirs), at most the total held weight: the rise of the
    held weight per unit past the latest, to first order, counting a held event once
    per way to it."""
    n_events, n_conflicts = chain_next.size, a_first.size
    indeg, out_start, out_to, out_off, arc_of = _arc_arrays(n_events, n_conflicts)
    _group_arcs(
        target, source, offset, live, a_first, following, chain_indeg,
        indeg, out_start, out_to, out_off, arc_of,
    )  # fmt: skip
    queue = np.empty(n_events + 1, dtype=np.int64)
    removed = np.full(n_conflicts, -1, dtype=np.int64)
    no_extra = np.full(n_events + 1, -1, dtype=np.int64)
    if not _walk_arcs(
        chain_next, indeg, out_start, out_to, out_off, removed, 0, no_extra,
        no_extra[:0], no_extra[:0], out_off[:0], d, queue,
    ):  # fmt: skip
        return CYCLIC
    if bound < np.inf:
        summed = 0.0
        for e in range(weight.size):  # no (E+1,) temporary
            summed += weight[e] * d[e]
        if summed >= bound:
            return WALKED_FORWARD
    total = held.sum()
    for q in range(n_events, -1, -1):
        e = queue[q]
        value = d[e] if held[e] > 0 else np.inf
        for k in range(out_start[e], out_start[e + 1]):
            value = min(value, latest[out_to[k]] - out_off[k])
        if e < n_events and chain_next[e] >= 0:
            value = min(value, latest[chain_next[e]])
        latest[e] = value
        pushed = held[e]
        for k in range(out_start[e], out_start[e + 1]):
            if latest[out_to[k]] - out_off[k] <= value + tol:
                pushed += slope[out_to[k]]
        if e < n_events and chain_next[e] >= 0 and latest[chain_next[e]] <= value + tol:
            pushed += slope[chain_next[e]]
        slope[e] = min(pushed, total)
    return WALKED_BOTH


@numba.njit(cache=True, nogil=True)
def _binding(
    target: np.ndarray,  # (2M,) int
    source: np.ndarray,  # (2, 2M) int
    offset: np.ndarray,  # (2, 2M) float
    realized: np.ndarray,  # (M,) bool
    a_first: np.ndarray,  # (M,) bool of one sample
    following: np.ndarray,  # (M,) bool of one sample
    delay: np.ndarray,  # (E+1,) float, the sample's least delays
    tol: float,
) -> np.ndarray:  # (M,) bool
    """Conflicts whose active constraint holds with equality and makes its target wait
    (a loop: numpy's gathers over (2, 2M) took 0.8 ms at 250 robots)."""
    out = np.zeros(a_first.size, dtype=np.bool_)
    for c in range(a_first.size):
        j, t = 2 * c + (1 if a_first[c] else 0), 1 if following[c] else 0
        wait = delay[target[j]]
        out[c] = (
            wait > tol and abs(wait - delay[source[t, j]] - offset[t, j]) <= tol and not realized[c]
        )
    return out


class Evaluator:
    """Evaluates batches of assignments of one problem; build once, call many times.

    ``threads`` > 1 walks a large batch's samples in that many shares at once (the same
    numbers: each sample's walk is independent of the others); the solve's share of the
    machine's cores, so it stays 1 where solves run side by side on every core.
    """

    def __init__(self, problem: Problem, threads: int = 1) -> None:
        if threads < 1:
            raise ValueError("threads must be at least 1")
        self.problem = problem
        self.threads = threads
        tp_robot = problem.tp_robot
        self.n_events = problem.events.size
        self._chain_next = problem.event_next  # (E,)
        self._tp_event = problem.tp_event  # (P,)
        self._build_slots(problem)
        # (2M,) slots of realized conflicts (re-scheduling): decided in the past, they only
        # relate passed points and never constrain the future.
        self._live = ~np.repeat(problem.realized, 2)
        # A constraint within this of holding with equality binds (see binding).
        self._tight = 1e-9 * max(1.0, float(np.abs(problem.tp_time).max(initial=0.0)))
        counts = np.diff(problem.tp_start).astype(np.float64)  # (R,) time points per robot
        weights = np.zeros(self.n_events + 1)
        np.add.at(weights, self._tp_event, 1.0 / (counts[tp_robot] * problem.n_robots))
        self._delay_weight = weights  # (E+1,): avg_delay = event_delay @ weights
        self._last_event = self._tp_event[problem.last_tp]  # (R,)
        # Each sum objective's (weights (E+1,), robots, summed free times), found once:
        # re-insertion search bounds every repair it evaluates (see _sum_bound).
        self._sum_forms: dict[Objective, tuple[np.ndarray, int, float]] = {}

    def _build_slots(self, problem: Problem) -> None:
        """Fixed arrays of the 2M conflict constraints, and each event's chain in-degree.

        Slot 2c+s constrains side s of conflict c (the side passing second) by
        side 1-s; it applies when side 1-s passes first. Its source and offset depend
        on the conflict's type (0 exclusive: the first side's pair exit; 1 following:
        its pair enter): (2, 2M) arrays indexed by type, so that the walk reads them
        per sample without (S, 2M) copies.
        """
        tp_event, t = self._tp_event, problem.tp_time
        pe, px = problem.tp_pair_enter, problem.tp_pair_exit  # (M, 2)
        first_pe, first_px = pe[:, ::-1], px[:, ::-1]  # time points of the side passing first
        self._target = tp_event[pe].ravel()  # (2M,)
        self._source = np.stack([tp_event[first_px].ravel(), tp_event[first_pe].ravel()])
        self._offset = np.stack([(t[first_px] - t[pe]).ravel(), (t[first_pe] - t[pe]).ravel()])
        chain_indeg = np.zeros(self.n_events, dtype=np.int64)  # (E,)
        chain_indeg[self._chain_next[self._chain_next >= 0]] = 1
        self._chain_indeg = chain_indeg

    @property
    def graph(self) -> ConstraintGraph:
        """The event graph this evaluator walks."""
        return ConstraintGraph(
            self._chain_next,
            self._target,
            self._source,
            self._offset,
            self._live,
            self._last_event,
            self._delay_weight,
        )

    def evaluate(self, assignments: Assignments) -> Evaluation:
        """Least updated times and costs of every assignment in the batch."""
        a_first = np.ascontiguousarray(assignments.a_first, dtype=bool).view(np.uint8)  # (S, M)
        following = np.ascontiguousarray(assignments.following, dtype=bool).view(np.uint8)  # (S, M)
        delay = np.zeros((assignments.n_samples, self.n_events + 1))  # (S, E+1), S may be 0

        def walk(rows: slice) -> np.ndarray:
            return _longest_paths(*self._fixed, a_first[rows], following[rows], delay[rows])

        return self._evaluation(delay, self._in_shares(walk, assignments.n_samples))

    def evaluate_flips(
        self,
        base: Assignments,
        start: np.ndarray,  # (C+1,) int, candidate i reverses flipped[start[i]:start[i+1]]
        flipped: np.ndarray,  # (K,) int, conflicts, distinct within each candidate
    ) -> Evaluation:
        """The C assignments that each reverse a few conflicts of the single assignment
        ``base`` (types unchanged): the same numbers as :meth:`evaluate` of them, without
        building them or grouping each one's arcs (which is 40 % of a full evaluation).

        Local searches that move many conflicts at once (robot-priority search) evaluate
        their candidates this way; the walk itself stays whole, since a reversal's
        effect reaches most events of a congested warehouse.

        Raises:
            ValueError: ``base`` is not one assignment, or a candidate lists a (live)
                conflict twice.
        """
        if base.n_samples != 1:
            raise ValueError("base must be a single assignment")
        start, flipped = np.asarray(start, dtype=np.int64), np.asarray(flipped, dtype=np.int64)
        a_first = np.ascontiguousarray(base.a_first[0], dtype=bool).view(np.uint8)  # (M,)
        following = np.ascontiguousarray(base.following[0], dtype=bool).view(np.uint8)  # (M,)
        delay = np.zeros((start.size - 1, self.n_events + 1))  # (C, E+1)

        def walk(rows: slice) -> np.ndarray:
            return _longest_paths_flipped(
                *self._fixed, a_first, following, start[rows.start : rows.stop + 1], flipped,
                delay[rows],
            )  # fmt: skip

        return self._evaluation(delay, self._in_shares(walk, start.size - 1))

    @property
    def _fixed(self) -> tuple[np.ndarray, ...]:
        """The kernels' fixed arrays: chains, then the conflict slots."""
        return (
            self._chain_next, self._chain_indeg, self._target, self._source, self._offset,
            self._live,
        )  # fmt: skip

    def _evaluation(self, delay: np.ndarray, converged: np.ndarray) -> Evaluation:
        """Completions and costs from walked delays (S, E+1) and converged flags (S,)."""
        problem = self.problem
        completion = problem.tp_time[problem.last_tp] + delay[:, self._last_event]  # (S, R)
        costs = costs_from_completion(completion)
        costs["avg_delay"] = _row_sums(delay, self._delay_weight)
        if not converged.all():  # a converged batch's costs stand as they are (no copies)
            costs = {k: np.where(converged, costs[k], np.inf) for k in OBJECTIVES}
        return Evaluation(delay, completion, costs, converged)

    def _in_shares(self, walk: Callable[[slice], np.ndarray], n_samples: int) -> np.ndarray:
        """``walk`` of every row of a batch, in up to ``threads`` shares of rows run at once
        when the batch is large enough to pay for it -> its converged flags (S,)."""
        work = n_samples * self.problem.n_conflicts
        shares = min(self.threads, n_samples, max(1, work // MIN_THREAD_WORK))
        if shares <= 1:
            return walk(slice(0, n_samples))
        bounds = np.linspace(0, n_samples, shares + 1).astype(np.int64)  # (shares+1,)
        rows = [slice(lo, hi) for lo, hi in itertools.pairwise(bounds.tolist())]
        return np.concatenate(in_parts(walk, rows))

    def binding(
        self, assignments: Assignments, evaluation: Evaluation, sample: int = 0
    ) -> np.ndarray:
        """(M,) bool: conflicts whose constraint holds with equality and makes a robot wait.

        These are the conflicts a local search should change first: the delay
        at the second side's pair enter is exactly what this conflict demands,
        so reversing it or changing its type is what can lower that delay.
        """
        return _binding(
            self._target, self._source, self._offset, self.problem.realized,
            np.asarray(assignments.a_first[sample], dtype=bool),
            np.asarray(assignments.following[sample], dtype=bool), evaluation.event_delay[sample],
            self._tight,
        )  # fmt: skip

    def objective_weights(self, objective: Objective) -> np.ndarray:
        """(E+1,) each event delay's weight in a sum objective, per robot: its completion
        event's 1 for avg_completion (completion = free time + that delay), the mean's
        weights for avg_delay (the zero-delay slot E weighs nothing).

        Raises:
            ValueError: ``objective`` is not a sum over robots.
        """
        if objective == "avg_delay":
            return self._delay_weight.copy()
        if objective != "avg_completion":
            raise ValueError(f"{objective} is not a sum over robots")
        weight = np.zeros(self.n_events + 1)
        weight[self._last_event] = 1.0
        weight[-1] = 0.0  # robots with no event
        return weight

    def held_weights(self, objective: Objective) -> np.ndarray:
        """(E+1,) the events a search that re-plans a few robots holds every other robot's
        part of the objective by (``held`` of :meth:`evaluate_with_latest`), weighted in
        the objective's units: :meth:`objective_weights`, except for avg_delay, each
        robot's completion event weighing the robot's whole part (its events' weights
        summed). avg_delay weighs every event, so holding them all leaves no held event
        any room (its latest delay is its least): held by completion, a robot whose
        completion waits for a later wait may wait longer on its way, which costs its
        part a little and frees the robots it meets; the one evaluation decides. Measured
        (session 50, docs/benchmarks.md "Room for held robots under avg_delay").

        Raises:
            ValueError: ``objective`` is not a sum over robots.
        """
        weight = self.objective_weights(objective)
        if objective != "avg_delay":
            return weight
        event_robot = self.problem.event_robot  # (E,)
        part = np.bincount(event_robot, weight[:-1], self.problem.n_robots)  # (R,)
        held = np.zeros_like(weight)
        held[self._last_event] = part
        held[-1] = 0.0  # robots with no event
        return held

    def cost_weights(
        self, objective: Objective, evaluation: Evaluation, sample: int = 0
    ) -> np.ndarray:
        """(E+1,) the events whose delays the cost of ``objective`` (one of
        MONOTONE_OBJECTIVES) reads, with their weights: :meth:`objective_weights` for the
        sums; for max_completion 1 at the completion events of the evaluated sample's
        robots that finish last (the maximum falls only where all of theirs fall).

        Raises:
            ValueError: ``objective`` is not one of MONOTONE_OBJECTIVES.
        """
        if objective not in MONOTONE_OBJECTIVES:
            raise ValueError(f"{objective} may fall when a delay rises")
        if objective == "max_completion":
            completion = evaluation.completion[sample]  # (R,)
            weights = np.zeros(self.n_events + 1)
            weights[self._last_event[completion >= completion.max()]] = 1.0
        else:
            weights = self.objective_weights(objective)
        weights[-1] = 0.0  # robots with no event never change
        return weights

    def critical_waits(
        self,
        assignment: Assignments,
        evaluation: Evaluation,
        objective: Objective,
        latest: np.ndarray | None = None,
    ) -> np.ndarray:
        """(M,) bool: of a single acyclic assignment (its ``evaluation``), the conflicts
        whose constraint acts on an event critical (:meth:`critical_slopes`) to the events
        the cost of ``objective`` (one of MONOTONE_OBJECTIVES) reads: a move (reversing a
        conflict or flipping its type) takes one constraint out and puts one in, and only
        taking one out of such an event can lower that cost. ``latest`` (E+1,): the
        latest delays holding those events (:meth:`latest_delays`), where the caller has
        them; else found here.

        Raises:
            ValueError: the assignment's constraint graph has a cycle.
        """
        if latest is None:
            held = self.cost_weights(objective, evaluation) > 0  # (E+1,)
            latest = self.latest_delays(assignment, evaluation, held)
        critical = self._at_least(latest, evaluation.event_delay[0])  # (E+1,)
        slots = 2 * np.arange(assignment.a_first.shape[1]) + assignment.a_first[0]  # (M,)
        return critical[self._target[slots]]

    def _at_least(self, latest: np.ndarray, least: np.ndarray) -> np.ndarray:
        """(E+1,) bool: the events whose ``latest`` delay is their ``least`` (to rounding):
        the critical ones."""
        return latest <= least + self._tight

    def latest_delays(
        self, assignments: Assignments, evaluation: Evaluation, held: np.ndarray, sample: int = 0
    ) -> np.ndarray:
        """(E+1,) the latest delay of every event of one evaluated sample such that raising
        any events' delays up to these (and what follows from them) leaves every ``held``
        (E+1,) bool event at its least delay: where a robot waits further on, its earlier
        events may be delayed up to that wait for free. Held events keep their least
        delays; the others are capped by what follows them only (inf if nothing held does).

        Raises:
            ValueError: the sample's constraint graph has a cycle.
        """
        least, latest = np.zeros(self.n_events + 1), np.empty(self.n_events + 1)  # (E+1,)
        slope = np.empty(self.n_events + 1)  # (E+1,) unread here
        unbounded = (np.zeros(0), np.inf)
        if (
            self._least_and_latest(assignments, sample, held, least, latest, slope, *unbounded)
            == CYCLIC
        ):
            raise ValueError("the assignment's constraint graph has a cycle")
        return np.maximum(latest, evaluation.event_delay[sample])  # rounding: never below

    def critical_slopes(
        self, assignment: Assignments, held: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Of a single acyclic assignment and ``held`` (E+1,) float weights (held where > 0):
        (critical (E+1,) bool, slope (E+1,) float). Critical events are those from which a
        path of constraints that hold with equality leads to a held event (the held ones
        among them): their latest delays (:meth:`latest_delays`) are their least. Only a
        wait at such an event holds up a held one, so only there can a relaxed wait lower
        one. The slopes are :meth:`evaluate_with_latest`'s: at a critical event at least
        the held weight those paths reach, so what a fall of its delay by x lowers the
        held events' weighted delays by is at most x times its slope.

        Raises:
            ValueError: the assignment's constraint graph has a cycle.
        """
        slope = np.empty(self.n_events + 1)  # (E+1,)
        evaluation, latest = self.evaluate_with_latest(assignment, held, slope)
        if latest is None:
            raise ValueError("the assignment's constraint graph has a cycle")
        return self._at_least(latest, evaluation.event_delay[0]), slope

    def evaluate_with_latest(
        self,
        assignment: Assignments,
        held: np.ndarray,
        slope: np.ndarray | None = None,
        below: tuple[Objective, float] | None = None,
    ) -> tuple[Evaluation, np.ndarray | None]:
        """:meth:`evaluate` of a single assignment and its :meth:`latest_delays` for
        ``held`` (E+1,) (bool, or float weights: held where > 0), from one walk of its
        arcs; None for the latter where the constraint graph has a cycle (the evaluation
        is then the cyclic one) or, with ``below`` (a sum objective and a cost), where
        the answer's cost in that objective is not below that cost by more than rounding
        (SUM_MARGIN; the backward pass skipped: a search that keeps only cheaper answers
        needs no more of the others).
        ``slope`` (E+1,) float, where given, gets each event's slope (see
        :func:`_least_and_latest`): how much held weight a delay past its latest pushes
        past theirs, per unit, to first order (at most once per way to a held event, and
        at most the total held weight).

        Raises:
            ValueError: ``assignment`` is not a single one, or ``below``'s objective is
                not a sum over robots.
        """
        if assignment.n_samples != 1:
            raise ValueError("the assignment must be a single one")
        delay = np.zeros((1, self.n_events + 1))  # (1, E+1)
        latest = np.empty(self.n_events + 1)  # (E+1,)
        slope = np.empty(self.n_events + 1) if slope is None else slope
        weight, bound = (np.zeros(0), np.inf) if below is None else self._sum_bound(*below)
        walked = self._least_and_latest(assignment, 0, held, delay[0], latest, slope, weight, bound)
        if walked == CYCLIC:
            return self.evaluate(assignment), None
        evaluation = self._evaluation(delay, np.ones(1, dtype=bool))
        return evaluation, np.maximum(latest, delay[0]) if walked == WALKED_BOTH else None

    def _sum_bound(self, objective: Objective, cost: float) -> tuple[np.ndarray, float]:
        """A cost of sum ``objective`` as a bound on the delays' weighted sum -> (weights
        (E+1,), bound): an answer whose sum reaches the bound costs at least ``cost``
        (avg_completion: the mean of free times plus completion delays; avg_delay: the
        sum itself), raised by SUM_MARGIN against the order in which sums are added.

        Raises:
            ValueError: ``objective`` is not a sum over robots.
        """
        if objective not in self._sum_forms:
            free = self.problem.tp_time[self.problem.last_tp]  # (R,)
            self._sum_forms[objective] = (
                self.objective_weights(objective),
                max(free.size, 1),
                float(free.sum()),
            )
        weight, robots, free_sum = self._sum_forms[objective]
        if objective == "avg_completion":
            cost = cost * robots - free_sum
        return weight, cost + SUM_MARGIN * (1.0 + abs(cost))

    def _least_and_latest(
        self, assignments: Assignments, sample: int, held: np.ndarray, d: np.ndarray,
        latest: np.ndarray, slope: np.ndarray, weight: np.ndarray, bound: float,
    ) -> int:  # fmt: skip
        """:func:`_least_and_latest` of one sample (``d`` zeros on entry, all (E+1,))."""
        a_first = np.ascontiguousarray(assignments.a_first[sample], dtype=bool).view(np.uint8)
        following = np.ascontiguousarray(assignments.following[sample], dtype=bool).view(np.uint8)
        held = np.ascontiguousarray(held, dtype=np.float64)
        return _least_and_latest(
            *self._fixed, a_first, following, held, d, latest, slope, self._tight, weight, bound
        )

    def delays_at(self, evaluation: Evaluation, sample: int, time_points: np.ndarray) -> np.ndarray:
        """Delays D at the given time points of one evaluated sample (same shape)."""
        return evaluation.event_delay[sample, self._tp_event[time_points]]

    def free_costs(self) -> dict[str, float]:
        """Every objective's cost with zero delay (each robot at its expected last time point)."""
        zero = costs_from_completion(self.problem.free_time()[None, :])
        zero["avg_delay"] = np.zeros(1)
        return {k: float(v[0]) for k, v in zero.items()}
