"""Arc-length and time interpolation helpers on cases with exact answers."""

from __future__ import annotations

import numpy as np
import pytest

from service.pictures.geometry import (
    cumulative_lengths,
    point_at_length,
    positions_at,
    sub_polyline,
    wait_intervals,
)

# An L: 4 m east, then 3 m north.
L_PATH = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]])


def test_cumulative_lengths_add_up_segments() -> None:
    assert cumulative_lengths(L_PATH).tolist() == [0.0, 4.0, 7.0]


def test_point_at_length_interpolates_and_clips() -> None:
    points = point_at_length(L_PATH, np.array([-1.0, 2.0, 4.0, 5.5, 99.0]))
    assert points.tolist() == [[0, 0], [2, 0], [4, 0], [4, 1.5], [4, 3]]
    assert point_at_length(L_PATH, 6.0).tolist() == [4.0, 2.0]


def test_sub_polyline_keeps_the_corner_inside() -> None:
    assert sub_polyline(L_PATH, 2.0, 6.0).tolist() == [[2, 0], [4, 0], [4, 2]]


def test_sub_polyline_within_one_segment_and_reversed_bounds() -> None:
    assert sub_polyline(L_PATH, 6.0, 5.0).tolist() == [[4, 1], [4, 2]]


def test_sub_polyline_clips_to_the_path() -> None:
    assert sub_polyline(L_PATH, -3.0, 50.0).tolist() == L_PATH.tolist()


def test_positions_at_interpolates_linearly_and_reports_presence() -> None:
    points = np.array([[1.0, 0.0, 0.0], [3.0, 2.0, 0.0], [5.0, 2.0, 0.0], [7.0, 2.0, 2.0]])
    xy, present = positions_at(points, np.array([0.0, 2.0, 4.0, 6.0, 8.0]))
    assert xy.tolist() == [[0, 0], [1, 0], [2, 0], [2, 1], [2, 2]]
    assert present.tolist() == [False, True, True, True, False]


def test_wait_intervals_merge_touching_runs() -> None:
    points = np.array([[0, 0, 0], [1, 1, 0], [2, 1, 0], [3.5, 1, 0], [4, 2, 0]], dtype=float)
    assert wait_intervals(points) == [(1.0, 3.5)]


def test_wait_intervals_tolerate_float_noise() -> None:
    points = np.array([[0, 0, 0], [2, 1e-9, 0], [3, 1, 0]], dtype=float)
    assert wait_intervals(points) == [(0.0, 2.0)]


@pytest.mark.parametrize(
    ("completion", "expected"), [(None, [(1.0, 4.0)]), (1.0, []), (2.5, [(1.0, 2.5)])]
)
def test_standing_after_completion_is_no_wait(
    completion: float | None, expected: list[tuple[float, float]]
) -> None:
    points = np.array([[0, 0, 0], [1, 1, 0], [4, 1, 0]], dtype=float)
    assert wait_intervals(points, completion) == expected


def test_moving_robot_has_no_wait() -> None:
    assert wait_intervals(np.array([[0, 0, 0], [1, 1, 0], [2, 2, 1]], dtype=float)) == []
