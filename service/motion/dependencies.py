"""From an assignment of a path-derived graph to a dependency plan the executor runs.

For a conflict between robots i (side a) and j (side b) decided "i first":

* **exclusive**: for each *section* of the conflict (its boxes split where either
  robot's arc lengths leave a gap: the places where the two routes meet), j may not
  pass the start of the section until i has reached its end. Most conflicts are
  one section (one wait point); two routes that meet twice in the same pair of
  nodes wait at each meeting separately, never more than the graph's union
  section (the graph's pair times) says;
* **following**: a staircase over the conflict's boxes: for every box, j may not pass
  the box's start ``y0`` until i has reached the box's end ``x1``. j may thus
  enter the shared section while i is still in it, keeping behind i by at least
  the clearance, and it stops when i stops (the following robot never catches up,
  whatever the speeds or a third robot do to i).

"j first" swaps the roles. Either way the pair stays out of every box's interior,
which is what keeps the disks apart (docs/paths.md).

A plan then drops the constraints that others imply through a third robot
(:func:`without_implied`): robots in one aisle wait for everyone ahead of them, but
waiting for the one in front implies the rest. On 250-robot warehouses that keeps a
tenth of the constraints, and execution, the answer and its encoding shrink with them.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numba
import numpy as np

from service.core.threads import balanced_cuts, in_parts, parts_for
from service.geometry.graph import CoordinationGraph
from service.simulation.executor import DependencyPlan

__all__ = [
    "IMPLIED_TOL_M",
    "STAIRCASE_STEP_M",
    "Decision",
    "dependency_plan",
    "sections",
    "staircase",
    "thin",
    "without_implied",
]

# Least distance, metres, between two wait points of one following conflict: a follower
# then trails at most this much further behind than it must, and a 250-robot plan keeps
# ~10^4 rather than ~10^5 constraints (executed and sent over the wire). Below the
# geometry's coarse pieces (1 m, ``geometry.interference.COARSE_PIECE_M``), so that two
# of their steps rarely merge into one: on 63 reference worlds (fcfs, executed cost)
# 0.75 m changed the cost by -0.07 % on average (at most +0.35 %) against 1 m with
# fine pieces, and kept 7 % more constraints; 1 m with coarse pieces cost +0.10 % (at
# most +1.45 %), 0.5 m -0.15 % with 19 % more constraints.
STAIRCASE_STEP_M = 0.75
# Most wait points one following conflict keeps: a shared stretch longer than this many
# steps gets longer steps (a kilometre-long corridor must not cost 10^3+ events).
MAX_STEPS = 100
# How far, metres, a robot must be past a wait point of its own for the constraint there
# to count as satisfied in a chain (:func:`without_implied`): rounding never makes a
# robot standing at its wait point count as past it.
IMPLIED_TOL_M = 1e-6
# Least boxes in a part of a plan made on a thread of its own.
MIN_PART_BOXES = 100_000


@dataclass(frozen=True, eq=False)
class Decision:
    """An assignment of the graph's conflicts. Shapes: M conflicts."""

    a_first: np.ndarray  # (M,) bool, side a (the lower robot index) passes first
    following: np.ndarray  # (M,) bool

    def exclusive(self) -> Decision:
        """The same directions with every conflict exclusive (always executable)."""
        return Decision(self.a_first, np.zeros_like(self.following))


@numba.njit(cache=True, nogil=True)
def staircase(until: np.ndarray, wait: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fewest constraints equivalent to "may not pass wait[k] until the other reached until[k]".

    Shapes: (K,) each -> (K',) each, ``until`` ascending. The limit while the other
    robot is before ``u`` is the least ``wait`` over constraints with ``until > u``:
    a non-decreasing step function; one constraint per step is kept.
    """
    # Sort by until, ties by descending wait (the least wait last, so only it is kept):
    # two stable sorts, as numba has no lexsort; none where the boxes of a corridor come
    # in order already (until strictly ascending, as most do).
    if np.any(until[1:] <= until[:-1]):
        by_wait = np.argsort(-wait, kind="mergesort")
        order = by_wait[np.argsort(until[by_wait], kind="mergesort")]
        until, wait = until[order], wait[order]
    least = wait.copy()  # least wait from k on
    for k in range(least.size - 2, -1, -1):
        least[k] = min(least[k], least[k + 1])
    keep = np.ones(until.size, dtype=np.bool_)
    keep[:-1] = least[:-1] < least[1:]
    return until[keep], least[keep]


@numba.njit(cache=True, nogil=True)
def thin(until: np.ndarray, wait: np.ndarray, step: float) -> tuple[np.ndarray, np.ndarray]:
    """A coarser staircase whose wait points lie at least ``step`` metres apart.

    Shapes: a staircase (K,) each (both ascending) -> (K',) each. Steps are merged
    into runs starting ``step`` apart; a run waits at its first (lowest) wait point
    until the other robot reached its last (farthest) release point, which implies
    every merged step: conservative, so just as safe, with fewer constraints.
    """
    if until.size <= 1:
        return until, wait
    run = np.floor((wait - wait[0]) / step)  # (K,) non-decreasing
    starts = np.ones(until.size, dtype=np.bool_)
    starts[1:] = run[1:] != run[:-1]
    first = np.flatnonzero(starts)  # (K',) where each run starts
    last = np.empty_like(first)
    last[:-1] = first[1:] - 1
    last[-1] = until.size - 1
    return until[last], wait[first]


@numba.njit(cache=True, nogil=True)
def sections(
    x0: np.ndarray, x1: np.ndarray, y0: np.ndarray, y1: np.ndarray
) -> np.ndarray:  # (B,) section label of each box
    """Split one conflict's boxes (B,) where i's arc lengths leave a gap, then j's.

    Any grouping is safe (each group's bounding box contains its boxes); splitting at
    gaps keeps separate meeting places (two routes that meet twice) apart.
    """
    label = np.empty(x0.size, dtype=np.int64)
    # Boxes usually come in order of i's pieces already: no sort then.
    by_x = np.arange(x0.size) if np.all(x0[1:] >= x0[:-1]) else np.argsort(x0, kind="mergesort")
    n_labels, k = 0, 0
    while k < by_x.size:  # one run of boxes overlapping along i
        end, reach = k + 1, x1[by_x[k]]
        while end < by_x.size and x0[by_x[end]] <= reach:
            reach = max(reach, x1[by_x[end]])
            end += 1
        members = by_x[k:end]
        by_y = members[np.argsort(y0[members], kind="mergesort")]
        reach_y = -np.inf
        for b in by_y:  # split the run where j's arc lengths leave a gap
            if y0[b] > reach_y:
                n_labels += 1
            reach_y = max(reach_y, y1[b])
            label[b] = n_labels - 1
        k = end
    return label


@numba.njit(cache=True, nogil=True)
def _plan_kernel(
    box_start: np.ndarray,  # (M'+1,) int, the boxes of the conflicts planned here
    x0: np.ndarray,  # (B,) float, boxes sorted by conflict
    x1: np.ndarray,
    y0: np.ndarray,
    y1: np.ndarray,
    robot_a: np.ndarray,  # (M',) int, robot of side a
    robot_b: np.ndarray,  # (M',) int
    a_first: np.ndarray,  # (M',) bool
    following: np.ndarray,  # (M',) bool
    step: float,
    waiters: np.ndarray,  # (K,) int out, K >= the conflicts' boxes: at most one per box
    waits: np.ndarray,  # (K,) float out
    waitees: np.ndarray,  # (K,) int out
    untils: np.ndarray,  # (K,) float out
) -> int:  # the constraints written
    n_out = 0
    for m in range(box_start.size - 1):
        lo, hi = box_start[m], box_start[m + 1]
        if a_first[m]:
            waiter, waitee, wait, until = robot_b[m], robot_a[m], y0[lo:hi], x1[lo:hi]
        else:
            waiter, waitee, wait, until = robot_a[m], robot_b[m], x0[lo:hi], y1[lo:hi]
        if not following[m]:  # one constraint per section: its start until its end
            label = sections(x0[lo:hi], x1[lo:hi], y0[lo:hi], y1[lo:hi])
            n = label.max() + 1
            if n == 1:  # most conflicts: one meeting place, one constraint
                waiters[n_out], waits[n_out] = waiter, wait.min()
                waitees[n_out], untils[n_out] = waitee, until.max()
                n_out += 1
                continue
            group_wait = np.full(n, np.inf)
            group_until = np.full(n, -np.inf)
            for b in range(label.size):
                group_wait[label[b]] = min(group_wait[label[b]], wait[b])
                group_until[label[b]] = max(group_until[label[b]], until[b])
            wait, until = group_wait, group_until
        until, wait = staircase(until, wait)
        span = wait[-1] - wait[0] if wait.size else 0.0
        until, wait = thin(until, wait, max(step, span / MAX_STEPS))
        for k in range(wait.size):
            waiters[n_out], waits[n_out] = waiter, wait[k]
            waitees[n_out], untils[n_out] = waitee, until[k]
            n_out += 1
    return n_out


def dependency_plan(graph: CoordinationGraph, decision: Decision) -> DependencyPlan:
    """The executor's constraints for ``decision`` on ``graph``."""
    if graph.n_conflicts == 0:
        return DependencyPlan.empty()
    robot = graph.node_robot[graph.conf_node].astype(np.int64)  # (M, 2)
    robot_a, robot_b = robot[:, 0].copy(), robot[:, 1].copy()  # (M,) each
    a_first, following = decision.a_first.astype(np.bool_), decision.following.astype(np.bool_)
    b, box_start = graph.boxes, graph.box_start
    # In parts of about equal boxes on threads of their own, each into its own rows of one
    # buffer (a part's conflicts make at most one constraint per box), joined after.
    bounds = balanced_cuts(np.diff(box_start), parts_for(b.size, MIN_PART_BOXES))
    out = (
        np.empty(b.size, np.int64),
        np.empty(b.size),
        np.empty(b.size, np.int64),
        np.empty(b.size),
    )

    def plan(part: tuple[int, int]) -> int:  # the constraints of conflicts lo:hi
        lo, hi = part
        rows = slice(box_start[lo], box_start[hi])
        return _plan_kernel(
            box_start[lo : hi + 1], b.x0, b.x1, b.y0, b.y1, robot_a[lo:hi], robot_b[lo:hi],
            a_first[lo:hi], following[lo:hi], STAIRCASE_STEP_M, *(o[rows] for o in out),
        )  # fmt: skip

    parts = list(itertools.pairwise(bounds))
    counts = in_parts(plan, parts)
    waiter, wait, waitee, until = (
        np.concatenate(
            [o[box_start[lo] : box_start[lo] + n] for (lo, _), n in zip(parts, counts, strict=True)]
        )
        for o in out
    )
    return DependencyPlan(waiter, wait, waitee, until)


@numba.njit(cache=True, nogil=True)
def _implied_kernel(
    start: np.ndarray,  # (R+1,) int, each waiter's constraints, sorted by wait point
    wait: np.ndarray,  # (D,) float
    waitee: np.ndarray,  # (D,) int
    until: np.ndarray,  # (D,) float
    order: np.ndarray,  # (R,) int, the robots in the order they are reduced
    tol: float,
) -> np.ndarray:  # (D,) bool, the constraints kept
    n = start.size - 1
    keep = np.ones(wait.size, dtype=np.bool_)
    # Each robot's list of constraints that may serve as a chain's second link: all of
    # them, then only those kept once the robot is reduced (copied after the first D).
    l_wait = np.concatenate((wait, wait))
    l_waitee = np.concatenate((waitee, waitee))
    l_until = np.concatenate((until, until))
    first, last = start[:-1].copy(), start[1:].copy()  # (R,) each robot's list
    n_items = wait.size
    reached = np.full(n, -np.inf)  # per robot k: how far i knows k is when passing w
    read = np.zeros(n, dtype=np.int64)  # per k: its list read up to here (wait < reached)
    known = np.full(n, -np.inf)  # per robot j: how far i knows j is, through one k
    touched_k = np.empty(n, dtype=np.int64)
    touched_j = np.empty(n, dtype=np.int64)
    for i in order:
        n_k = n_j = 0
        d = start[i]
        while d < start[i + 1]:  # one wait point of i at a time
            end = d
            while end < start[i + 1] and wait[end] == wait[d]:
                k = waitee[end]
                if until[end] > reached[k]:
                    if reached[k] == -np.inf:
                        touched_k[n_k] = k
                        n_k += 1
                        read[k] = first[k]
                    reached[k] = until[end]
                    q = read[k]  # k is past these wait points: their waitees are as far
                    while q < last[k] and l_wait[q] + tol < reached[k]:
                        j = l_waitee[q]
                        if j != i:
                            if known[j] == -np.inf:
                                touched_j[n_j] = j
                                n_j += 1
                            known[j] = max(known[j], l_until[q])
                        q += 1
                    read[k] = q
                end += 1
            for e in range(d, end):
                keep[e] = known[waitee[e]] < until[e]
            d = end
        for t in range(n_k):
            reached[touched_k[t]] = -np.inf
        for t in range(n_j):
            known[touched_j[t]] = -np.inf
        first[i] = n_items  # from now on, chains through i read only what i kept
        for e in range(start[i], start[i + 1]):
            if keep[e]:
                l_wait[n_items], l_waitee[n_items], l_until[n_items] = wait[e], waitee[e], until[e]
                n_items += 1
        last[i] = n_items
    return keep


@numba.njit(cache=True, nogil=True)
def _by_waiter_and_point(
    waiter: np.ndarray,  # (D,) int in [0, R)
    wait: np.ndarray,  # (D,) float
    waitee: np.ndarray,  # (D,) int
    until: np.ndarray,  # (D,) float
    n_robots: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    # -> the rows grouped by waiter (D,) x 4, each group by wait point (stable), and
    # (R+1,) each waiter's rows
    """The rows as ``np.lexsort((wait, waiter))`` orders them: a counting sort by waiter
    that moves the rows themselves, then each waiter's rows sorted where they are not in
    order. At 437,000 rows ~28 ms, where the lexsort took ~60 ms and a sorted permutation
    gathered after ~36 ms."""
    start = np.zeros(n_robots + 1, dtype=np.int64)
    for d in range(waiter.size):
        start[waiter[d] + 1] += 1
    start = np.cumsum(start)
    fill = start[:-1].copy()
    out_waiter, out_waitee = np.empty_like(waiter), np.empty_like(waitee)
    out_wait, out_until = np.empty_like(wait), np.empty_like(until)
    for d in range(waiter.size):
        k = fill[waiter[d]]
        out_waiter[k], out_wait[k], out_waitee[k], out_until[k] = (
            waiter[d],
            wait[d],
            waitee[d],
            until[d],
        )
        fill[waiter[d]] += 1
    for r in range(n_robots):
        lo, hi = start[r], start[r + 1]
        if hi - lo < 2 or np.all(out_wait[lo + 1 : hi] >= out_wait[lo : hi - 1]):
            continue
        order = lo + np.argsort(out_wait[lo:hi], kind="mergesort")
        out_wait[lo:hi], out_waitee[lo:hi], out_until[lo:hi] = (
            out_wait[order],
            out_waitee[order],
            out_until[order],
        )
    return out_waiter, out_wait, out_waitee, out_until, start


def without_implied(plan: DependencyPlan, n_robots: int) -> DependencyPlan:
    """``plan`` less each constraint that two others imply through a third robot.

    "i may not pass w until j reached u" is implied by "i may not pass w1 <= w until k
    reached u1" and "k may not pass w2 < u1 until j reached u2 >= u": when i passes w,
    k is past w2 (strictly, by IMPLIED_TOL_M), so j is at u2 or beyond. Removed together,
    the constraints still imply each other along chains that end in kept ones as long as
    the plan never deadlocks, which plans of acyclic schedules never do (docs/paths.md);
    the run is then the same. Every constraint must still be ahead of its waiter (none
    already passed, as in a re-schedule's): a passed wait point proves nothing of its
    waitee. Shapes: D constraints -> D' <= D, sorted by waiter and wait point.

    Robots are reduced in turn, those with the fewest constraints first (the front of a
    queue), and a chain's second link is read among what its robot kept, once reduced:
    the queue behind reads one leader's staircase, not everyone's (a one-way warehouse
    of 250 robots, FCFS: 437,150 constraints, 17,143 kept in ~40 ms, where every second
    link read keeps 15,268 in ~140 ms). Any subset of second links drops only implied
    constraints.
    """
    waiter, wait, waitee, until, start = _by_waiter_and_point(  # (D,) x 4, (R+1,)
        plan.waiter, plan.wait_s, plan.waitee, plan.until_s, n_robots
    )
    order = np.argsort(np.diff(start), kind="stable")  # (R,) fewest constraints first
    keep = _implied_kernel(start, wait, waitee, until, order, IMPLIED_TOL_M)  # (D,)
    return DependencyPlan(waiter[keep], wait[keep], waitee[keep], until[keep])
