"""Open floors with obstacles: random disks and boxes, optional walls with gaps.

Robots drive between start and goal points drawn in free space (clear of
obstacles and of each other's footprints) along grid A* paths smoothed into
short polylines (``planner``). Variants: sparse or dense clutter (``density``)
and narrow passages (``walls`` crossing the floor, each with a few gaps).

A robot waiting at its start blocks every route that passes it: it must leave first.
Where such waits close a cycle (two robots each starting on the other's route, or
rings of more), no schedule exists and the service refuses the paths (422). Planned
without regard to each other, most floors of 50 robots had one (session 55, seeds 0-9:
floor_dense 0 of 10 accepted, floor_sparse 1, floor_passages 0, floor_mixed 0; at 25
robots floor_dense 3). So the routes are planned again in an order
(:func:`unblock_starts`): a route that passes the start of a robot later in the order
goes around it where it can, a start no route can go around moves the robot ahead, and
of two robots facing each other in one corridor one starts from a spare cell instead.
Accepted then (seeds 0-9 unless said): floor_dense 10 of 10 at 25 robots, 9 at 50, 3
of 8 at 100, 0 of 2 at 250 (too crowded: the waits against the order stall, and the
rounds stop, UNBLOCK_PATIENCE); floor_sparse 10 at 50 and 100, 2 of 3 at 250;
floor_passages 10 at 50, 2 of 2 at 250; floor_mixed 10 at 50, 2 of 2 at 250. A floor
of 250 robots then takes ~2.5 s to make (3.5 s where it stalls; re-plans reuse the
floor's planner, :meth:`GridPlanner.with_obstacles`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import shapely

from service.scenarios.fleet import (
    FleetParams,
    check_robot_count,
    make_robots,
    sample_radii,
)
from service.scenarios.params import split_params
from service.scenarios.planner import (
    CLEARANCE_MARGIN,
    SQRT2,
    GridPlanner,
    NoPathError,
    largest_component,
)
from service.scenarios.shapes import Box, Disk, Shape
from service.scenarios.world import World, ring_of

__all__ = ["FloorParams", "floor", "start_passings", "unblock_starts", "waits_order"]

# Default floor size: 10 m^2 of free floor per robot (a busy AMR floor, and A* stays
# fast at 250 robots), never under 20 m a side, 3:2 landscape.
AREA_PER_ROBOT = 10.0
# AREA_PER_ROBOT is free floor for robots of this radius: larger robots and
# more clutter get proportionally more floor.
REFERENCE_RADIUS = 0.4
MIN_SIDE = 20.0
ASPECT = 1.5
WALL_THICKNESS = 0.3  # metres, a partition wall
# Metres beyond the radius a start or goal keeps from obstacles, so robots are
# not parked against a wall.
ENDPOINT_CLEARANCE = 0.3
# Metres between the footprints of any two endpoints: robots waiting at their
# starts never overlap each other, and goals are distinct places.
ENDPOINT_GAP = 0.2
# Metres on each side of a wall gap kept free of clutter, so every gap stays passable.
GAP_KEEP_CLEAR = 1.5
# Metres beyond both radii within which a route passes another robot's start: twice the
# geometry's default margin (0.05 m), so that a route planned around a start is not seen
# passing it by the service either.
START_MARGIN = 2 * CLEARANCE_MARGIN
# Rounds of planning routes around later robots' starts and moving starts (see
# unblock_starts): a route planned around some starts may pass others.
UNBLOCK_ROUNDS = 24
# Rounds without fewer waits against the order after which unblock_starts gives up: on
# floors too crowded to unblock (dense clutter, 250 robots) the count stalls near its start
# while every round costs seconds.
UNBLOCK_PATIENCE = 3
# Spare start cells drawn per robot, where robots that each start on the other's route
# with no way around move one start (see unblock_starts).
SPARE_STARTS = 0.25

Cell = tuple[int, int]


class Trips(NamedTuple):
    """Each robot's start and goal cell, and spare start cells."""

    starts: list[Cell]
    goals: list[Cell]
    spare: list[Cell]


@dataclass(frozen=True)
class FloorParams:
    """Layout of an obstacle floor; ``None`` sizes are derived from the fleet."""

    width: float | None = None  # metres; None: AREA_PER_ROBOT of free floor per robot
    height: float | None = None
    density: float = 0.1  # share of the floor area drawn as clutter obstacles
    disk_fraction: float = 0.5  # share of clutter that is disks (the rest boxes)
    disk_radius_range: tuple[float, float] = (0.3, 1.5)  # metres
    box_side_range: tuple[float, float] = (0.5, 4.0)  # metres, each side drawn apart
    walls: int = 0  # walls spanning the floor's height, evenly spaced in x
    gaps_per_wall: int = 2
    gap_width: float | None = None  # metres; None: the largest robot passes with a cell to spare
    resolution: float = 0.5  # metres per planning grid cell
    min_trip_fraction: float = 0.4  # start-goal distance >= this share of the shorter side

    def __post_init__(self) -> None:
        """Reject parameters that cannot make a floor."""
        if not 0 <= self.density < 1:
            raise ValueError(f"density must be in [0, 1): {self.density}")
        if self.walls < 0 or self.gaps_per_wall < 1:
            raise ValueError("walls must be >= 0 and gaps_per_wall >= 1")
        if self.resolution <= 0:
            raise ValueError(f"resolution must be positive: {self.resolution}")

    def resolved(self, n_robots: int, max_radius: float) -> FloorParams:
        """These parameters with the floor size and gap width filled in."""
        crowding = (max_radius / REFERENCE_RADIUS) ** 2 / (1.0 - self.density)
        area = max(n_robots * AREA_PER_ROBOT, MIN_SIDE * MIN_SIDE * ASPECT) * max(1.0, crowding)
        free_band = max_radius + CLEARANCE_MARGIN + self.resolution / SQRT2
        return dataclasses.replace(
            self,
            width=self.width or round(math.sqrt(area * ASPECT), 1),
            height=self.height or round(math.sqrt(area / ASPECT), 1),
            gap_width=self.gap_width or round(2 * free_band + 2 * self.resolution, 2),
        )


def floor(n_robots: int, seed: int, density: float = 0.1, **params: Any) -> World:
    """A seeded obstacle floor with ``n_robots`` robots on smoothed A* paths.

    ``params``: any field of ``FloorParams`` or ``FleetParams``.
    """
    check_robot_count(n_robots)
    layout, fleet = split_params({"density": density, **params}, FloorParams, FleetParams)
    rng = np.random.default_rng(seed)
    radii = sample_radii(n_robots, fleet, rng)
    layout = layout.resolved(n_robots, fleet.max_radius)
    bounds = (0.0, 0.0, float(layout.width), float(layout.height))
    walls, keep_clear = walls_with_gaps(layout, rng)
    shapes = walls + clutter(layout, keep_clear, rng)
    reach = fleet.max_radius + ENDPOINT_CLEARANCE + layout.resolution  # above every threshold
    planner = GridPlanner(bounds, shapes, layout.resolution, reach)
    trips = draw_trips(planner, layout, n_robots, fleet.max_radius, rng)
    paths = [
        planner.plan(s, g, r)
        for s, g, r in zip(trips.starts, trips.goals, radii.tolist(), strict=True)
    ]
    paths = unblock_starts(planner, trips, radii, paths)
    return World(
        kind="floor",
        params={**dataclasses.asdict(layout), **dataclasses.asdict(fleet)},
        obstacles=[ring_of(shape.polygon()) for shape in shapes],
        bounds=bounds,
        robots=make_robots(paths, radii, fleet, rng),
    )


def walls_with_gaps(layout: FloorParams, rng: np.random.Generator) -> tuple[list[Shape], list[Box]]:
    """Wall pieces across the floor and the zones around their gaps to keep free.

    Each wall's height is split into ``gaps_per_wall`` equal sections with one
    gap drawn inside each, so gaps never overlap.
    """
    assert layout.width and layout.height and layout.gap_width  # resolved
    pieces: list[Shape] = []
    keep_clear: list[Box] = []
    section = layout.height / layout.gaps_per_wall
    half_gap, half_wall = layout.gap_width / 2, WALL_THICKNESS / 2
    for k in range(layout.walls):
        x = layout.width * (k + 1) / (layout.walls + 1)
        low = np.arange(layout.gaps_per_wall) * section
        centres = rng.uniform(low + half_gap, low + section - half_gap)
        edges = [0.0, *[v for c in centres for v in (c - half_gap, c + half_gap)], layout.height]
        for y0, y1 in zip(edges[::2], edges[1::2], strict=True):
            if y1 > y0:
                pieces.append(Box(x - half_wall, y0, x + half_wall, y1))
        keep_clear += [
            Box(x - GAP_KEEP_CLEAR, c - half_gap, x + GAP_KEEP_CLEAR, c + half_gap) for c in centres
        ]
    return pieces, keep_clear


def clutter(layout: FloorParams, keep_clear: list[Box], rng: np.random.Generator) -> list[Shape]:
    """Disks and boxes drawn until their area reaches ``density`` of the floor.

    Shapes that would block a wall gap are drawn but dropped, so the loop always ends.
    """
    assert layout.width and layout.height  # resolved
    target, drawn = layout.density * layout.width * layout.height, 0.0
    zones = [zone.polygon() for zone in keep_clear]
    shapes: list[Shape] = []
    while drawn < target:
        cx, cy = rng.uniform(0.0, layout.width), rng.uniform(0.0, layout.height)
        shape: Shape
        if rng.random() < layout.disk_fraction:
            r = rng.uniform(*layout.disk_radius_range)
            shape, drawn = Disk(cx, cy, r), drawn + math.pi * r * r
        else:
            w, h = rng.uniform(*layout.box_side_range, size=2)
            shape, drawn = Box(cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2), drawn + w * h
        if not any(zone.intersects(shape.polygon()) for zone in zones):
            shapes.append(shape)
    return shapes


def draw_trips(
    planner: GridPlanner,
    layout: FloorParams,
    n_robots: int,
    max_radius: float,
    rng: np.random.Generator,
) -> Trips:
    """Start and goal cells of each robot (distinct, mutually reachable, far enough
    apart) and up to SPARE_STARTS x robots spare start cells.

    Endpoints come from the largest free component for the largest robot (so
    every robot can reach every endpoint) and keep ``ENDPOINT_GAP`` between
    footprints; each goal is at least ``min_trip_fraction`` of the shorter
    floor side from its start where the floor allows. Spare cells keep the gap too;
    drawn after the endpoints, they change none of them.
    """
    candidates = largest_component(planner.free_mask(max_radius)) & (
        planner.clearance >= max_radius + ENDPOINT_CLEARANCE
    )
    spare = int(SPARE_STARTS * n_robots)
    cells = spread_cells(planner, np.argwhere(candidates), 2 * n_robots, max_radius, rng, spare)
    points = planner.point(np.array(cells))
    min_trip = layout.min_trip_fraction * min(layout.width or 0.0, layout.height or 0.0)
    pool = list(range(n_robots, 2 * n_robots))
    goals = []
    for k in range(n_robots):
        distance = np.linalg.norm(points[pool] - points[k], axis=1)
        far = np.flatnonzero(distance >= min_trip)
        pick = int(rng.choice(far)) if len(far) else int(np.argmax(distance))
        goals.append(cells[pool.pop(pick)])
    return Trips(cells[:n_robots], goals, cells[2 * n_robots :])


def spread_cells(
    planner: GridPlanner,
    candidates: np.ndarray,
    count: int,
    max_radius: float,
    rng: np.random.Generator,
    spare: int = 0,
) -> list[Cell]:
    """``count`` cells from ``candidates`` (K, 2), in random order, footprints kept apart,
    and up to ``spare`` more where the floor has room."""
    separation = 2 * max_radius + ENDPOINT_GAP
    chosen: list[Cell] = []
    points = np.empty((count + spare, 2))
    for cell in rng.permutation(candidates):
        point = planner.point(cell)
        gaps = np.linalg.norm(points[: len(chosen)] - point, axis=1)
        if not chosen or gaps.min() >= separation:
            points[len(chosen)] = point
            chosen.append((int(cell[0]), int(cell[1])))
            if len(chosen) == count + spare:
                break
    if len(chosen) < count:
        raise ValueError(f"the floor has room for {len(chosen)} endpoints, {count} needed")
    return chosen


def start_passings(paths: list[np.ndarray], starts: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(R, R) bool: robot i's route (paths[i], (N_i, 2)) passes robot j's start footprint
    (``starts`` (R, 2), ``radii`` (R,)) within START_MARGIN, so j must leave first; i != j."""
    passes = _route_gaps(paths, starts) < radii[:, None] + radii[None, :] + START_MARGIN
    np.fill_diagonal(passes, False)
    return passes


def _route_gaps(paths: list[np.ndarray], points: np.ndarray) -> np.ndarray:
    """(R, P) the least distance from each route (paths[i], (N_i, 2)) to each point (P, 2)."""
    lines = np.array([shapely.LineString(path) for path in paths])  # (R,)
    return shapely.distance(lines[:, None], shapely.points(points)[None, :])


def waits_order(passes: np.ndarray) -> np.ndarray:
    """(R,) each robot's place in an order with few waits against it (robot i passing
    the start of a robot j after it, ``passes[i, j]``): the greedy of Eades, Lin and
    Smyth for a small feedback arc set. Robots no route waits for go last, robots that
    wait for none first, else the robot whose start most routes pass, less the starts
    its own passes, goes next."""
    n = passes.shape[0]
    waits_for = passes.sum(axis=1)  # (R,) starts each route passes, among robots left
    waited_by = passes.sum(axis=0)  # (R,) routes passing each start, among robots left
    left = np.ones(n, dtype=bool)
    head, tail = [], []

    def take(r: int, into: list[int]) -> None:  # robot r placed: it counts no more
        into.append(r)
        left[r] = False
        waits_for[:] -= passes[:, r]
        waited_by[:] -= passes[r]

    while left.any():
        changed = True
        while changed:  # peel robots that wait for none (first) or that none waits for (last)
            changed = False
            for r in np.flatnonzero(left & ((waits_for == 0) | (waited_by == 0))).tolist():
                if left[r]:
                    take(r, head if waits_for[r] == 0 else tail)
                    changed = True
        if left.any():
            take(int(np.flatnonzero(left)[np.argmax((waited_by - waits_for)[left])]), head)
    place = np.empty(n, dtype=np.int64)
    place[head + tail[::-1]] = np.arange(n)
    return place


def unblock_starts(
    planner: GridPlanner, trips: Trips, radii: np.ndarray, paths: list[np.ndarray]
) -> list[np.ndarray]:
    """``paths`` with the waits at starts acyclic where the floor allows, ``trips.starts``
    moved where they must be. In the order of :func:`waits_order`, a route that passes
    the start of a robot later in it is planned again around those starts and the ones it
    avoided before (their footprints grown by START_MARGIN as obstacles); where no route
    goes around them all, around each alone, and a start no route goes around (one
    blocking a corridor) moves just before the robot in the order. Two robots that then
    still each pass the other's start (both in one corridor, facing) cannot both be
    avoided: the later one's start moves to a spare cell that few routes pass
    (:func:`_move_start`). Up to UNBLOCK_ROUNDS rounds (a new route may pass other
    starts); the world may still be refused then. Routes that pass no later start are
    kept as they are."""
    points = planner.point(np.array(trips.starts))  # (R, 2)
    paths = list(paths)
    passes = start_passings(paths, points, radii)
    place = waits_order(passes).astype(np.float64)  # (R,) ranks, a half where robots move
    avoided = np.zeros_like(passes)  # (R, R) the starts each route is planned around
    fewest, stalled = np.inf, 0  # the fewest waits against the order, rounds since
    for _ in range(UNBLOCK_ROUNDS):
        against = passes & (place[None, :] > place[:, None]) & ~avoided  # (R, R)
        count = int(against.sum())
        fewest, stalled = (count, 0) if count < fewest else (fewest, stalled + 1)
        if not against.any() or stalled >= UNBLOCK_PATIENCE:
            break
        for i in np.flatnonzero(against.any(axis=1)).tolist():
            later = np.flatnonzero(against[i])
            tries = [later] if later.size == 1 else [later, *later[:, None]]
            for avoid in tries:
                every = avoided[i] | np.isin(np.arange(radii.size), avoid)  # (R,)
                route = _around(planner, trips, points, radii, every, i)
                if route is not None:
                    paths[i], avoided[i, avoid] = route, True
                    if avoid.size == later.size:
                        break
                elif avoid.size == 1:  # a start the route cannot but pass: it leaves first
                    place[avoid[0]] = place[i] - 0.5
            place = np.argsort(np.argsort(place, kind="stable")).astype(np.float64)  # ranks
        passes = start_passings(paths, points, radii)
        for i, j in np.argwhere(np.triu(passes & passes.T)).tolist():
            later = i if place[i] > place[j] else j
            if (
                passes[i, j]
                and passes[j, i]
                and _move_start(planner, trips, points, radii, paths, later)
            ):
                avoided[later] = False
                passes = start_passings(paths, points, radii)
    return paths


def _move_start(
    planner: GridPlanner,
    trips: Trips,
    points: np.ndarray,
    radii: np.ndarray,
    paths: list[np.ndarray],
    robot: int,
) -> bool:
    """Robot's start moved to the spare cell that the fewest routes pass, the nearest of
    those, and its route planned from there (``trips``, ``points`` (R, 2) and ``paths``
    updated) -> whether a spare cell was left."""
    if not trips.spare:
        return False
    spare = planner.point(np.array(trips.spare))  # (S, 2)
    gap = _route_gaps(paths, spare)  # (R, S)
    passed = (gap < radii[:, None] + radii[robot] + START_MARGIN).sum(axis=0)  # (S,)
    passed -= gap[robot] < 2 * radii[robot] + START_MARGIN  # its own route moves with it
    distance = np.linalg.norm(spare - points[robot], axis=1)
    cell = trips.spare.pop(int(np.lexsort((distance, passed))[0]))
    trips.starts[robot], points[robot] = cell, planner.point(cell)
    paths[robot] = planner.plan(cell, trips.goals[robot], float(radii[robot]))
    return True


def _around(
    planner: GridPlanner,
    trips: Trips,
    points: np.ndarray,
    radii: np.ndarray,
    avoid: np.ndarray,
    robot: int,
) -> np.ndarray | None:
    """Robot's route around the start footprints ``avoid`` (R,) bool of ``points`` (R, 2)
    grown by START_MARGIN (None: there is none)."""
    parked = [
        Disk(float(points[j, 0]), float(points[j, 1]), float(radii[j]) + START_MARGIN)
        for j in np.flatnonzero(avoid)
    ]
    around = planner.with_obstacles(parked)
    try:
        return around.plan(trips.starts[robot], trips.goals[robot], float(radii[robot]))
    except NoPathError:
        return None
