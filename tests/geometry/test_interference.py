"""Interference boxes: they cover every close configuration, none is needlessly far, headings.

The reference is dense sampling of each robot pair's coordination space (s_i, s_j):
every sampled configuration where the two disks come within ``r_i + r_j + margin``
must lie in one of the pair's boxes, and every box must contain a configuration
within ``r_i + r_j + margin + resolution`` (boxes are conservative by at most the
resolution, never made of far-apart configurations only).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.path_schemas import PathsRequest
from service.geometry import interference
from service.geometry.graph import GeometrySettings
from service.geometry.interference import COARSE_PIECE_M, Boxes, Segments, interference_boxes
from service.geometry.paths import RobotPath
from service.scenarios import generate
from tests.motion.worlds import fleets, paths_of, request, robot

SETTINGS = GeometrySettings()
SAMPLE_M = 0.02  # arc-length step of the dense sampling


def _boxes(paths: list[RobotPath], settings: GeometrySettings = SETTINGS) -> Boxes:
    """The interference boxes of ``paths`` under ``settings``."""
    return interference_boxes(paths, settings.resolution, settings.margin, settings.max_pairs)


def _pair_boxes(boxes: Boxes, i: int, j: int) -> np.ndarray:
    """(B', 4) x0 x1 y0 y1 of the boxes of robots i < j."""
    mine = (boxes.i == i) & (boxes.j == j)
    return np.stack([boxes.x0, boxes.x1, boxes.y0, boxes.y1], axis=1)[mine]


def _distances(a: RobotPath, b: RobotPath) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sampled arc lengths (P,), (Q,) (with every vertex) and centre distances (P, Q)."""
    sa = np.unique(np.concatenate([np.arange(0.0, a.length, SAMPLE_M), a.arc]))
    sb = np.unique(np.concatenate([np.arange(0.0, b.length, SAMPLE_M), b.arc]))
    pa, pb = a.position_at(sa), b.position_at(sb)
    return sa, sb, np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=2)


def assert_boxes_sound(paths: list[RobotPath], settings: GeometrySettings) -> Boxes:
    """Cover every close sampled configuration; no box made only of far ones."""
    boxes = _boxes(paths, settings)
    assert np.all(boxes.i < boxes.j)
    assert np.all(boxes.x0 < boxes.x1) and np.all(boxes.y0 < boxes.y1)
    for i in range(len(paths)):
        for j in range(i + 1, len(paths)):
            a, b = paths[i], paths[j]
            mine = _pair_boxes(boxes, i, j)
            assert np.all(mine[:, 0] >= 0) and np.all(mine[:, 1] <= a.length + 1e-9)
            assert np.all(mine[:, 2] >= 0) and np.all(mine[:, 3] <= b.length + 1e-9)
            sa, sb, dist = _distances(a, b)
            reach = a.radius + b.radius + settings.margin
            pi, pj = np.nonzero(dist < reach - 1e-9)
            x, y = sa[pi, None], sb[pj, None]
            covered = (
                (x >= mine[:, 0] - 1e-9)
                & (x <= mine[:, 1] + 1e-9)
                & (y >= mine[:, 2] - 1e-9)
                & (y <= mine[:, 3] + 1e-9)
            ).any(axis=1)
            assert covered.all(), (
                f"robots {i},{j}: configuration {sa[pi[~covered][0]], sb[pj[~covered][0]]} "
                "within reach lies in no box"
            )
            for box in mine:
                nearest = _box_nearest(a, b, tuple(box))
                assert nearest <= reach + settings.resolution + SAMPLE_M, (
                    f"robots {i},{j}: box {box.tolist()} is {nearest} m apart at best"
                )
    return boxes


def _box_nearest(a: RobotPath, b: RobotPath, box: tuple[float, float, float, float]) -> float:
    """Least centre distance over a fine grid of the box (its corners included)."""
    x0, x1, y0, y1 = box
    sx = np.linspace(x0, x1, max(3, math.ceil((x1 - x0) / 0.005)))
    sy = np.linspace(y0, y1, max(3, math.ceil((y1 - y0) / 0.005)))
    pa, pb = a.position_at(sx), b.position_at(sy)
    return float(np.linalg.norm(pa[:, None, :] - pb[None, :, :], axis=2).min())


def _paths(robots: list[dict[str, Any]]) -> list[RobotPath]:
    """Wire robots as arrays."""
    return paths_of(request(robots))


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    angle=st.floats(35.0, 175.0),
    radii=st.tuples(st.floats(0.2, 0.6), st.floats(0.2, 0.6)),
    offsets=st.tuples(st.floats(1.0, 4.0), st.floats(1.0, 4.0)),
)
def test_crossing_straight_paths(
    angle: float, radii: tuple[float, float], offsets: tuple[float, float]
) -> None:
    """Two straight paths through (5, 5) at ``angle`` degrees to each other."""
    u = np.array([math.cos(math.radians(angle)), math.sin(math.radians(angle))])
    centre = np.array([5.0, 5.0])
    robots = [
        robot("a", [centre - [offsets[0], 0.0], centre + [4.0, 0.0]], radius=radii[0]),
        robot("b", [centre - offsets[1] * u, centre + 4.0 * u], radius=radii[1]),
    ]
    boxes = assert_boxes_sound(_paths(robots), SETTINGS)
    assert boxes.size > 0
    assert not boxes.co_directional.any()


@settings(max_examples=25, deadline=None, derandomize=True)
@given(robots=fleets(min_robots=2, max_robots=3), resolution=st.sampled_from([0.1, 0.25, 0.7]))
def test_random_polylines(robots: list[dict[str, Any]], resolution: float) -> None:
    assert_boxes_sound(_paths(robots), GeometrySettings(resolution=resolution, margin=0.05))


def test_self_crossing_path_against_a_crossing_robot() -> None:
    """Out and back along an aisle, crossed by a second robot: two regions on the aisle."""
    robots = [
        robot("aisle", [[0, 0], [6, 0], [0, 0.01]]),
        robot("cross", [[3, -3], [3, 3]]),
    ]
    boxes = assert_boxes_sound(_paths(robots), SETTINGS)
    x = np.concatenate([boxes.x0, boxes.x1])
    assert x.min() < 6.0 < x.max(), "both the way out and the way back interfere"


def test_far_apart_and_single_robots_have_no_boxes() -> None:
    far = _paths([robot("a", [[0, 0], [1, 0]]), robot("b", [[0, 5], [1, 5]])])
    assert _boxes(far).size == 0
    single = _paths([robot("a", [[0, 0], [1, 0]])])
    assert _boxes(single).size == 0


def test_headings_decide_co_direction() -> None:
    """Side by side the same way: co-directional; the opposite way or crossing: not."""
    same = _paths([robot("a", [[0, 0], [10, 0]]), robot("b", [[0, 0.5], [10, 0.5]])])
    boxes = assert_boxes_sound(same, SETTINGS)
    assert boxes.size > 0 and boxes.co_directional.all()
    opposite = _paths([robot("a", [[0, 0], [10, 0]]), robot("b", [[10, 0.5], [0, 0.5]])])
    boxes = assert_boxes_sound(opposite, SETTINGS)
    assert boxes.size > 0 and not boxes.co_directional.any()
    slanted = _paths([robot("a", [[0, 0], [10, 0]]), robot("b", [[0, 0.5], [10, 3.0]])])
    boxes = _boxes(slanted)
    assert boxes.size > 0 and boxes.co_directional.all()  # 14 degrees apart


def test_boxes_on_side_i_are_coarse_pieces_along_a_shared_stretch() -> None:
    paths = _paths([robot("a", [[0, 0], [10, 0]]), robot("b", [[0, 0.5], [10, 0.5]])])
    boxes = _boxes(paths, GeometrySettings(resolution=0.3))
    widths = boxes.x1 - boxes.x0
    assert np.all(widths <= COARSE_PIECE_M + 1e-9)
    assert np.all(widths[:-1] > COARSE_PIECE_M - 0.3)  # all as coarse as pieces allow
    # The pieces of robot a tile its whole path (all of it is within reach of b).
    pieces = np.unique(np.stack([boxes.x0, boxes.x1], axis=1), axis=0)
    np.testing.assert_allclose(pieces[0, 0], 0.0)
    np.testing.assert_allclose(pieces[-1, 1], 10.0)
    np.testing.assert_allclose(pieces[1:, 0], pieces[:-1, 1])


def assert_the_same_boxes_in_parts(paths: list[RobotPath], parts: int) -> None:
    """The narrow phase run in ``parts`` parts on threads gives the boxes of one run, in
    order."""
    whole = _boxes(paths)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(interference, "parts_for", lambda work, least: parts)
        cut = _boxes(paths)
    for field in Boxes.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(cut, field), getattr(whole, field), err_msg=field)


@pytest.mark.parametrize("parts", [2, 3, 7])
def test_boxes_are_the_same_however_the_narrow_phase_is_cut(parts: int) -> None:
    req = PathsRequest.model_validate(generate("wh_two_way", 25, 3).to_request())
    assert_the_same_boxes_in_parts(paths_of(req), parts)


@settings(max_examples=15, deadline=None, derandomize=True)
@given(robots=fleets(min_robots=2, max_robots=5), parts=st.integers(2, 6))
def test_random_fleets_cut_in_parts_give_the_same_boxes(
    robots: list[dict[str, Any]], parts: int
) -> None:
    """Parts that are empty or hold a single segment's candidates change nothing either."""
    assert_the_same_boxes_in_parts(paths_of(request(robots)), parts)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(robots=fleets(min_robots=1, max_robots=5), extra=st.integers(0, 4))
def test_segments_are_each_paths_straight_runs(robots: list[dict[str, Any]], extra: int) -> None:
    """Per robot, the segments run along its path from end to end, each path point lies
    on the segment it falls in, and no segment goes on straight into the next (points
    added inside the paths' segments change nothing)."""
    for r in robots:  # ``extra`` points evenly inside every segment of the path
        pts = np.asarray(r["path"], dtype=float)
        f = np.linspace(0.0, 1.0, extra + 2)[:-1]
        inner = pts[:-1, None, :] + f[None, :, None] * np.diff(pts, axis=0)[:, None, :]
        r["path"] = np.concatenate([inner.reshape(-1, 2), pts[-1:]]).tolist()
        r.pop("times", None)
        r.setdefault("speed", 1.0)
    paths = paths_of(request(robots))
    segs = Segments.of(paths)
    for k, path in enumerate(paths):
        mine = np.flatnonzero(segs.robot == k)
        assert mine.size >= 1 and np.all(np.diff(mine) == 1)
        s0, length, p0, p1 = segs.s0[mine], segs.length[mine], segs.p0[mine], segs.p1[mine]
        assert s0[0] == 0.0 and s0[-1] + length[-1] == pytest.approx(path.length, abs=1e-9)
        np.testing.assert_allclose(s0[1:], s0[:-1] + length[:-1], atol=1e-9)
        np.testing.assert_array_equal(p1[:-1], p0[1:])
        on = np.searchsorted(s0, path.arc, side="right") - 1  # (N,) segment of each point
        f = np.clip((path.arc - s0[on]) / length[on], 0.0, 1.0)[:, None]
        np.testing.assert_allclose(p0[on] + f * (p1[on] - p0[on]), path.points, atol=1e-6)
        heading = (p1 - p0) / length[:, None]
        same = np.einsum("kd,kd->k", heading[:-1], heading[1:]) > 1.0 - 1e-12
        assert not np.any(same), "a straight run split in two"
