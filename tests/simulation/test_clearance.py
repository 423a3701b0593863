"""The clearance check against the sampled reference, and hand-computed cases.

Random trajectories are drawn with a clear margin either way (every pair's sampled
least gap is at least ``BAND`` away from zero), so the sampling resolution of the
reference cannot decide the verdict: the check must report an overlap exactly for
the pairs where the reference finds one, and its least gaps must agree with the
reference's up to the sampling error (never above the sampled value).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, event, given, settings
from hypothesis import strategies as st

from service.simulation.clearance import (
    CHUNK,
    EXACT_BELOW_M,
    Clearance,
    Trajectory,
    check_clearance,
)
from tests.motion.reference_clearance import position, reference_clearance

MAX_SPEED = 3.0  # m/s of the random trajectories
STEP_S = 0.002  # reference sampling step
SAMPLING_ERR = 2 * MAX_SPEED * STEP_S  # bound on sampled minus true least gap
BAND = 0.03  # verdicts closer to zero than this are not drawn


@st.composite
def trajectories_st(draw: st.DrawFn, steps: tuple[int, int] = (1, 5)) -> list[Trajectory]:
    """2-4 robots, ``steps`` + 1 waypoints each, waits (repeated positions), speeds <=
    MAX_SPEED."""
    out = []
    for _ in range(draw(st.integers(2, 4))):
        t = [draw(st.floats(0.0, 5.0))]
        xy = [np.array([draw(st.floats(0.0, 4.0)), draw(st.floats(0.0, 4.0))])]
        for _ in range(draw(st.integers(*steps))):
            dt = draw(st.floats(0.1, 3.0))
            heading = draw(st.floats(0.0, 2 * np.pi))
            dist = draw(st.sampled_from([0.0, 1.0])) * draw(st.floats(0.0, MAX_SPEED * dt))
            t.append(t[-1] + dt)
            xy.append(xy[-1] + dist * np.array([np.cos(heading), np.sin(heading)]))
        out.append(Trajectory(np.array(t), np.array(xy), draw(st.floats(0.2, 0.6))))
    return out


def _gap_at(trajs: list[Trajectory], i: int, j: int, t: float) -> float:
    """Gap of robots i and j at time t by the reference's interpolation."""
    d = np.linalg.norm(position(trajs[i], t) - position(trajs[j], t))
    return float(d - trajs[i].radius - trajs[j].radius)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(trajs=trajectories_st())
def test_check_agrees_with_the_sampled_reference(trajs: list[Trajectory]) -> None:
    _assert_agrees_with_reference(trajs)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(trajs=trajectories_st(steps=(CHUNK + 1, 3 * CHUNK)))
def test_long_trajectories_checked_piece_by_piece_agree_with_the_reference(
    trajs: list[Trajectory],
) -> None:
    """Several broad-phase pieces per robot: the pieces' least gaps are the pairs'."""
    result = _assert_agrees_with_reference(trajs)
    close = result.min_gap is not None and result.min_gap < EXACT_BELOW_M
    event("pieces (least gap below EXACT_BELOW_M)" if close else "whole trajectories")


def _assert_agrees_with_reference(trajs: list[Trajectory]) -> Clearance:
    """The check's verdicts and least gaps are the sampled reference's; returns the check."""
    ref = reference_clearance(trajs, STEP_S)
    assume(all(abs(g) >= BAND for g in ref.pair_gap.values()))
    result = check_clearance(trajs)
    assert {(i, j) for i, j, _, _ in result.overlaps} == ref.overlapping(0.0)
    assert result.ok == (not ref.overlapping(0.0))
    for i, j, when, gap in result.overlaps:
        assert ref.pair_gap[(i, j)] - SAMPLING_ERR <= gap <= ref.pair_gap[(i, j)] + 1e-9
        assert _gap_at(trajs, i, j, when) == pytest.approx(gap, abs=1e-6)
    if ref.overlapping(0.0):
        assert result.min_gap is not None and result.pair is not None
        assert ref.min_gap - SAMPLING_ERR <= result.min_gap <= ref.min_gap + 1e-9
    if result.min_gap is not None:
        assert result.pair is not None and result.time is not None
        assert result.min_gap <= ref.pair_gap[result.pair] + 1e-9
        assert result.min_gap >= ref.pair_gap[result.pair] - SAMPLING_ERR
        assert _gap_at(trajs, *result.pair, result.time) == pytest.approx(result.min_gap, abs=1e-6)
        if result.min_gap < EXACT_BELOW_M:  # then the least of every pair, not only of its own
            assert result.min_gap <= ref.min_gap + 1e-9
    else:
        assert ref.min_gap is None or ref.min_gap > 0
    return result


def _line(t: list[float], xy: list[list[float]], radius: float = 0.5) -> Trajectory:
    return Trajectory(np.array(t, dtype=float), np.array(xy, dtype=float), radius)


def test_robots_crossing_at_the_same_time_overlap_at_the_crossing() -> None:
    a = _line([0, 10], [[-5, 0], [5, 0]])
    b = _line([0, 10], [[0, -5], [0, 5]], radius=0.3)
    result = check_clearance([a, b])
    assert not result.ok
    assert result.min_gap == pytest.approx(-0.8)
    assert result.time == pytest.approx(5.0)
    assert result.pair == (0, 1)
    ((i, j, when, gap),) = result.overlaps
    assert (i, j) == (0, 1) and when == pytest.approx(5.0) and gap == pytest.approx(-0.8)


def test_one_passes_after_the_other_with_the_exact_least_gap() -> None:
    """b reaches the crossing 2 s after a: least distance of (t, 0) and (0, t - 2)."""
    a = _line([0, 10], [[-5, 0], [5, 0]])
    b = _line([0, 10], [[0, -7], [0, 3]])
    result = check_clearance([a, b])
    assert result.ok
    # |(s, s - 2)| is least at s = 1: sqrt(2); both radii 0.5.
    assert result.min_gap == pytest.approx(np.sqrt(2) - 1.0)
    assert result.time == pytest.approx(6.0)


def test_waiting_robot_is_hit_by_a_passing_one() -> None:
    parked = _line([0, 4, 9], [[0, 0], [0, 0], [0, 0]])
    passer = _line([0, 8], [[-4, 0.6], [4, 0.6]])
    result = check_clearance([parked, passer])
    assert not result.ok and result.min_gap == pytest.approx(-0.4)
    assert result.time == pytest.approx(4.0)


def test_presence_runs_from_first_to_last_waypoint_inclusive() -> None:
    gone = _line([0, 5], [[-5, 0], [0, 0]])
    later = _line([6, 10], [[0, 0.2], [0, 5]])
    assert check_clearance([gone, later]).min_gap is None  # never present together
    touching = _line([5, 10], [[0, 0.2], [0, 5]])  # appears at the instant the other arrives
    result = check_clearance([gone, touching])
    assert not result.ok and result.time == pytest.approx(5.0)
    assert result.min_gap == pytest.approx(-0.8)


def test_far_apart_pairs_and_single_robots() -> None:
    far = [_line([0, 1], [[0, 0], [1, 0]]), _line([0, 1], [[0, 50], [1, 50]])]
    assert check_clearance(far).min_gap is None and check_clearance(far).ok
    single = check_clearance(far[:1])
    assert single.ok and single.min_gap is None and single.pair is None


def test_exactly_touching_disks_are_clear() -> None:
    a = _line([0, 10], [[-5, 0], [5, 0]])
    b = _line([0, 10], [[-5, 1.0], [5, 1.0]])
    result = check_clearance([a, b])
    assert result.ok and result.min_gap == pytest.approx(0.0, abs=1e-12)
