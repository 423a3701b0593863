"""RobotPath: arc lengths, planned times from speed or ``times``, and the s <-> t <-> xy maps."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.path_schemas import PathRobotIn
from service.geometry.paths import RobotPath
from tests.motion.worlds import fleets, robot

L_PATH = [[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]]  # a 3-4 corner: arc 0, 3, 7


def _path(**kwargs: object) -> RobotPath:
    """The L path with the given timing."""
    return RobotPath.from_wire(PathRobotIn.model_validate(robot("r", L_PATH, **kwargs)))


def test_arc_length_and_times_from_speed_and_start_time() -> None:
    path = _path(speed=2.0, start_time=1.5, radius=0.3)
    np.testing.assert_array_equal(path.arc, [0.0, 3.0, 7.0])
    np.testing.assert_allclose(path.times, [1.5, 3.0, 5.0])
    assert path.length == 7.0
    assert (path.start_time, path.finish_time, path.radius) == (1.5, 5.0, 0.3)
    np.testing.assert_allclose(path.segment_speeds(), [2.0, 2.0])


def test_start_time_defaults_to_zero() -> None:
    path = _path(speed=1.0)
    np.testing.assert_allclose(path.times, [0.0, 3.0, 7.0])


def test_times_give_each_segment_its_own_speed() -> None:
    path = _path(times=[2.0, 5.0, 7.0])
    np.testing.assert_array_equal(path.times, [2.0, 5.0, 7.0])
    np.testing.assert_allclose(path.segment_speeds(), [1.0, 2.0])
    assert (path.start_time, path.finish_time) == (2.0, 7.0)


def test_exact_maps_at_vertices_and_inside_segments() -> None:
    path = _path(times=[2.0, 5.0, 7.0])
    np.testing.assert_allclose(path.time_at([0.0, 1.5, 3.0, 5.0, 7.0]), [2.0, 3.5, 5.0, 6.0, 7.0])
    np.testing.assert_allclose(path.arc_at([2.0, 3.5, 5.0, 6.0, 7.0]), [0.0, 1.5, 3.0, 5.0, 7.0])
    np.testing.assert_allclose(
        path.position_at(np.array([0.0, 1.5, 3.0, 5.0, 7.0])),
        [[0.0, 0.0], [1.5, 0.0], [3.0, 0.0], [3.0, 2.0], [3.0, 4.0]],
    )
    assert path.position_at(5.0).shape == (2,)


def test_arc_at_is_clamped_to_the_path() -> None:
    path = _path(speed=1.0, start_time=10.0)
    np.testing.assert_allclose(path.arc_at([0.0, 9.99, 100.0]), [0.0, 0.0, 7.0])


@settings(max_examples=30, deadline=None, derandomize=True)
@given(robots=fleets(min_robots=1, max_robots=1), f=st.floats(0.0, 1.0))
def test_time_and_arc_are_inverse_and_positions_lie_on_segments(
    robots: list[dict[str, object]], f: float
) -> None:
    path = RobotPath.from_wire(PathRobotIn.model_validate(robots[0]))
    assert path.arc[0] == 0.0 and np.all(np.diff(path.arc) > 0)
    assert np.all(np.diff(path.times) > 0)
    s = f * path.length
    assert float(path.arc_at(path.time_at(s))) == pytest.approx(s, abs=1e-9)
    k = min(int(np.searchsorted(path.arc, s, side="right")) - 1, path.arc.size - 2)
    p0, p1 = path.points[k], path.points[k + 1]
    expected = p0 + (s - path.arc[k]) / (path.arc[k + 1] - path.arc[k]) * (p1 - p0)
    np.testing.assert_allclose(path.position_at(s), expected, atol=1e-9)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(robots=fleets(min_robots=1, max_robots=6))
def test_paths_built_in_bulk_are_those_built_one_by_one(robots: list[dict[str, object]]) -> None:
    """The same points, arc lengths and times to the bit, and the same ids and radii."""
    wire = [PathRobotIn.model_validate(r) for r in robots]
    bulk = RobotPath.all_from_wire(wire)
    assert len(bulk) == len(wire)
    for got, one in zip(bulk, (RobotPath.from_wire(r) for r in wire), strict=True):
        assert (got.id, got.radius) == (one.id, one.radius)
        for field in ("points", "arc", "times"):
            np.testing.assert_array_equal(getattr(got, field), getattr(one, field), err_msg=field)
    assert RobotPath.all_from_wire([]) == []
