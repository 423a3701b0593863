"""Grid planning on an obstacle floor: clearance field, 8-connected A*, smoothing.

A cell is free for a robot of radius ``r`` when its centre is at least
``r + CLEARANCE_MARGIN + resolution / sqrt(2)`` from every obstacle and the
floor's edge: every point of a step to a free neighbour then lies within half a
diagonal of a free centre, so each grid step is safe without a geometric test.
Smoothing shortcuts the grid path wherever the straight segment keeps
``r + CLEARANCE_MARGIN`` from the (exact, shapely) obstacles.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from service.scenarios.shapes import DISK_QUAD_SEGS, Shape

__all__ = ["CLEARANCE_MARGIN", "GridPlanner", "NoPathError"]

# Metres every planned segment keeps beyond the robot radius: absorbs the
# rounding of coordinates (0.1 mm) and float error in the distance checks.
CLEARANCE_MARGIN = 0.05
# A* heuristic inflation: a bounded-suboptimal search (at most twice the grid
# optimum; smoothing straightens the detours) that expands fewer cells on open floors.
HEURISTIC_WEIGHT = 2.0
SQRT2 = math.sqrt(2.0)


class NoPathError(RuntimeError):
    """The goal cell is not reachable from the start cell for this radius."""


@dataclass(eq=False)
class GridPlanner:
    """Plans paths on one floor for robots of any radius (masks cached per radius).

    Shapes: ``clearance`` (ny, nx), distance of each cell centre to the nearest
    obstacle or floor edge, metres; cell (i, j) has its centre at
    ``(xmin + (j + 0.5) * resolution, ymin + (i + 0.5) * resolution)``.
    """

    bounds: tuple[float, float, float, float]
    shapes: Sequence[Shape]
    resolution: float
    clearance: np.ndarray = field(init=False)
    obstacles: BaseGeometry = field(init=False)
    _inflated_by: dict[float, BaseGeometry] = field(init=False, default_factory=dict)
    _free: dict[float, list[bool]] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        """Compute the clearance field and the obstacles' union once per floor."""
        xs, ys = self.cell_centres()
        x, y = np.meshgrid(xs, ys)
        xmin, ymin, xmax, ymax = self.bounds
        clearance = np.minimum.reduce([x - xmin, xmax - x, y - ymin, ymax - y])
        for shape in self.shapes:
            np.minimum(clearance, shape.distance(x, y), out=clearance)
        self.clearance = clearance
        self.obstacles = shapely.union_all([s.polygon() for s in self.shapes])

    @property
    def shape(self) -> tuple[int, int]:
        """(ny, nx) cells."""
        return self.clearance.shape

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """(nx,) x and (ny,) y of the cell centres."""
        xmin, ymin, xmax, ymax = self.bounds
        nx = int((xmax - xmin) / self.resolution)
        ny = int((ymax - ymin) / self.resolution)
        xs = xmin + (np.arange(nx) + 0.5) * self.resolution
        ys = ymin + (np.arange(ny) + 0.5) * self.resolution
        return xs, ys

    def free_mask(self, radius: float) -> np.ndarray:
        """(ny, nx) bool, cells whose every 8-connected step is safe for ``radius``."""
        return self.clearance >= radius + CLEARANCE_MARGIN + self.resolution / SQRT2

    def point(self, cells: np.ndarray | tuple[int, int]) -> np.ndarray:
        """Centres of cells (i, j). Shapes: (..., 2) -> (..., 2) as (x, y)."""
        ij = np.asarray(cells, dtype=np.float64)
        return np.asarray(self.bounds[:2]) + (ij[..., ::-1] + 0.5) * self.resolution

    def plan(self, start: tuple[int, int], goal: tuple[int, int], radius: float) -> np.ndarray:
        """(N, 2) a short polyline from the start to the goal cell centre, clear by ``radius``."""
        a, b = self.point(start), self.point(goal)
        if self.segments_clear(a, b[None, :], radius)[0]:
            return np.stack([a, b])
        cells = np.array(astar(self._padded_free(radius), self.shape[1] + 2, start, goal))
        return self.smooth(self.point(turning_cells(cells)), radius)

    def segments_clear(self, a: np.ndarray, ends: np.ndarray, radius: float) -> np.ndarray:
        """(K,) bool, whether each segment from ``a`` (2,) to ``ends`` (K, 2) keeps clear."""
        lines = shapely.linestrings(np.stack([np.broadcast_to(a, ends.shape), ends], axis=1))
        return ~shapely.intersects(self._inflated(radius), lines)

    def smooth(self, points: np.ndarray, radius: float) -> np.ndarray:
        """(M, 2) the grid path shortcut greedily: from each kept point to the farthest visible."""
        kept = [0]
        while kept[-1] < len(points) - 1:
            i = kept[-1]
            visible = self.segments_clear(points[i], points[i + 1 :], radius)
            visible[0] = True  # a straight grid run is clear by construction (module docstring)
            kept.append(i + 1 + int(np.flatnonzero(visible)[-1]))
        return points[kept]

    def _inflated(self, radius: float) -> BaseGeometry:
        """The obstacles grown by ``radius + CLEARANCE_MARGIN``, prepared (cached per radius).

        A segment clear of it keeps the clearance: a prepared intersection test
        is far cheaper than a distance to every nearby obstacle. The buffer's arcs
        are inscribed chords, short of the true arc by under 0.5 % of the radius,
        which ``CLEARANCE_MARGIN`` covers.
        """
        if radius not in self._inflated_by:
            grown = shapely.buffer(
                self.obstacles, radius + CLEARANCE_MARGIN, quad_segs=DISK_QUAD_SEGS
            )
            shapely.prepare(grown)
            self._inflated_by[radius] = grown
        return self._inflated_by[radius]

    def _padded_free(self, radius: float) -> list[bool]:
        """The free mask for ``radius`` with a blocked border, flattened (cached per radius).

        The border lets A* step to neighbours by index offsets without bounds checks.
        """
        if radius not in self._free:
            padded = np.zeros((self.shape[0] + 2, self.shape[1] + 2), dtype=bool)
            padded[1:-1, 1:-1] = self.free_mask(radius)
            self._free[radius] = padded.ravel().tolist()
        return self._free[radius]


def turning_cells(cells: np.ndarray) -> np.ndarray:
    """The ends of a grid path (N, 2) and the cells where its step direction changes.

    Shortcuts are tried between these only: a straight run adds nothing but checks.
    """
    steps = np.diff(cells, axis=0)
    turns = np.flatnonzero(np.any(steps[1:] != steps[:-1], axis=1)) + 1
    return cells[np.concatenate([[0], turns, [len(cells) - 1]])]


def neighbour_steps(width: int) -> list[tuple[int, float]]:
    """The 8 moves on a flattened grid of row length ``width``: (index offset, cost in cells)."""
    return [(1, 1.0), (-1, 1.0), (width, 1.0), (-width, 1.0)] + [
        (dy * width + dx, SQRT2) for dy in (-1, 1) for dx in (-1, 1)
    ]


def astar(
    free: list[bool], width: int, start: tuple[int, int], goal: tuple[int, int]
) -> list[tuple[int, int]]:
    """Cells (i, j) of an 8-connected path on the padded flattened grid ``free``.

    Octile heuristic times ``HEURISTIC_WEIGHT`` (precomputed for all cells in
    numpy, cheaper than per push in Python); ties go to the deeper node.
    Raises ``NoPathError`` when the goal is unreachable.
    """
    source, target = (start[0] + 1) * width + start[1] + 1, (goal[0] + 1) * width + goal[1] + 1
    rows, cols = np.divmod(np.arange(len(free)), width)
    dy, dx = np.abs(rows - (goal[0] + 1)), np.abs(cols - (goal[1] + 1))
    h = (HEURISTIC_WEIGHT * (dx + dy + (SQRT2 - 2.0) * np.minimum(dx, dy))).tolist()
    steps = neighbour_steps(width)
    cost = [math.inf] * len(free)
    cost[source] = 0.0
    parent = {source: source}
    closed = bytearray(len(free))
    heap = [(h[source], 0.0, source)]
    while heap:
        _, neg_g, u = heapq.heappop(heap)
        if u == target:
            return _cells_back(parent, target, width)
        if closed[u]:
            continue
        closed[u] = 1
        for offset, step in steps:
            v = u + offset
            g = step - neg_g
            if free[v] and g < cost[v]:
                cost[v], parent[v] = g, u
                heapq.heappush(heap, (g + h[v], -g, v))
    raise NoPathError(f"no path from cell {start} to cell {goal}")


def _cells_back(parent: dict[int, int], target: int, width: int) -> list[tuple[int, int]]:
    """The unpadded cells from the source to ``target`` by following parents."""
    chain = [target]
    while parent[chain[-1]] != chain[-1]:
        chain.append(parent[chain[-1]])
    return [(v // width - 1, v % width - 1) for v in reversed(chain)]


def largest_component(free: np.ndarray) -> np.ndarray:
    """(ny, nx) bool, the largest 8-connected component of ``free`` (ny, nx).

    Endpoints drawn from it are mutually reachable; a pocket walled in by
    obstacles would make a robot's trip impossible.
    """
    ny, nx = free.shape
    width = nx + 2
    padded = np.zeros((ny + 2, width), dtype=bool)
    padded[1:-1, 1:-1] = free
    open_cells = padded.ravel().tolist()
    offsets = [offset for offset, _ in neighbour_steps(width)]
    label = [0] * len(open_cells)
    best, best_size = 0, 0
    for seed in np.flatnonzero(padded.ravel()).tolist():
        if label[seed]:
            continue
        current = seed + 1  # labels are seed index + 1, so 0 means "unvisited"
        label[seed], size, queue = current, 1, deque([seed])
        while queue:
            u = queue.popleft()
            for offset in offsets:
                v = u + offset
                if open_cells[v] and not label[v]:
                    label[v] = current
                    size += 1
                    queue.append(v)
        if size > best_size:
            best, best_size = current, size
    return (np.asarray(label).reshape(ny + 2, width) == best)[1:-1, 1:-1]
