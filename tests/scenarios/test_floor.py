"""Obstacle floors: clearance, passages, parameters, no cycle of robots waiting at starts."""

from __future__ import annotations

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.path_schemas import PathsRequest
from service.geometry.graph import GeometrySettings
from service.motion.plan import derive
from service.scenarios import floor, generate
from service.scenarios.floor import Trips, start_passings, unblock_starts, waits_order
from service.scenarios.planner import GridPlanner
from tests.scenarios.checks import assert_clear_of_obstacles, assert_valid_robots


@pytest.mark.parametrize("density", [0.0, 0.1, 0.3])
def test_paths_keep_each_robots_radius_from_obstacles(density: float) -> None:
    world = floor(40, seed=1, density=density, radius_choices=(0.3, 0.6))
    assert_valid_robots(world, 40)
    assert_clear_of_obstacles(world)
    assert {r["radius"] for r in world.robots} == {0.3, 0.6}


def test_walls_split_the_floor_and_robots_cross_through_gaps() -> None:
    world = floor(30, seed=2, density=0.0, walls=1, gaps_per_wall=1, min_trip_fraction=0.8)
    assert_clear_of_obstacles(world)
    wall_x = world.params["width"] / 2
    crossing = [r for r in world.robots if (np.asarray(r["path"])[[0, -1], 0] < wall_x).sum() == 1]
    assert crossing, "some trips cross the wall"


def test_smoothed_paths_are_short_polylines() -> None:
    world = floor(50, seed=4, density=0.15)
    assert np.mean([len(r["path"]) for r in world.robots]) < 8


def test_timed_robots_get_piecewise_times() -> None:
    world = floor(20, seed=5, timed_fraction=1.0)
    assert all("times" in r and "speed" not in r for r in world.robots)


def test_unknown_parameter_is_refused() -> None:
    with pytest.raises(TypeError, match="densty"):
        floor(5, seed=0, densty=0.1)


def _waits_close_a_cycle(passes: np.ndarray) -> bool:
    """Whether the waits at starts (j leaves before i where passes[i, j]) close a cycle."""
    return not nx.is_directed_acyclic_graph(nx.DiGraph(zip(*np.nonzero(passes.T), strict=True)))


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 9).flatmap(lambda n: st.lists(st.booleans(), min_size=n * n, max_size=n * n)))
def test_the_waits_order_puts_every_start_before_the_routes_passing_it_where_it_can(
    flags: list[bool],
) -> None:
    n = int(round(len(flags) ** 0.5))
    passes = np.array(flags).reshape(n, n)
    np.fill_diagonal(passes, False)
    place = waits_order(passes)
    assert sorted(place.tolist()) == list(range(n))
    against = passes & (place[None, :] > place[:, None])  # i passes a later robot's start
    if not _waits_close_a_cycle(passes):
        assert not against.any()
    assert against.sum() <= passes.sum() / 2  # Eades et al.: at most half the arcs


def test_a_route_passes_a_start_within_both_radii_and_the_margin() -> None:
    paths = [np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[5.0, 0.85], [5.0, 9.0]])]
    starts = np.array([p[0] for p in paths])
    passes = start_passings(paths, starts, np.array([0.4, 0.4]))
    assert passes.tolist() == [[False, True], [False, False]]  # 0.85 < 0.4 + 0.4 + 0.1
    far = [paths[0], paths[1] + [0.0, 0.1]]  # 0.95 from the first route
    assert not start_passings(far, np.array([p[0] for p in far]), np.array([0.4, 0.4])).any()


def _facing(height: float, spare: list[tuple[int, int]]) -> tuple[list[np.ndarray], Trips]:
    """Two robots on a floor ``height`` m high, each route over the other's start; spare
    start cells ``spare``."""
    planner = GridPlanner((0.0, 0.0, 20.0, height), [], 0.5, 2.0)
    row = int(height)  # the middle row of 0.5-m cells
    trips = Trips([(row, 9), (row, 19)], [(row, 29), (row, 3)], spare)
    paths = [planner.plan(s, g, 0.4) for s, g in zip(trips.starts, trips.goals, strict=True)]
    return [planner, *paths], trips


@pytest.mark.parametrize("height", [8.0, 3.0])
def test_two_robots_starting_on_each_others_route_no_longer_wait_for_each_other(
    height: float,
) -> None:
    (planner, *paths), trips = _facing(height, [(int(height), 35)])
    radii = np.array([0.4, 0.4])
    before = start_passings(paths, planner.point(np.array(trips.starts)), radii)
    assert before[0, 1] and before[1, 0]
    after = unblock_starts(planner, trips, radii, paths)
    passes = start_passings(after, planner.point(np.array(trips.starts)), radii)
    assert not _waits_close_a_cycle(passes)
    moved = trips.starts != [(int(height), 9), (int(height), 19)]
    assert moved == (height < 4)  # open floor: a route goes around; a corridor: a start moves
    for path, start, goal in zip(after, trips.starts, trips.goals, strict=True):
        assert np.allclose(path[[0, -1]], planner.point(np.array([start, goal])))


@pytest.mark.parametrize("kind", ["floor_dense", "floor_sparse", "floor_passages", "floor_mixed"])
def test_floors_of_fifty_robots_have_paths_the_service_accepts(kind: str) -> None:
    world = generate(kind, 50, 0)
    assert_valid_robots(world, 50)
    assert_clear_of_obstacles(world)
    paths = PathsRequest.model_validate(world.to_request("avg_completion"))
    assert derive(paths, GeometrySettings()).to_request(paths) is not None  # no 422
