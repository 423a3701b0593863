"""Open floors with obstacles: random disks and boxes, optional walls with gaps.

Robots drive between start and goal points drawn in free space (clear of
obstacles and of each other's footprints) along grid A* paths smoothed into
short polylines (``planner``). Variants: sparse or dense clutter (``density``)
and narrow passages (``walls`` crossing the floor, each with a few gaps).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.scenarios.fleet import (
    FleetParams,
    check_robot_count,
    make_robots,
    sample_radii,
)
from service.scenarios.params import split_params
from service.scenarios.planner import CLEARANCE_MARGIN, SQRT2, GridPlanner, largest_component
from service.scenarios.shapes import Box, Disk, Shape
from service.scenarios.world import World, ring_of

__all__ = ["FloorParams", "floor"]

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
    starts, goals = draw_trips(planner, layout, n_robots, fleet.max_radius, rng)
    paths = [planner.plan(s, g, r) for s, g, r in zip(starts, goals, radii.tolist(), strict=True)]
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
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Start and goal cells of each robot: distinct, mutually reachable, far enough apart.

    Endpoints come from the largest free component for the largest robot (so
    every robot can reach every endpoint) and keep ``ENDPOINT_GAP`` between
    footprints; each goal is at least ``min_trip_fraction`` of the shorter
    floor side from its start where the floor allows.
    """
    candidates = largest_component(planner.free_mask(max_radius)) & (
        planner.clearance >= max_radius + ENDPOINT_CLEARANCE
    )
    cells = spread_cells(planner, np.argwhere(candidates), 2 * n_robots, max_radius, rng)
    points = planner.point(np.array(cells))
    min_trip = layout.min_trip_fraction * min(layout.width or 0.0, layout.height or 0.0)
    pool = list(range(n_robots, 2 * n_robots))
    goals = []
    for k in range(n_robots):
        distance = np.linalg.norm(points[pool] - points[k], axis=1)
        far = np.flatnonzero(distance >= min_trip)
        pick = int(rng.choice(far)) if len(far) else int(np.argmax(distance))
        goals.append(cells[pool.pop(pick)])
    return cells[:n_robots], goals


def spread_cells(
    planner: GridPlanner,
    candidates: np.ndarray,
    count: int,
    max_radius: float,
    rng: np.random.Generator,
) -> list[tuple[int, int]]:
    """``count`` cells from ``candidates`` (K, 2), in random order, footprints kept apart."""
    separation = 2 * max_radius + ENDPOINT_GAP
    chosen: list[tuple[int, int]] = []
    points = np.empty((count, 2))
    for cell in rng.permutation(candidates):
        point = planner.point(cell)
        gaps = np.linalg.norm(points[: len(chosen)] - point, axis=1)
        if not chosen or gaps.min() >= separation:
            points[len(chosen)] = point
            chosen.append((int(cell[0]), int(cell[1])))
            if len(chosen) == count:
                return chosen
    raise ValueError(f"the floor has room for {len(chosen)} endpoints, {count} needed")
