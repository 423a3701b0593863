"""The executor's event loop, compiled: robots drive, wait, release and finish.

:class:`~service.simulation.executor.Execution` keeps its state in one
:class:`Loop` of arrays and typed lists, and these numba kernels advance it
event by event (a 250-robot one-way warehouse: ~19,000 events and ~64,000
re-schedules of waiting robots; the same loop in Python took 0.1-0.2 s, this one
0.04 s). Semantics (docs in executor.py):

* each robot drives from its start time at its planned speed scaled by its progress
  rate (piecewise constant over wall time, 1 outside its pieces) and stops exactly at
  the nearest wait point whose constraint is unsatisfied;
* a constraint is satisfied once its waitee's progress clock reaches the release
  threshold (or the waitee is done); the waiters it concerns are then woken in robot
  order and move on as far as their next blocking point;
* every robot has at most one pending event, its start or its next arrival (at
  progress ``clock``); events are taken in order of wall time, ties in the order they
  were set (an indexed binary heap over robots: setting a robot's event replaces the
  one it had, a robot that stops has none).

Clocks are each robot's progress clock: the planned time of where it stands.

Each call between kernels passes the whole :class:`Loop` (every array in it
reference-counted on the way in and out, ~1 us a call), so the small helpers are
inlined (``inline="always"``); ``_schedule`` and the heap updates stay calls, which
keeps the first compilation near 10 s (inlining all of them: 50 s, for 37 -> 24 ms
at 250 robots).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np
from numba import types
from numba.typed import List

from service.simulation.disturbances import advance, progress

__all__ = [
    "RECORD",
    "Loop",
    "catch_up",
    "clocks_at",
    "push_starts",
    "reach_all",
    "run_until",
    "schedule_all",
    "waypoints",
]

RECORD = types.Tuple((types.int64, types.float64, types.float64))  # robot, wall, clock


class Loop(NamedTuple):
    """The executor's state. Shapes: R robots, D live constraints, E rate edges in all.

    Per robot: ``clock`` is its progress clock at wall time ``wall``; ``target`` the
    clock of its pending arrival while ``moving``. Constraints: ``block_*`` lists them
    by (waiter, wait clock), ``block_next[r]`` is robot r's first not yet known to be
    satisfied; ``release_*`` lists them by (waitee, threshold), ``next_release[r]`` is
    robot r's first threshold not yet reached. Rates: with f = ``rate_start[r]``, robot
    r's K = ``rate_start[r + 1] - f - 1`` pieces are ``rate_value[f + k]`` on
    ``[rate_edge[f + k], rate_edge[f + k + 1])``, k < K (K + 1 edges and K + 1 values,
    the last a pad, per robot; :func:`service.simulation.disturbances.progress`); K = 0
    is rate 1.
    """

    clock: np.ndarray  # (R,) float
    wall: np.ndarray  # (R,) float
    target: np.ndarray  # (R,) float
    finish_clock: np.ndarray  # (R,) float, planned arrival at the last point
    completion: np.ndarray  # (R,) float, wall time at the last point, NaN before
    moving: np.ndarray  # (R,) bool
    started: np.ndarray  # (R,) bool
    done: np.ndarray  # (R,) bool
    rate_start: np.ndarray  # (R+1,) int
    rate_edge: np.ndarray  # (E + R,) float
    rate_value: np.ndarray  # (E + R,) float
    waiter: np.ndarray  # (D,) int
    satisfied: np.ndarray  # (D,) bool
    block_start: np.ndarray  # (R+1,) int
    block_next: np.ndarray  # (R,) int
    block_clock: np.ndarray  # (D,) float, wait clocks sorted by (waiter, clock)
    block_constraint: np.ndarray  # (D,) int
    release_start: np.ndarray  # (R+1,) int
    next_release: np.ndarray  # (R,) int
    release_clock: np.ndarray  # (D,) float, thresholds sorted by (waitee, clock)
    release_constraint: np.ndarray  # (D,) int
    event_wall: np.ndarray  # (R,) float, wall time of each robot's pending event
    event_clock: np.ndarray  # (R,) float, progress clock it reaches then
    event_start: np.ndarray  # (R,) bool, the event is its start
    event_seq: np.ndarray  # (R,) int, when it was set (ties break in that order)
    seq: np.ndarray  # (1,) int, events set so far
    heap: np.ndarray  # (R,) int, robots with a pending event, heap-ordered; size in heap_size
    heap_size: np.ndarray  # (1,) int
    heap_pos: np.ndarray  # (R,) int, each robot's index in ``heap``, -1 without an event
    records: List  # RECORD: every (robot, wall, clock) where motion changes, in order


@numba.njit(cache=True, nogil=True)
def run_until(loop: Loop, until: float) -> None:
    """Process every event at wall time <= ``until`` (all of them for ``np.inf``)."""
    while loop.heap_size[0] > 0 and loop.event_wall[loop.heap[0]] <= until:
        r = loop.heap[0]
        _unset(loop, r)
        if loop.event_start[r]:
            _start(loop, r)
        else:
            _arrive(loop, r, loop.event_wall[r], loop.event_clock[r])


@numba.njit(cache=True, nogil=True)
def push_starts(loop: Loop, robots: np.ndarray, walls: np.ndarray, clocks: np.ndarray) -> None:
    """Each of ``robots`` (P,) appears at its first point (progress ``clocks`` (P,)) at
    wall time ``walls`` (P,)."""
    for k in range(robots.size):
        _set(loop, robots[k], walls[k], clocks[k], True)


@numba.njit(cache=True, nogil=True)
def reach_all(loop: Loop) -> None:
    """Satisfy what every started robot has already reached (after a plan is loaded)."""
    for r in range(loop.clock.size):
        if loop.started[r]:
            _reach(loop, r)


@numba.njit(cache=True, nogil=True)
def schedule_all(loop: Loop, robots: np.ndarray) -> None:
    """Let each of ``robots`` (int, in order) move as far as it may from where it stands."""
    for r in robots:
        _schedule(loop, r)


@numba.njit(cache=True, nogil=True)
def catch_up(loop: Loop, robots: np.ndarray, wall: float) -> None:
    """Bring the clocks of ``robots`` up to wall time ``wall``."""
    for r in robots:
        _catch_up(loop, r, wall)


@numba.njit(cache=True, nogil=True)
def clocks_at(loop: Loop, wall: float) -> np.ndarray:
    """(R,) every robot's progress clock at ``wall`` (not past its pending event)."""
    out = np.empty(loop.clock.size)
    for r in range(out.size):
        out[r] = _clock_at(loop, r, wall)
    return out


@numba.njit(cache=True, nogil=True, inline="always")
def rate_progress(loop: Loop, r: int, t0: float, t1: float) -> float:
    """Progress-clock seconds robot r gains moving from wall time t0 to t1 >= t0."""
    first, pieces = loop.rate_start[r], loop.rate_start[r + 1] - loop.rate_start[r] - 1
    return progress(loop.rate_edge, loop.rate_value, first, pieces, t0, t1)


@numba.njit(cache=True, nogil=True, inline="always")
def rate_advance(loop: Loop, r: int, t0: float, gain: float) -> float:
    """The wall time at which robot r, moving from t0, has gained ``gain`` progress."""
    first, pieces = loop.rate_start[r], loop.rate_start[r + 1] - loop.rate_start[r] - 1
    return advance(loop.rate_edge, loop.rate_value, first, pieces, t0, gain)


@numba.njit(cache=True, nogil=True)
def waypoints(
    loop: Loop, times: np.ndarray, times_start: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every robot's records with, inside each move, the planned path vertices it passes
    (where speed or heading change) and the changes of its rate added: waypoints
    between which motion is linear in the plane, grouped by robot (unsorted within).

    Shapes: times (N,) every path's planned vertex times, robot r's are
    ``times[times_start[r]:times_start[r + 1]]``; returns robot (K,) int, wall (K,),
    clock (K,).
    """
    n = len(loop.records)
    rec_robot, rec_wall, rec_clock = np.empty(n, np.int64), np.empty(n), np.empty(n)
    for k in range(n):
        rec_robot[k], rec_wall[k], rec_clock[k] = loop.records[k]
    out_robot = List.empty_list(types.int64)
    out_wall, out_clock = List.empty_list(types.float64), List.empty_list(types.float64)
    for r in range(loop.clock.size):
        rows = np.flatnonzero(rec_robot == r)
        vertex = times[times_start[r] : times_start[r + 1]]
        for m in range(rows.size):
            w0, c0 = rec_wall[rows[m]], rec_clock[rows[m]]
            out_robot.append(r)
            out_wall.append(w0)
            out_clock.append(c0)
            if m + 1 == rows.size or rec_clock[rows[m + 1]] <= c0:
                continue
            w1, c1 = rec_wall[rows[m + 1]], rec_clock[rows[m + 1]]
            for c in vertex[np.searchsorted(vertex, c0, "right") : np.searchsorted(vertex, c1)]:
                out_robot.append(r)
                out_wall.append(rate_advance(loop, r, w0, c - c0))
                out_clock.append(c)
            for e in range(loop.rate_start[r], loop.rate_start[r + 1]):
                if w0 < loop.rate_edge[e] < w1:
                    out_robot.append(r)
                    out_wall.append(loop.rate_edge[e])
                    out_clock.append(c0 + rate_progress(loop, r, w0, loop.rate_edge[e]))
    return np.asarray(out_robot), np.asarray(out_wall), np.asarray(out_clock)


@numba.njit(cache=True, nogil=True)
def _set(loop: Loop, r: int, wall: float, clock: float, start: bool) -> None:
    """Robot r's pending event is now this one (replacing any it had)."""
    loop.event_wall[r], loop.event_clock[r], loop.event_start[r] = wall, clock, start
    loop.event_seq[r] = loop.seq[0]
    loop.seq[0] += 1
    k = loop.heap_pos[r]
    if k < 0:
        k = loop.heap_size[0]
        loop.heap_size[0] += 1
        _place(loop, r, k)
    _sift_up(loop, _sift_down(loop, k))


@numba.njit(cache=True, nogil=True)
def _unset(loop: Loop, r: int) -> None:
    """Robot r has no pending event any more."""
    k = loop.heap_pos[r]
    if k < 0:
        return
    loop.heap_pos[r] = -1
    loop.heap_size[0] -= 1
    last = loop.heap_size[0]
    if k < last:
        _place(loop, loop.heap[last], k)
        _sift_up(loop, _sift_down(loop, k))


@numba.njit(cache=True, nogil=True, inline="always")
def _before(loop: Loop, a: int, b: int) -> bool:
    """Robot a's event comes before robot b's."""
    if loop.event_wall[a] != loop.event_wall[b]:
        return loop.event_wall[a] < loop.event_wall[b]
    return loop.event_seq[a] < loop.event_seq[b]


@numba.njit(cache=True, nogil=True, inline="always")
def _place(loop: Loop, r: int, k: int) -> None:
    loop.heap[k] = r
    loop.heap_pos[r] = k


@numba.njit(cache=True, nogil=True, inline="always")
def _sift_up(loop: Loop, k: int) -> int:
    """Move the entry at heap index k up to its place; returns where it ends."""
    r = loop.heap[k]
    while k > 0 and _before(loop, r, loop.heap[(k - 1) // 2]):
        _place(loop, loop.heap[(k - 1) // 2], k)
        k = (k - 1) // 2
    _place(loop, r, k)
    return k


@numba.njit(cache=True, nogil=True, inline="always")
def _sift_down(loop: Loop, k: int) -> int:
    """Move the entry at heap index k down to its place; returns where it ends."""
    r, size = loop.heap[k], loop.heap_size[0]
    while 2 * k + 1 < size:
        child = 2 * k + 1
        if child + 1 < size and _before(loop, loop.heap[child + 1], loop.heap[child]):
            child += 1
        if not _before(loop, loop.heap[child], r):
            break
        _place(loop, loop.heap[child], k)
        k = child
    _place(loop, r, k)
    return k


@numba.njit(cache=True, nogil=True, inline="always")
def _record(loop: Loop, r: int) -> None:
    loop.records.append((r, loop.wall[r], loop.clock[r]))


@numba.njit(cache=True, nogil=True, inline="always")
def _limit_clock(loop: Loop, r: int) -> float:
    """Progress clock of robot r's nearest blocking wait point (its finish if none)."""
    k, end = loop.block_next[r], loop.block_start[r + 1]
    while k < end and loop.satisfied[loop.block_constraint[k]]:
        k += 1
    loop.block_next[r] = k
    return loop.block_clock[k] if k < end else loop.finish_clock[r]


@numba.njit(cache=True, nogil=True)
def _schedule(loop: Loop, r: int) -> None:
    """Robot r moves from (wall, clock): push its next event, or stop it at its limit."""
    limit = _limit_clock(loop, r)
    if limit <= loop.clock[r]:
        if loop.moving[r]:
            loop.moving[r] = False
            _unset(loop, r)  # a new plan may stop it before its pending event
            _record(loop, r)
        return
    if not loop.moving[r]:
        loop.moving[r] = True
        _record(loop, r)
    target = min(limit, loop.finish_clock[r])
    k = loop.next_release[r]
    if k < loop.release_start[r + 1]:
        target = min(target, loop.release_clock[k])
    loop.target[r] = target
    _set(loop, r, rate_advance(loop, r, loop.wall[r], target - loop.clock[r]), target, False)


@numba.njit(cache=True, nogil=True, inline="always")
def _start(loop: Loop, r: int) -> None:
    """Robot r appears at its first point at its start time."""
    loop.started[r] = True
    _record(loop, r)
    _release(loop, r)
    _schedule(loop, r)


@numba.njit(cache=True, nogil=True, inline="always")
def _arrive(loop: Loop, r: int, wall: float, clock: float) -> None:
    """Robot r reached progress ``clock`` at ``wall``: release, finish or go on."""
    loop.wall[r], loop.clock[r] = wall, clock
    if clock >= loop.finish_clock[r]:
        loop.done[r], loop.moving[r] = True, False
        loop.completion[r] = wall
        _record(loop, r)
    _release(loop, r)
    if not loop.done[r]:
        _schedule(loop, r)


@numba.njit(cache=True, nogil=True, inline="always")
def _release(loop: Loop, r: int) -> None:
    """Satisfy the constraints robot r has now reached and wake their waiters (each once,
    in robot order)."""
    first = loop.next_release[r]
    _reach(loop, r)
    last = loop.next_release[r]
    if last == first:
        return
    waiters = np.sort(loop.waiter[loop.release_constraint[first:last]])
    for k in range(waiters.size):
        if k == 0 or waiters[k] != waiters[k - 1]:
            _wake(loop, waiters[k], loop.wall[r])


@numba.njit(cache=True, nogil=True, inline="always")
def _reach(loop: Loop, r: int) -> None:
    """Satisfy the constraints robot r has now reached (all of them once it is done)."""
    k, end = loop.next_release[r], loop.release_start[r + 1]
    while k < end and (loop.done[r] or loop.release_clock[k] <= loop.clock[r]):
        loop.satisfied[loop.release_constraint[k]] = True
        k += 1
    loop.next_release[r] = k


@numba.njit(cache=True, nogil=True, inline="always")
def _clock_at(loop: Loop, r: int, wall: float) -> float:
    """Robot r's progress clock at ``wall`` (never past its pending event: rounding of
    advance/progress)."""
    if not loop.moving[r]:
        return loop.clock[r]
    return min(loop.clock[r] + rate_progress(loop, r, loop.wall[r], wall), loop.target[r])


@numba.njit(cache=True, nogil=True, inline="always")
def _catch_up(loop: Loop, r: int, wall: float) -> None:
    loop.clock[r] = _clock_at(loop, r, wall)
    loop.wall[r] = wall


@numba.njit(cache=True, nogil=True, inline="always")
def _wake(loop: Loop, w: int, wall: float) -> None:
    """Robot w's limit may have moved on at ``wall``: bring it up to date and reschedule."""
    if not loop.started[w] or loop.done[w]:
        return
    _catch_up(loop, w, wall)
    _schedule(loop, w)
