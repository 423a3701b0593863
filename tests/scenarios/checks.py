"""Shared assertions on generated worlds: the paths-form robot rules and clearances."""

from __future__ import annotations

import math

import numpy as np
import shapely

from service.scenarios import World

# Metres a checked clearance may fall short by: coordinates are rounded to
# 0.1 mm and generators keep a 5 cm margin, so anything beyond this is a bug.
CLEARANCE_TOL = 1e-3


def assert_valid_robots(world: World, n_robots: int) -> None:
    """Every robot satisfies the paths-form rules, and waiting robots never overlap."""
    assert len(world.robots) == n_robots
    assert len({r["id"] for r in world.robots}) == n_robots
    for robot in world.robots:
        path = np.asarray(robot["path"], dtype=np.float64)
        assert path.ndim == 2 and path.shape[0] >= 2 and path.shape[1] == 2, robot["id"]
        assert np.isfinite(path).all(), robot["id"]
        assert np.all(np.any(np.diff(path, axis=0) != 0, axis=1)), robot["id"]
        assert robot["radius"] > 0 and math.isfinite(robot["radius"])
        if "times" in robot:
            times = np.asarray(robot["times"])
            assert "speed" not in robot and "start_time" not in robot
            assert len(times) == len(path) and times[0] >= 0 and np.isfinite(times).all()
            assert np.all(np.diff(times) > 0), robot["id"]
        else:
            assert robot["speed"] > 0 and math.isfinite(robot["speed"])
            assert robot["start_time"] >= 0 and math.isfinite(robot["start_time"])
    starts = np.array([r["path"][0] for r in world.robots])
    radii = np.array([r["radius"] for r in world.robots])
    gaps = np.linalg.norm(starts[:, None] - starts[None, :], axis=-1) - radii[:, None] - radii
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() >= -CLEARANCE_TOL, "two robots overlap while waiting at their starts"


def assert_clear_of_obstacles(world: World) -> None:
    """Every segment keeps its robot's radius from every obstacle and inside the floor."""
    obstacles = shapely.union_all(world.obstacle_polygons())
    xmin, ymin, xmax, ymax = world.bounds
    for robot in world.robots:
        path = np.asarray(robot["path"])
        segments = shapely.linestrings(np.stack([path[:-1], path[1:]], axis=1))
        if world.obstacles:
            distance = shapely.distance(segments, obstacles)
            assert distance.min() >= robot["radius"] - CLEARANCE_TOL, robot["id"]
        assert path[:, 0].min() >= xmin and path[:, 0].max() <= xmax, robot["id"]
        assert path[:, 1].min() >= ymin and path[:, 1].max() <= ymax, robot["id"]
