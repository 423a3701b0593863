"""Obstacle floors: clearance, passages, parameters."""

from __future__ import annotations

import numpy as np
import pytest

from service.scenarios import floor
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
