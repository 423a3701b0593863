"""Warehouses: routes on lanes, one-way directions, bays off the lanes, connectivity."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest

from service.scenarios import STYLES, warehouse
from service.scenarios.aisles import AisleGraph, Lane
from service.scenarios.warehouse import layout_of
from tests.scenarios.checks import assert_clear_of_obstacles, assert_valid_robots

# Metres within which a path point counts as lying on a lane's centre line
# (coordinates are rounded to 0.1 mm).
ON_LANE_TOL = 1e-3


def lane_under(a: np.ndarray, b: np.ndarray, lanes: list[Lane]) -> Lane | None:
    """The lane whose centre line holds the segment from ``a`` to ``b``, if any."""
    for lane in lanes:
        axis = 1 if lane.vertical else 0
        across = lane.start[1 - axis]
        low, high = sorted((lane.start[axis], lane.end[axis]))
        if all(
            abs(p[1 - axis] - across) <= ON_LANE_TOL
            and low - ON_LANE_TOL <= p[axis] <= high + ON_LANE_TOL
            for p in (a, b)
        ):
            return lane
    return None


@pytest.mark.parametrize("style", STYLES)
def test_routes_drive_lanes_between_spurs_and_respect_one_way(style: str) -> None:
    world = warehouse(80, style, seed=3, parked_in_lanes=0.2, station_sides=2)
    assert_valid_robots(world, 80)
    assert_clear_of_obstacles(world)
    lanes = layout_of(world).lanes
    for robot in world.robots:
        path = np.asarray(robot["path"])
        for k, (a, b) in enumerate(zip(path[:-1], path[1:], strict=True)):
            lane = lane_under(a, b, lanes)
            if lane is None:
                assert k in (0, len(path) - 2), f"{robot['id']} leaves the lanes mid-route"
                assert a[0] == b[0] or a[1] == b[1], "spurs are straight"
            elif lane.one_way:
                forward = np.subtract(lane.end, lane.start)
                assert np.dot(b - a, forward) > 0, f"{robot['id']} drives a one-way lane backwards"


@pytest.mark.parametrize("style", STYLES)
def test_starts_sit_off_the_lanes_unless_parked(style: str) -> None:
    world = warehouse(60, style, seed=1)
    lanes = layout_of(world).lanes
    for robot in world.robots:
        start = np.asarray(robot["path"][0])
        assert lane_under(start, start, lanes) is None, robot["id"]


def test_parked_share_starts_on_lanes() -> None:
    world = warehouse(100, "two_way", seed=2, parked_in_lanes=0.5)
    lanes = layout_of(world).lanes
    on_lane = sum(
        lane_under(np.asarray(r["path"][0]), np.asarray(r["path"][0]), lanes) is not None
        for r in world.robots
    )
    assert 25 <= on_lane <= 75


@pytest.mark.parametrize("style", STYLES)
@pytest.mark.parametrize("blocks", [(1, 1), (2, 3), (4, 2)])
def test_every_place_reaches_every_other(style: str, blocks: tuple[int, int]) -> None:
    world = warehouse(2, style, seed=0, blocks_x=blocks[0], blocks_y=blocks[1])
    layout = layout_of(world)
    graph = AisleGraph(layout.lanes, layout.storage + layout.stations).graph
    assert nx.is_strongly_connected(graph)


def test_too_narrow_aisles_are_refused() -> None:
    with pytest.raises(ValueError, match="aisle_width"):
        warehouse(10, "two_lane", seed=0, aisle_width=2.0)
