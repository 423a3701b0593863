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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.geometry.graph import CoordinationGraph
from service.simulation.executor import DependencyPlan

__all__ = ["Decision", "dependency_plan", "staircase"]


@dataclass(frozen=True, eq=False)
class Decision:
    """An assignment of the graph's conflicts. Shapes: M conflicts."""

    a_first: np.ndarray  # (M,) bool, side a (the lower robot index) passes first
    following: np.ndarray  # (M,) bool

    def exclusive(self) -> Decision:
        """The same directions with every conflict exclusive (always executable)."""
        return Decision(self.a_first, np.zeros_like(self.following))


def staircase(until: np.ndarray, wait: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fewest constraints equivalent to "may not pass wait[k] until the other reached until[k]".

    Shapes: (K,) each -> (K',) each, ``until`` ascending. The limit while the other
    robot is before ``u`` is the least ``wait`` over constraints with ``until > u``:
    a non-decreasing step function; one constraint per step is kept.
    """
    order = np.lexsort((-wait, until))  # ties: the least wait last, so only it is kept
    until, wait = until[order], wait[order]
    least = np.minimum.accumulate(wait[::-1])[::-1]  # (K,) least wait from k on
    keep = np.ones(until.size, dtype=bool)
    keep[:-1] = least[:-1] < least[1:]
    return until[keep], least[keep]


@dataclass(frozen=True, eq=False)
class Sections:
    """Boxes grouped into sections: ``order`` (B,) box indices grouped, ``first`` (G,)
    where each group starts in ``order`` (for ``ufunc.reduceat``)."""

    order: np.ndarray
    first: np.ndarray


def sections(x0: np.ndarray, x1: np.ndarray, y0: np.ndarray, y1: np.ndarray) -> Sections:
    """Split one conflict's boxes (B,) where i's arc lengths leave a gap, then j's.

    Any grouping is safe (each group's bounding box contains its boxes); splitting at
    gaps keeps separate meeting places apart.
    """
    order = np.argsort(x0, kind="stable")
    label = _gap_runs(x0[order], x1[order])  # (B,) group along i
    refined = np.empty_like(label)
    for g in np.unique(label):
        members = order[label == g]
        by_y = np.argsort(y0[members], kind="stable")
        sub = _gap_runs(y0[members][by_y], y1[members][by_y])
        refined[np.flatnonzero(label == g)[by_y]] = g * order.size + sub
    grouped = np.argsort(refined, kind="stable")
    _, first = np.unique(refined[grouped], return_index=True)
    return Sections(order[grouped], first)


def _gap_runs(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(K,) run label of intervals sorted by ``lo``: a new run where ``lo`` passes every
    earlier ``hi``."""
    reach = np.maximum.accumulate(hi)
    new = np.ones(lo.size, dtype=bool)
    new[1:] = lo[1:] > reach[:-1]
    return np.cumsum(new) - 1


def dependency_plan(graph: CoordinationGraph, decision: Decision) -> DependencyPlan:
    """The executor's constraints for ``decision`` on ``graph``."""
    parts: list[tuple[np.ndarray, ...]] = []
    boxes = graph.boxes
    for m in range(graph.n_conflicts):
        i, j = graph.node_robot[graph.conf_node[m]].tolist()
        lo, hi = graph.box_start[m], graph.box_start[m + 1]
        x0, x1, y0, y1 = (arr[lo:hi] for arr in (boxes.x0, boxes.x1, boxes.y0, boxes.y1))
        if decision.a_first[m]:
            waiter, waitee, wait, until = j, i, y0, x1
        else:
            waiter, waitee, wait, until = i, j, x0, y1
        if not decision.following[m]:
            group = sections(x0, x1, y0, y1)
            until = np.maximum.reduceat(until[group.order], group.first)
            wait = np.minimum.reduceat(wait[group.order], group.first)
        until, wait = staircase(until, wait)
        parts.append((np.full(wait.size, waiter), wait, np.full(wait.size, waitee), until))
    if not parts:
        return DependencyPlan.empty()
    waiter, wait, waitee, until = (np.concatenate(col) for col in zip(*parts, strict=True))
    return DependencyPlan(waiter.astype(np.int64), wait, waitee.astype(np.int64), until)
