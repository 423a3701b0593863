"""From interference boxes to a coordination graph: nodes, conflicts, densities, fixed orders.

* **Nodes**: on each robot, the arc-length intervals of all its boxes (with every
  other robot) merged where they overlap or touch, so a robot's nodes are
  strictly separated and in path order.
* **Conflicts**: one per pair of nodes of two robots that share a box; its pair
  section is the union box (the stretch of each path where that pair interferes).
* **Following**: a conflict may be following-type when the pair drives some of its
  section the same way (a co-directional box: one robot can trail the other) and
  none of it head-on; pure crossings and head-on sections are exclusive.
* **Density**: every node holds every robot of the graph, so that no maximal clique's
  budget binds, and each exclusive-only conflict gets its own density limit (its two
  nodes, ``max_robots`` 1): the density rules forbid following exactly there and
  nowhere else. Collisions are kept out pairwise (each pair's sections and its order),
  not by counting robots: a node is a robot's merged interference along its route (at
  250 robots, about the whole route), so its cliques gather robots that meet at
  different places, and bounding their following by how many fit along one of them
  forbade safe following (docs/paths.md, "Density": executed plans up to 22 % dearer)
  and made every 250-robot floor's cliques too many to serve (413).
* **Fixed orders**: a robot is present at its first point from its start time
  until it moves, so when that point lies in a conflict's section the robot
  parked there must pass first. Two robots parked in each other's way, or a
  cycle of such fixed orders, leave no collision-free plan: a :class:`ProblemError`
  names the robots.

Times of the graph are the planned times at those arc lengths (the robot's own
clock from ``speed``/``start_time`` or ``times``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import networkx as nx
import numba
import numpy as np

from service.core.lazy import cached_property
from service.core.path_schemas import PathsRequest
from service.core.problem import (
    DensityLimits,
    ErrorItem,
    Problem,
    ProblemError,
    problem_from_arrays,
)
from service.core.schemas import PreviousConflictIn, ProgressIn, ScheduleRequest
from service.geometry.interference import Boxes, interference_boxes
from service.geometry.paths import RobotPath, concatenated

__all__ = ["CoordinationGraph", "GeometrySettings", "build_graph"]

# Intervals of one robot closer than this (metres) merge into one node: only exact
# touching (shared piece ends, equal up to rounding) is meant.
TOUCH_TOL = 1e-9
# Work bound of the narrow phase: paths longer in total than MAX_PIECES x resolution are
# cut coarser (conservative sections, same safety) instead of exhausting memory.
MAX_PIECES = 2_000_000


@dataclass(frozen=True)
class GeometrySettings:
    """Resolution and tolerance of the interference geometry (documented in docs/paths.md).

    ``resolution``: longest piece of a path, metres; sections and following gaps are
    conservative by up to this much. ``margin``: extra clearance, metres, that every
    plan keeps between two footprints (it also absorbs floating-point rounding).
    ``max_pairs``: most segment pairs within reach before the request is refused.
    """

    resolution: float = 0.25
    margin: float = 0.05
    max_pairs: int = 5_000_000

    def effective_resolution(self, total_length: float) -> float:
        """``resolution``, coarsened so that all paths together make at most MAX_PIECES pieces."""
        return max(self.resolution, total_length / MAX_PIECES)


@dataclass(frozen=True, eq=False)
class CoordinationGraph:
    """A coordination graph derived from paths, with the geometry behind it.

    Shapes: V nodes, M conflicts, B boxes. A conflict's side a is its lower robot
    index ``i``, side b the higher ``j``; boxes are sorted by conflict.
    """

    paths: tuple[RobotPath, ...]
    node_robot: np.ndarray  # (V,) int, robot of each node, nodes grouped by robot in path order
    node_span: np.ndarray  # (V, 2) float, [s_enter, s_exit] on its robot's path
    node_density: np.ndarray  # (V,) int, robots in the graph (at least 2)
    conf_may_follow: np.ndarray  # (M,) bool, the conflict may be following-type
    conf_node: np.ndarray  # (M, 2) int, node of side a (robot i) and side b (robot j)
    conf_span: np.ndarray  # (M, 4) float, union box x0 x1 (on i) y0 y1 (on j)
    forced: np.ndarray  # (M,) int8, +1 side a first, -1 side b first, 0 free
    boxes: Boxes  # (B,) sorted by conflict
    box_start: np.ndarray  # (M+1,) int, boxes of conflict m are box_start[m]:box_start[m+1]

    @property
    def n_conflicts(self) -> int:
        return int(self.conf_node.shape[0])

    def node_ids(self) -> list[str]:
        """``{robot id}/{k}``: the k-th node of the robot (injective: k has no '/')."""
        return list(self._node_ids)

    @cached_property
    def _node_ids(self) -> tuple[str, ...]:
        first = np.searchsorted(self.node_robot, self.node_robot)  # (V,) robot's first node
        rank = np.arange(self.node_robot.size) - first
        return tuple(
            f"{self.paths[r].id}/{k}"
            for r, k in zip(self.node_robot.tolist(), rank.tolist(), strict=True)
        )

    def robots_in_graph(self) -> np.ndarray:
        """(R',) int: robots with at least one node, in request order."""
        return np.unique(self.node_robot)

    def isolated_robots(self) -> list[str]:
        """Ids of robots that interfere with nobody (they have no node)."""
        inside = set(self.robots_in_graph().tolist())
        return [p.id for r, p in enumerate(self.paths) if r not in inside]

    def node_spans(self) -> dict[str, tuple[float, float]]:
        """Node id -> its arc-length interval ``[s_enter, s_exit]``."""
        return {
            nid: (float(a), float(b))
            for nid, (a, b) in zip(self.node_ids(), self.node_span.tolist(), strict=True)
        }

    def to_request(self, base: PathsRequest) -> ScheduleRequest | None:
        """The graph as a validated graph-form request (objective and options of ``base``);
        None if empty. For callers that post or store it; planning reads :meth:`problem`."""
        wire = self.to_wire(base)
        return None if wire is None else ScheduleRequest.model_validate(wire)

    def to_wire(
        self,
        base: PathsRequest,
        previous: list[PreviousConflictIn] | None = None,
        progress: ProgressIn | None = None,
    ) -> dict[str, Any] | None:
        """The graph-form request body (objective and options of ``base``; ``previous``
        and ``progress`` of a re-schedule) as plain JSON values, every field given as the
        validated model would write it; None if the graph is empty.

        Built in bulk (times by one interpolation per robot and side, ids and dicts from
        Python lists): per-conflict interpolation and numpy scalars cost 0.22 s at 23,000
        conflicts, the bulk build 0.02 s. Not validated here (0.06 s more there): it is
        valid by construction, which the tests check by validating it and posting it.
        """
        if self.node_robot.size == 0:
            return None
        ids = self._node_ids
        node_times = self._node_times.tolist()  # (V, 2)
        density = self.node_density.tolist()
        nodes = [
            {"id": nid, "enter": t0, "exit": t1, "density": d}
            for nid, (t0, t1), d in zip(ids, node_times, density, strict=True)
        ]
        bounds = np.flatnonzero(np.diff(self.node_robot, prepend=-1, append=-1)).tolist()
        robots = [
            {"id": self.paths[r].id, "nodes": nodes[lo:hi], "goal_time": self.paths[r].finish_time}
            for r, lo, hi in zip(
                self.node_robot[bounds[:-1]].tolist(), bounds[:-1], bounds[1:], strict=True
            )
        ]
        return {
            "objective": base.objective,
            "robots": robots,
            "conflicts": self._wire_conflicts(),
            "density_limits": [
                {"nodes": [ids[a], ids[b]], "max_robots": 1}
                for a, b in self.exclusive_pairs().tolist()
            ],
            "options": base.options.model_dump(mode="json"),
            "previous": None
            if previous is None
            else [p.model_dump(mode="json", by_alias=True) for p in previous],
            "progress": None if progress is None else progress.model_dump(mode="json"),
        }

    def problem(self) -> Problem | None:
        """The graph's :class:`Problem` straight from its arrays (the problem of
        :meth:`to_request`, without the wire round trip); None if the graph is empty."""
        if self.node_robot.size == 0:
            return None
        robots = self.robots_in_graph()  # (R',) request index of each problem robot
        local = np.searchsorted(robots, self.node_robot)  # (V,) problem robot of each node
        conf_a, conf_b = self.conf_node[:, 0].copy(), self.conf_node[:, 1].copy()
        ids = self._node_ids
        return problem_from_arrays(
            robot_ids=tuple(self.paths[r].id for r in robots.tolist()),
            node_ids=ids,
            node_robot=local,
            node_enter=self._node_times[:, 0].copy(),
            node_exit=self._node_times[:, 1].copy(),
            node_density=self.node_density.astype(np.int64),
            goal_time=np.array([self.paths[r].finish_time for r in robots.tolist()]),
            conf_a=conf_a,
            conf_b=conf_b,
            pair_enter=self._pair_times[:, [0, 2]],  # (M, 2) side a, side b
            pair_exit=self._pair_times[:, [1, 3]],
            forced=self.forced.astype(np.int8),
            density_limits=DensityLimits.of_pairs(self.exclusive_pairs(), 1),
        )

    @property
    def _node_times(self) -> np.ndarray:
        """(V, 2) planned times at each node's ends."""
        return self._times[: self.node_robot.size]

    @property
    def _pair_times(self) -> np.ndarray:
        """(M, 4) planned times at each conflict's section ends: a enter, a exit, b enter,
        b exit."""
        sides = self._times[self.node_robot.size :]  # (2M, 2) side a of each, then side b
        return np.concatenate([sides[: self.n_conflicts], sides[self.n_conflicts :]], axis=1)

    @cached_property
    def _times(self) -> np.ndarray:
        """(V + 2M, 2) planned times at the ends of every node, then of every conflict's
        section on side a, then on side b: one interpolation per robot for all of them."""
        side_robot = self.node_robot[self.conf_node]  # (M, 2)
        robot = np.concatenate([self.node_robot, side_robot[:, 0], side_robot[:, 1]])
        span = np.concatenate([self.node_span, self.conf_span[:, :2], self.conf_span[:, 2:]])
        return self._times_at(robot, span)

    def _wire_conflicts(self) -> list[dict[str, str | float | None]]:
        """The conflicts as wire dicts: node ids, section times, ``first`` where fixed."""
        ids = self._node_ids
        conflicts: list[dict[str, str | float | None]] = [
            {
                "a": ids[a],
                "b": ids[b],
                "a_enter": ta0,
                "a_exit": ta1,
                "b_enter": tb0,
                "b_exit": tb1,
                "first": None,
            }
            for (a, b), (ta0, ta1, tb0, tb1) in zip(
                self.conf_node.tolist(), self._pair_times.tolist(), strict=True
            )
        ]
        for m in np.flatnonzero(self.forced).tolist():
            conflicts[m]["first"] = "a" if self.forced[m] > 0 else "b"
        return conflicts

    def _times_at(self, robot: np.ndarray, s: np.ndarray) -> np.ndarray:
        """Planned times at arc lengths ``s`` (K, w) of robots ``robot`` (K,): one
        interpolation per robot (the values :meth:`RobotPath.time_at` gives one by one)."""
        times = np.empty_like(s)
        order = np.argsort(robot, kind="stable")
        cuts = np.flatnonzero(np.diff(robot[order])) + 1
        for rows in np.split(order, cuts):
            if rows.size:
                times[rows] = self.paths[int(robot[rows[0]])].time_at(s[rows])
        return times

    def exclusive_pairs(self) -> np.ndarray:
        """(X, 2) int: node pairs of the exclusive-only conflicts (each a density limit of
        one robot)."""
        return self.conf_node[~self.conf_may_follow]


def build_graph(paths: Sequence[RobotPath], settings: GeometrySettings) -> CoordinationGraph:
    """Derive the coordination graph of ``paths``.

    Raises:
        ProblemError: fixed paths leave no collision-free order (robots parked in
            each other's way), naming the robots.
        TooComplex: the paths interfere in more places than the work bound allows.
    """
    resolution = settings.effective_resolution(sum(p.length for p in paths))
    boxes = interference_boxes(paths, resolution, settings.margin, settings.max_pairs)
    node_robot, node_span, box_node_i, box_node_j = _merge_nodes(boxes, len(paths))
    order = _by_node_pair(box_node_i, box_node_j, node_robot.size)  # (B,)
    boxes = boxes.take(order)
    box_node_i, box_node_j = box_node_i[order], box_node_j[order]
    starts = np.ones(boxes.size, dtype=bool)  # (B,) the box starts a conflict
    starts[1:] = (np.diff(box_node_i) != 0) | (np.diff(box_node_j) != 0)
    first = np.flatnonzero(starts)  # (M,)
    box_start = np.append(first, boxes.size)
    conf_node = np.stack([box_node_i[first], box_node_j[first]], axis=1)  # (M, 2)
    conf_span = _union_boxes(boxes, first)
    may_follow = _may_follow(boxes, first)
    graph = CoordinationGraph(
        paths=tuple(paths),
        node_robot=node_robot,
        node_span=node_span,
        node_density=_densities(node_robot),
        conf_may_follow=may_follow,
        conf_node=conf_node,
        conf_span=conf_span,
        forced=_parked_orders(paths, boxes, first, conf_span, settings.margin),
        boxes=boxes,
        box_start=box_start,
    )
    _check_fixed_orders(graph)
    return graph


def _merge_nodes(
    boxes: Boxes, n_robots: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Merge each robot's box intervals into nodes (robots without boxes get none).

    A node starts where a robot's interval, in order of start, begins more than
    TOUCH_TOL after every earlier one (of that robot) has ended. Sorting all 2B
    intervals cost 0.3 s at 1.7 M boxes, so they are first folded into hulls
    (:func:`_hulls`, which leaves the nodes exactly as they are) and only the hulls
    are sorted.

    Returns node_robot (V,), node_span (V, 2), and the node of each box on side i
    and on side j (B,) each.
    """
    hull_robot, hull_lo, hull_hi = _hulls(  # (H,) each
        boxes.i, boxes.x0, boxes.x1, boxes.j, boxes.y0, boxes.y1, n_robots, TOUCH_TOL
    )
    order = np.lexsort((hull_lo, hull_robot))
    node_robot, node_lo, node_hi = _sweep(
        hull_robot[order], hull_lo[order], hull_hi[order], TOUCH_TOL
    )
    node_first = np.searchsorted(node_robot, np.arange(n_robots + 1))  # (R+1,)
    return (
        node_robot,
        np.stack([node_lo, node_hi], axis=1),
        _node_of(boxes.i, boxes.x0, node_first, node_lo),
        _node_of(boxes.j, boxes.y0, node_first, node_lo),
    )


@numba.njit(cache=True, nogil=True)
def _hulls(
    robot_i: np.ndarray,  # (B,) int, side i: robot, lo, hi of each box
    lo_i: np.ndarray,
    hi_i: np.ndarray,
    robot_j: np.ndarray,  # (B,) int, side j
    lo_j: np.ndarray,
    hi_j: np.ndarray,
    n_robots: int,
    tol: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # (H,) robot, lo, hi of each hull
    """Fold the intervals of both sides, in the order given, into hulls: an interval
    that overlaps its robot's open hull (within ``tol``) widens it, else it closes that
    hull and opens its own. A hull is thus a chain of intervals that one node holds, and
    sorting and sweeping the hulls gives exactly the nodes (and spans) that the
    intervals give: no interval of a chain starts more than ``tol`` past what the chain
    before it covers. Boxes come piece by piece along side i's paths, so most fold."""
    size = robot_i.size + robot_j.size
    hulls = (np.empty(size, dtype=np.int64), np.empty(size), np.empty(size))
    is_open = np.zeros(n_robots, dtype=np.bool_)
    open_lo, open_hi = np.empty(n_robots), np.empty(n_robots)
    n = _fold(robot_i, lo_i, hi_i, is_open, open_lo, open_hi, hulls, 0, tol)
    n = _fold(robot_j, lo_j, hi_j, is_open, open_lo, open_hi, hulls, n, tol)
    for r in range(n_robots):
        if is_open[r]:
            hulls[0][n], hulls[1][n], hulls[2][n] = r, open_lo[r], open_hi[r]
            n += 1
    return hulls[0][:n], hulls[1][:n], hulls[2][:n]


@numba.njit(cache=True, nogil=True)
def _fold(
    robot: np.ndarray,  # (B,) int
    lo: np.ndarray,  # (B,) float
    hi: np.ndarray,  # (B,) float
    is_open: np.ndarray,  # (R,) bool, the robot has an open hull
    open_lo: np.ndarray,  # (R,) float
    open_hi: np.ndarray,  # (R,) float
    hulls: tuple[np.ndarray, np.ndarray, np.ndarray],  # closed hulls: robot, lo, hi
    n: int,
    tol: float,
) -> int:
    """Fold intervals into the open hulls (see :func:`_hulls`); the closed hull count."""
    for k in range(robot.size):
        r = robot[k]
        if is_open[r] and lo[k] <= open_hi[r] + tol and open_lo[r] <= hi[k] + tol:
            open_lo[r], open_hi[r] = min(open_lo[r], lo[k]), max(open_hi[r], hi[k])
            continue
        if is_open[r]:
            hulls[0][n], hulls[1][n], hulls[2][n] = r, open_lo[r], open_hi[r]
            n += 1
        is_open[r], open_lo[r], open_hi[r] = True, lo[k], hi[k]
    return n


@numba.njit(cache=True, nogil=True)
def _sweep(
    robot: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # (V,) robot, lo, hi of each node
    """Nodes of intervals sorted by (robot, lo): a node starts where the robot changes
    or an interval starts more than ``tol`` after every earlier one has ended."""
    node_robot = np.empty(robot.size, dtype=np.int64)
    node_lo, node_hi = np.empty(robot.size), np.empty(robot.size)
    v = -1
    for k in range(robot.size):
        if v < 0 or robot[k] != node_robot[v] or lo[k] > node_hi[v] + tol:
            v += 1
            node_robot[v], node_lo[v], node_hi[v] = robot[k], lo[k], hi[k]
        else:
            node_hi[v] = max(node_hi[v], hi[k])
    return node_robot[: v + 1], node_lo[: v + 1], node_hi[: v + 1]


@numba.njit(cache=True, nogil=True)
def _node_of(
    robot: np.ndarray,  # (B,) int
    lo: np.ndarray,  # (B,) float, start of each interval
    node_first: np.ndarray,  # (R+1,) int, nodes of robot r are node_first[r]:node_first[r+1]
    node_lo: np.ndarray,  # (V,) float
) -> np.ndarray:  # (B,) int
    """The node holding each interval: its robot's last node starting at or before it."""
    out = np.empty(robot.size, dtype=np.int64)
    for k in range(robot.size):
        lo_r, hi_r = node_first[robot[k]], node_first[robot[k] + 1]
        out[k] = lo_r + np.searchsorted(node_lo[lo_r:hi_r], lo[k], side="right") - 1
    return out


@numba.njit(cache=True, nogil=True)
def _by_node_pair(node_i: np.ndarray, node_j: np.ndarray, n_nodes: int) -> np.ndarray:
    """(B,) box order by (node i, node j), ties kept in box order: a stable sort, by two
    counting-sort passes (least significant key first), O(B + V). At 1.7 M boxes a
    stable argsort of pair keys with np.unique took 50-65 ms, this 40-50 ms."""
    order = np.arange(node_i.size)
    for key in (node_j, node_i):
        start = np.zeros(n_nodes + 1, dtype=np.int64)  # (V+1,) first slot of each key
        for k in range(key.size):
            start[key[k] + 1] += 1
        start = np.cumsum(start)
        placed = np.empty_like(order)
        for k in order:
            placed[start[key[k]]] = k
            start[key[k]] += 1
        order = placed
    return order


def _union_boxes(boxes: Boxes, first: np.ndarray) -> np.ndarray:
    """(M, 4) bounding box x0 x1 y0 y1 of each conflict's boxes (boxes sorted by conflict)."""
    if first.size == 0:
        return np.zeros((0, 4))
    return np.stack(
        [
            np.minimum.reduceat(boxes.x0, first),
            np.maximum.reduceat(boxes.x1, first),
            np.minimum.reduceat(boxes.y0, first),
            np.maximum.reduceat(boxes.y1, first),
        ],
        axis=1,
    )


def _may_follow(boxes: Boxes, first: np.ndarray) -> np.ndarray:
    """(M,) bool: some of the conflict's boxes co-directional and none head-on."""
    if first.size == 0:
        return np.zeros(0, dtype=bool)
    same_way = np.logical_or.reduceat(boxes.co_directional, first)
    head_on = np.logical_or.reduceat(boxes.head_on, first)
    return same_way & ~head_on


def _densities(node_robot: np.ndarray) -> np.ndarray:
    """(V,) every node holds every robot of the graph (at least 2): then no maximal
    clique, one node per robot at most, has more members than its density, and only the
    exclusive-only conflicts' own limits constrain (see the module's docstring)."""
    robots = np.unique(node_robot).size
    return np.full(node_robot.size, max(robots, 2), dtype=np.int64)


def _parked_orders(
    paths: Sequence[RobotPath],
    boxes: Boxes,
    first: np.ndarray,
    conf_span: np.ndarray,
    margin: float,
) -> np.ndarray:
    """(M,) int8 fixed directions: a robot whose first point lies in the section goes first.

    Side b (exact arc lengths) is parked when its section starts at arc length 0: its
    first point is within reach of a's piece. Side a's arc lengths are pieces, so a
    section starting at 0 only says that a's first *piece* comes within reach; a is
    parked when its first point itself is within reach of b's stretch of such a box
    (else standing at its start is clear of b, and waiting there is safe). Both at
    once is a contradiction that :func:`_check_fixed_orders` reports.
    """
    b_parked = conf_span[:, 2] <= 0.0
    at_start = np.flatnonzero(boxes.x0 <= 0.0)  # (K,) boxes of a's first piece
    points, arc, first_point = concatenated(paths)  # (N, 2), (N,), (R+1,)
    gaps = _start_gaps(  # (K,)
        points,
        arc,
        first_point,
        boxes.i[at_start],
        boxes.j[at_start],
        boxes.y0[at_start],
        boxes.y1[at_start],
    )
    radius = np.array([p.radius for p in paths])  # (R,)
    near = np.zeros(boxes.size, dtype=bool)  # (B,) a's first point within reach in the box
    near[at_start] = gaps < radius[boxes.i[at_start]] + radius[boxes.j[at_start]] + margin
    a_parked = np.logical_or.reduceat(near, first) if first.size else np.zeros(0, dtype=bool)
    return np.where(a_parked & b_parked, 2, a_parked.astype(np.int8) - b_parked).astype(np.int8)


@numba.njit(cache=True, nogil=True)
def _start_gaps(
    points: np.ndarray,  # (N, 2) all paths' points, robot by robot
    arc: np.ndarray,  # (N,) their arc lengths
    first_point: np.ndarray,  # (R+1,) robot r's points are first_point[r]:first_point[r+1]
    robot_a: np.ndarray,  # (K,) int
    robot_b: np.ndarray,  # (K,) int
    s0: np.ndarray,  # (K,) float, stretch of robot b
    s1: np.ndarray,  # (K,) float
) -> np.ndarray:  # (K,) least distance from a's first point to b's stretch s0..s1
    """Least distance from each robot a's first point to robot b's path between arc lengths
    s0 and s1 (the stretch may turn at path vertices: a box's stretch is not assumed
    straight), over the stretch's straight pieces."""
    out = np.empty(robot_a.size)
    for k in range(robot_a.size):
        qx, qy = points[first_point[robot_a[k]], 0], points[first_point[robot_a[k]], 1]
        lo, hi = first_point[robot_b[k]], first_point[robot_b[k] + 1]
        # The piece of b's path from s0 to s1, vertex by vertex.
        v = lo + np.searchsorted(arc[lo:hi], s0[k], side="right") - 1
        v = min(max(v, lo), hi - 2)
        best = np.inf
        s = s0[k]
        while True:
            end = min(s1[k], arc[v + 1])
            ax, ay = _point_at(points, arc, v, s)
            bx, by = _point_at(points, arc, v, end)
            dx, dy = bx - ax, by - ay
            length2 = max(dx * dx + dy * dy, 1e-300)
            f = min(1.0, max(0.0, ((qx - ax) * dx + (qy - ay) * dy) / length2))
            best = min(best, np.hypot(ax + f * dx - qx, ay + f * dy - qy))
            if end >= s1[k] or v + 2 >= hi:
                break
            v, s = v + 1, end
        out[k] = best
    return out


@numba.njit(cache=True, nogil=True)
def _point_at(points: np.ndarray, arc: np.ndarray, v: int, s: float) -> tuple[float, float]:
    """The point at arc length s on the path segment from vertex v to v + 1."""
    f = (s - arc[v]) / (arc[v + 1] - arc[v])
    return (
        points[v, 0] + f * (points[v + 1, 0] - points[v, 0]),
        points[v, 1] + f * (points[v + 1, 1] - points[v, 1]),
    )


def _check_fixed_orders(graph: CoordinationGraph) -> None:
    """Refuse paths whose fixed orders contradict each other (robots parked in each other's way).

    Raises:
        ProblemError: naming the robots of the first contradiction found.
    """
    ids = [p.id for p in graph.paths]
    both = np.flatnonzero(graph.forced == 2)
    if both.size:
        i, j = graph.node_robot[graph.conf_node[both[0]]].tolist()
        raise ProblemError(
            [
                ErrorItem(
                    ("body", "robots", i, "path"),
                    f"robots '{ids[i]}' and '{ids[j]}' each start inside the other's route "
                    "(or their start footprints overlap): neither can pass the other; "
                    "re-plan one of their paths",
                )
            ]
        )
    dag = nx.DiGraph()
    chain = np.flatnonzero(graph.node_robot[1:] == graph.node_robot[:-1])
    dag.add_edges_from(zip(chain.tolist(), (chain + 1).tolist(), strict=True))
    fixed = np.flatnonzero(graph.forced != 0)
    for m in fixed.tolist():
        a, b = graph.conf_node[m].tolist()
        dag.add_edge(*((a, b) if graph.forced[m] > 0 else (b, a)))
    try:
        cycle = nx.find_cycle(dag)
    except nx.NetworkXNoCycle:
        return
    robots = list(dict.fromkeys(int(graph.node_robot[u]) for u, _ in cycle))
    names = ", ".join(f"'{ids[r]}'" for r in robots)
    raise ProblemError(
        [
            ErrorItem(
                ("body", "robots", robots[0], "path"),
                f"robots {names} wait at their starts in each other's routes in a circle: "
                "no order lets them pass; re-plan one of their paths",
            )
        ]
    )
