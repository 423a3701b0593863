"""Warehouses: rack blocks in a grid, aisles between them, pick stations at the edge.

Blocks of double-sided racks stand in a ``blocks_x`` x ``blocks_y`` grid;
vertical pick aisles run between block columns and cross aisles between block
rows. Storage bays are notches in the rack faces and station bays lie beyond
the bottom (and top) cross aisle, so robots waiting at their start stand off
the lanes. Robots drive from a storage bay to a station or back along
turn-aware shortest routes of the aisle graph (``aisles``).

Aisle styles: ``one_way`` (every lane one-way: alternating, with the outer
ring circulating so every place is reachable), ``two_way`` (one lane, both
directions), ``two_lane`` (a lane per direction a quarter aisle off the
centre, right-hand traffic).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import shapely
from shapely.geometry import Polygon, box

from service.scenarios.aisles import AisleGraph, Bay, Lane, Point, key
from service.scenarios.fleet import FleetParams, check_robot_count, make_robots, sample_radii
from service.scenarios.params import split_params
from service.scenarios.world import World, ring_of

__all__ = ["STYLES", "Layout", "WarehouseParams", "build_layout", "layout_of", "warehouse"]

STYLES = ("one_way", "two_way", "two_lane")
# Metres between a parked robot's footprint and the walls of its bay.
BAY_CLEARANCE = 0.15
RACK_POST = 0.3  # metres of upright between neighbouring bays
RACK_SPINE = 0.8  # metres of shelving between the two rows of bays of a double-sided rack
# Metres between a lane robot's footprint and the rack faces beside its lane.
AISLE_CLEARANCE = 0.3
# Storage bays per robot when the block grid is derived: room to draw distinct bays.
BAYS_PER_ROBOT = 1.5
BLOCK_ASPECT = 1.5  # derived block grids are this much wider than deep


@dataclass(frozen=True)
class WarehouseParams:
    """Layout of a warehouse; ``None`` entries are derived from the fleet."""

    style: str = "two_way"
    blocks_x: int | None = None  # block columns; None: enough bays for the fleet
    blocks_y: int | None = None  # block rows
    rack_length: float = 12.0  # metres along the pick aisle
    aisle_width: float | None = None  # metres; None: the narrowest the style allows
    station_sides: int = 1  # stations below the grid (1) or below and above (2)
    to_station_fraction: float = 0.5  # share of robots driving storage -> station
    parked_in_lanes: float = 0.0  # share of robots starting on the lane, not in their bay
    bay_size: float | None = None  # metres, square bays; None: fits the largest robot

    def __post_init__(self) -> None:
        """Reject parameters that cannot make a warehouse."""
        if self.style not in STYLES:
            raise ValueError(f"style must be one of {STYLES}: {self.style!r}")
        if self.station_sides not in (1, 2):
            raise ValueError(f"station_sides must be 1 or 2: {self.station_sides}")
        for name in ("to_station_fraction", "parked_in_lanes"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must be in [0, 1]: {getattr(self, name)}")

    @property
    def lane_offsets(self) -> tuple[float, ...]:
        """Offsets of an aisle's lanes from its centre: one lane, or a quarter aisle each way."""
        assert self.aisle_width is not None  # resolved
        quarter = self.aisle_width / 4
        return (-quarter, quarter) if self.style == "two_lane" else (0.0,)

    @property
    def pitch(self) -> float:
        """Metres from one bay centre to the next along a rack face."""
        assert self.bay_size is not None  # resolved
        return self.bay_size + RACK_POST

    @property
    def rack_depth(self) -> float:
        """Metres across a double-sided rack: two bay rows and the spine."""
        assert self.bay_size is not None  # resolved
        return 2 * self.bay_size + RACK_SPINE

    def bays_per_face(self) -> int:
        """Storage bays along one face of one rack block."""
        return int((self.rack_length - RACK_POST) // self.pitch)

    def resolved(self, n_robots: int, max_radius: float) -> WarehouseParams:
        """These parameters with bay size, aisle width and block grid filled in and checked."""
        lanes = 2 if self.style == "two_lane" else 1
        narrowest = 2 * lanes * (max_radius + AISLE_CLEARANCE)
        if self.aisle_width is not None and self.aisle_width < narrowest:
            raise ValueError(f"aisle_width {self.aisle_width} < {narrowest:.2f} for this fleet")
        sized = dataclasses.replace(
            self,
            bay_size=self.bay_size or round(2 * (max_radius + BAY_CLEARANCE), 3),
            aisle_width=self.aisle_width or round(narrowest, 3),
        )
        per_block = 2 * sized.bays_per_face()
        if per_block == 0:
            raise ValueError(f"rack_length {self.rack_length} holds no bay")
        blocks = math.ceil(BAYS_PER_ROBOT * n_robots / per_block)
        blocks_x = self.blocks_x or max(1, math.ceil(math.sqrt(blocks * BLOCK_ASPECT)))
        blocks_y = self.blocks_y or max(1, math.ceil(blocks / blocks_x))
        if blocks_x * blocks_y * per_block < n_robots:
            raise ValueError(
                f"{blocks_x * blocks_y * per_block} storage bays for {n_robots} robots"
            )
        return dataclasses.replace(sized, blocks_x=blocks_x, blocks_y=blocks_y)


@dataclass(frozen=True)
class Layout:
    """The geometry of a resolved warehouse."""

    racks: list[Polygon]  # rack blocks with their bays cut out
    lanes: list[Lane]
    storage: list[Bay]
    stations: list[Bay]
    bounds: tuple[float, float, float, float]


def build_layout(p: WarehouseParams) -> Layout:
    """Racks, lanes and bays of resolved parameters (every ``None`` filled in)."""
    assert p.blocks_x and p.blocks_y and p.aisle_width and p.bay_size  # resolved
    w, depth, bay = p.aisle_width, p.rack_depth, p.bay_size
    aisle_x = [w / 2 + i * (w + depth) for i in range(p.blocks_x + 1)]
    cross_y = [bay + w / 2 + j * (w + p.rack_length) for j in range(p.blocks_y + 1)]
    top = cross_y[-1] + w / 2 + (bay if p.station_sides == 2 else 0.0)
    racks, storage = [], []
    for i in range(p.blocks_x):
        for j in range(p.blocks_y):
            rack, bays = rack_block(p, aisle_x[i : i + 2], cross_y[j] + w / 2)
            racks.append(rack)
            storage += bays
    station_rows = [(bay / 2, cross_y[0])] + (
        [(top - bay / 2, cross_y[-1])] if p.station_sides == 2 else []
    )
    stations = [
        station
        for bay_y, lane_y in station_rows
        for i in range(p.blocks_x)
        for station in station_bays(p, aisle_x[i] + w / 2 + depth / 2, bay_y, lane_y)
    ]
    bounds = (0.0, 0.0, round(aisle_x[-1] + w / 2, 6), round(top, 6))
    return Layout(racks, lanes(p, aisle_x, cross_y), storage, stations, bounds)


def rack_block(p: WarehouseParams, aisles: list[float], y0: float) -> tuple[Polygon, list[Bay]]:
    """One double-sided rack between two aisles (centre x), bays notched into both faces."""
    assert p.aisle_width and p.bay_size  # resolved
    bay, n = p.bay_size, p.bays_per_face()
    x0 = aisles[0] + p.aisle_width / 2
    x1 = x0 + p.rack_depth
    margin = (p.rack_length - n * p.pitch - RACK_POST) / 2
    ys = [y0 + margin + RACK_POST + bay / 2 + k * p.pitch for k in range(n)]
    faces = [(x0, x0 + bay, aisles[0], False), (x1 - bay, x1, aisles[1], True)]
    notches, bays = [], []
    for bx0, bx1, aisle, lanes_left in faces:
        offsets = sorted(p.lane_offsets, reverse=not lanes_left)  # nearest lane first
        for y in ys:
            notches.append(box(bx0, y - bay / 2, bx1, y + bay / 2))
            access = tuple(key((aisle + o, y)) for o in offsets)
            bays.append(Bay(key(((bx0 + bx1) / 2, y)), access))
    rack = box(x0, y0, x1, y0 + p.rack_length).difference(shapely.union_all(notches))
    return rack, bays


def station_bays(p: WarehouseParams, x: float, bay_y: float, lane_y: float) -> list[Bay]:
    """The bays of one pick station centred at ``x``, side by side beyond a cross aisle."""
    count = max(1, int(p.rack_depth // p.pitch))
    nearest_first = sorted(p.lane_offsets, key=lambda o: abs(lane_y + o - bay_y))
    return [
        Bay(key((bx, bay_y)), tuple(key((bx, lane_y + o)) for o in nearest_first))
        for bx in (x + (k - (count - 1) / 2) * p.pitch for k in range(count))
    ]


def lanes(p: WarehouseParams, aisle_x: list[float], cross_y: list[float]) -> list[Lane]:
    """Every lane of the aisle grid with its direction (see the module docstring)."""
    reach = max(p.lane_offsets)
    result = []
    for i, x in enumerate(aisle_x):
        for o in p.lane_offsets:
            north = o > 0 if p.style == "two_lane" else i == len(aisle_x) - 1 or i % 2 == 1
            ends = [key((x + o, cross_y[0] - reach)), key((x + o, cross_y[-1] + reach))]
            result.append(lane_along(ends, north, p.style != "two_way"))
    for j, y in enumerate(cross_y):
        for o in p.lane_offsets:
            east = o < 0 if p.style == "two_lane" else j != len(cross_y) - 1 and j % 2 == 0
            ends = [key((aisle_x[0] - reach, y + o)), key((aisle_x[-1] + reach, y + o))]
            result.append(lane_along(ends, east, p.style != "two_way"))
    return result


def lane_along(ends: list[Point], forward: bool, one_way: bool) -> Lane:
    """A lane between ``ends`` (low to high coordinate), reversed when not ``forward``."""
    start, end = ends if forward else ends[::-1]
    return Lane(start, end, one_way)


def draw_trips(
    layout: Layout, p: WarehouseParams, n_robots: int, rng: np.random.Generator
) -> list[tuple[Point, Point]]:
    """(start, goal) of each robot: storage -> station or station -> storage.

    Robots beyond the number of station bays that drew station -> storage drive
    storage -> station instead.
    Storage bays are distinct across robots and station starts too (robots waiting
    at their start never share a spot); robots bound for a station prefer a bay
    nobody starts at. A ``parked_in_lanes`` share starts on the lane in front of
    its bay instead, where the spot is not taken.
    """
    if len(layout.storage) < n_robots:
        raise ValueError(f"{len(layout.storage)} storage bays for {n_robots} robots")
    to_station = rng.random(n_robots) < p.to_station_fraction
    outbound = np.flatnonzero(~to_station)[: len(layout.stations)]  # one station bay each
    cells = rng.choice(len(layout.storage), size=n_robots, replace=False)
    station_starts = rng.choice(len(layout.stations), size=len(outbound), replace=False)
    taken = set(station_starts.tolist())
    goal_stations = [k for k in range(len(layout.stations)) if k not in taken] or list(taken)
    goals = rng.choice(goal_stations, size=n_robots)
    parked = rng.random(n_robots) < p.parked_in_lanes
    trips, starts_used = [], set()
    outbound_station = dict(zip(outbound.tolist(), station_starts.tolist(), strict=True))
    for k in range(n_robots):
        cell = layout.storage[cells[k]]
        if k in outbound_station:
            start_bay, goal = layout.stations[outbound_station[k]], cell.point
        else:
            start_bay, goal = cell, layout.stations[goals[k]].point
        start = start_bay.access[0] if parked[k] else start_bay.point
        if start in starts_used:
            start = start_bay.point
        starts_used.add(start)
        trips.append((start, goal))
    return trips


def warehouse(n_robots: int, style: str, seed: int, **params: Any) -> World:
    """A seeded warehouse of the given aisle ``style`` with ``n_robots`` robots.

    ``params``: any field of ``WarehouseParams`` or ``FleetParams``.
    """
    check_robot_count(n_robots)
    layout_params, fleet = split_params({"style": style, **params}, WarehouseParams, FleetParams)
    rng = np.random.default_rng(seed)
    radii = sample_radii(n_robots, fleet, rng)
    resolved = layout_params.resolved(n_robots, fleet.max_radius)
    layout = build_layout(resolved)
    trips = draw_trips(layout, resolved, n_robots, rng)
    routes = AisleGraph(layout.lanes, layout.storage + layout.stations).routes(trips)
    return World(
        kind=f"wh_{style}",
        params={**dataclasses.asdict(resolved), **dataclasses.asdict(fleet)},
        obstacles=[ring_of(rack) for rack in layout.racks],
        bounds=layout.bounds,
        robots=make_robots(routes, radii, fleet, rng),
    )


def layout_of(world: World) -> Layout:
    """The layout a warehouse world was built on (tests check routes against it)."""
    names = {f.name for f in dataclasses.fields(WarehouseParams)}
    return build_layout(WarehouseParams(**{k: v for k, v in world.params.items() if k in names}))
