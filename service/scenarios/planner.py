"""Grid planning on an obstacle floor: clearance field, 8-connected A*, smoothing.

A cell is free for a robot of radius ``r`` when its centre is at least
``r + CLEARANCE_MARGIN + resolution / sqrt(2)`` from every obstacle and the
floor's edge: every point of a step to a free neighbour then lies within half a
diagonal of a free centre, so each grid step is safe without a geometric test.
Smoothing shortcuts the grid path wherever the straight segment keeps
``r + CLEARANCE_MARGIN`` from the (exact, shapely) obstacles.
"""

from __future__ import annotations

import copy
import heapq
import math
from array import array
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numba
import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from service.scenarios.shapes import DISK_QUAD_SEGS, Shape

__all__ = [
    "CLEARANCE_MARGIN",
    "SQRT2",
    "GridPlanner",
    "NoPathError",
    "SearchGrid",
    "largest_component",
]

# Metres every planned segment keeps beyond the robot radius: absorbs the
# rounding of coordinates (0.1 mm) and float error in the distance checks.
CLEARANCE_MARGIN = 0.05
# A* heuristic inflation: a bounded-suboptimal search (at most twice the grid
# optimum; smoothing straightens the detours) that expands fewer cells on open floors.
HEURISTIC_WEIGHT = 2.0
SQRT2 = math.sqrt(2.0)


class NoPathError(RuntimeError):
    """The goal cell is not reachable from the start cell for this radius."""


@dataclass(frozen=True, eq=False)
class SearchGrid:
    """One radius's free cells, flattened with a blocked border, and landmark distances.

    The border lets A* step to neighbours by index offsets without bounds
    checks. Landmark distances make an ALT heuristic: by the triangle
    inequality ``|d(L, v) - d(L, goal)|`` never exceeds ``d(v, goal)``, and
    unlike the straight-line distance it knows the detour around a wall.
    Shapes: N = (ny + 2) * (nx + 2) cells; ``landmarks`` (K, N).
    """

    free: list[bool]
    width: int
    rows: np.ndarray  # (N,) float32 row of each flat cell
    cols: np.ndarray  # (N,) float32 column of each flat cell
    landmarks: np.ndarray  # (K, N) float32 hops from each landmark cell, inf where unreachable

    @classmethod
    def of(cls, free: np.ndarray) -> SearchGrid:
        """The search grid of a (ny, nx) free mask; landmarks: free cells nearest its corners."""
        padded = np.zeros((free.shape[0] + 2, free.shape[1] + 2), dtype=bool)
        padded[1:-1, 1:-1] = free
        cells = np.argwhere(padded)
        landmarks = []
        for corner in ((0, 0), (0, padded.shape[1]), (padded.shape[0], 0), padded.shape):
            if len(cells):
                nearest = cells[np.argmin(np.abs(cells - corner).sum(axis=1))]
                landmarks.append(hop_distances(padded, (int(nearest[0]), int(nearest[1]))))
        rows, cols = np.indices(padded.shape, dtype=np.float32).reshape(2, -1)
        stacked = np.array(landmarks, dtype=np.float32).reshape(len(landmarks), padded.size)
        return cls(padded.ravel().tolist(), padded.shape[1], rows, cols, stacked)


def hop_distances(free: np.ndarray, source: tuple[int, int]) -> np.ndarray:
    """(H * W,) 8-connected hop counts from ``source`` over ``free`` (H, W), inf if unreachable.

    Hops never exceed the grid path cost (a step costs 1 or sqrt 2), so landmark
    bounds from them stay below the true distances.
    """
    return _breadth_first(free, source[0] * free.shape[1] + source[1])


@numba.njit(cache=True, nogil=True)
def _breadth_first(free: np.ndarray, source: int) -> np.ndarray:
    """(H * W,) hops from flat cell ``source`` over ``free`` (H, W), inf where unreachable:
    a breadth-first search with a flat queue (each cell enters it once)."""
    height, width = free.shape
    open_cells = free.ravel()
    distance = np.full(height * width, np.inf)
    queue = np.empty(height * width, dtype=np.int64)
    distance[source], queue[0] = 0.0, source
    head, tail = 0, 1
    while head < tail:
        u = queue[head]
        head += 1
        row, col = u // width, u % width
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                r, c = row + dy, col + dx
                if 0 <= r < height and 0 <= c < width:
                    v = r * width + c
                    if open_cells[v] and distance[v] == np.inf:
                        distance[v] = distance[u] + 1.0
                        queue[tail] = v
                        tail += 1
    return distance


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
    reach: float  # metres: clearances beyond this are not needed and stored as ``reach``
    clearance: np.ndarray = field(init=False)
    obstacles: BaseGeometry = field(init=False)  # the union of the shapes this planner adds
    _base: GridPlanner | None = field(init=False, default=None)  # the floor it adds them to
    _inflated_by: dict[float, BaseGeometry] = field(init=False, default_factory=dict)
    _grids: dict[float, SearchGrid] = field(init=False, default_factory=dict)

    def __post_init__(self) -> None:
        """Compute the clearance field and the obstacles' union once per floor."""
        xs, ys = self.cell_centres()
        x, y = np.meshgrid(xs, ys)
        xmin, ymin, xmax, ymax = self.bounds
        clearance = np.minimum.reduce([x - xmin, xmax - x, y - ymin, ymax - y])
        self.clearance = np.minimum(clearance, self.reach)
        self._lower_clearance(self.shapes)
        self.obstacles = shapely.union_all([s.polygon() for s in self.shapes])

    def with_obstacles(self, extra: Sequence[Shape]) -> GridPlanner:
        """This floor with the ``extra`` shapes as obstacles too.

        Reuses this floor's clearance field and grown obstacles (only the new
        shapes' windows and their own union are computed), so a route planned
        around a few more obstacles costs a search rather than a whole floor.
        """
        planner = copy.copy(self)
        planner.shapes = [*self.shapes, *extra]
        planner.clearance = self.clearance.copy()
        planner._lower_clearance(extra)
        planner.obstacles = shapely.union_all([s.polygon() for s in extra])
        planner._base, planner._inflated_by, planner._grids = self, {}, {}
        return planner

    def _lower_clearance(self, shapes: Sequence[Shape]) -> None:
        """``clearance`` lowered to each shape's distance. Capping clearances at ``reach``
        lets each shape update only the cells within ``reach`` of its bounding box."""
        xs, ys = self.cell_centres()
        for shape in shapes:
            sx0, sy0, sx1, sy1 = shape.bbox
            cols = slice(*np.searchsorted(xs, [sx0 - self.reach, sx1 + self.reach]))
            rows = slice(*np.searchsorted(ys, [sy0 - self.reach, sy1 + self.reach]))
            x, y = np.meshgrid(xs[cols], ys[rows])
            window = self.clearance[rows, cols]
            np.minimum(window, shape.distance(x, y), out=window)

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
        cells = np.array(astar(self._search_grid(radius), start, goal))
        return self.smooth(self.point(turning_cells(cells)), radius)

    def segments_clear(self, a: np.ndarray, ends: np.ndarray, radius: float) -> np.ndarray:
        """(K,) bool, whether each segment from ``a`` (2,) to ``ends`` (K, 2) keeps clear."""
        lines = shapely.linestrings(np.stack([np.broadcast_to(a, ends.shape), ends], axis=1))
        clear = ~shapely.intersects(self._inflated(radius), lines)
        return clear if self._base is None else clear & self._base.segments_clear(a, ends, radius)

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
        """The obstacles this planner adds grown by ``radius + CLEARANCE_MARGIN``, prepared
        (cached per radius).

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

    def _search_grid(self, radius: float) -> SearchGrid:
        """The search grid for ``radius`` (cached per radius)."""
        if radius not in self._grids:
            self._grids[radius] = SearchGrid.of(self.free_mask(radius))
        return self._grids[radius]


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


def astar(grid: SearchGrid, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]]:
    """Cells (i, j) of an 8-connected path on ``grid`` from ``start`` to ``goal``.

    Heuristic: the larger of the octile distance and the landmark bound, times
    ``HEURISTIC_WEIGHT``, computed for all cells in numpy (float32: a heuristic
    needs no more) and read from a flat ``array``, far cheaper than per push
    in Python; ties go to the deeper node. Raises ``NoPathError`` when the goal is unreachable.
    """
    free, width = grid.free, grid.width
    source, target = (start[0] + 1) * width + start[1] + 1, (goal[0] + 1) * width + goal[1] + 1
    dy, dx = np.abs(grid.rows - grid.rows[target]), np.abs(grid.cols - grid.cols[target])
    bound = dx + dy + np.float32(SQRT2 - 2.0) * np.minimum(dx, dy)
    for hops in grid.landmarks:
        if np.isfinite(hops[target]):
            np.maximum(bound, np.abs(hops - hops[target]), out=bound)
    h = array("f", (bound * np.float32(HEURISTIC_WEIGHT)).tobytes())
    steps = neighbour_steps(width)
    cost = array("d", [math.inf]) * len(free)
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
