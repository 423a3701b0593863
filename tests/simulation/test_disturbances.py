"""Disturbance profiles (seeded, documented distributions), rates per robot, clock playback."""

from __future__ import annotations

import numpy as np
import pytest

from service.simulation.clearance import Trajectory
from service.simulation.disturbances import (
    PROFILES,
    Disturbance,
    Rate,
    played_by_clock,
    rates_of,
)

N = 4000  # robots of the statistical checks: shares within ~4 standard errors
WINDOWS = [(f"r{k}", float(k % 7), float(k % 7) + 100.0) for k in range(N)]


def test_a_draw_is_reproducible_for_its_seed_and_differs_across_seeds() -> None:
    heavy = PROFILES["heavy"]
    assert heavy.draw(WINDOWS[:50], 3) == heavy.draw(WINDOWS[:50], 3)
    assert heavy.draw(WINDOWS[:50], 3) != heavy.draw(WINDOWS[:50], 4)


@pytest.mark.parametrize("name", ["light", "heavy"])
def test_each_kind_follows_its_documented_distribution(name: str) -> None:
    profile = PROFILES[name]
    out = profile.draw(WINDOWS, 0)
    window = {rid: (a, b) for rid, a, b in WINDOWS}
    late = [d for d in out if d.factor == 0.0 and d.start == window[d.robot][0]]
    slow = [d for d in out if d.factor > 0.0]
    stops = [d for d in out if d.factor == 0.0 and d not in late]
    for hazard, drawn in ((profile.late_start, late), (profile.stop, stops)):
        share = len({d.robot for d in drawn}) / N
        assert share == pytest.approx(hazard.share, abs=4 * np.sqrt(hazard.share / N))
        durations = np.array([d.duration for d in drawn])
        assert durations.mean() == pytest.approx(hazard.mean_s, rel=0.15)
    assert len(slow) / N == pytest.approx(profile.slow_down.share, abs=0.03)
    factors = np.array([d.factor for d in slow])
    lo, hi = profile.slow_down.factor
    assert lo <= factors.min() and factors.max() <= hi and 0.0 < lo < hi < 1.0
    for d in stops + slow:  # they begin inside the robot's window
        assert window[d.robot][0] <= d.start <= window[d.robot][1]


def test_heavy_hits_more_robots_for_longer_than_light() -> None:
    light, heavy = PROFILES["light"], PROFILES["heavy"]
    for kind in ("late_start", "stop", "slow_down"):
        a, b = getattr(light, kind), getattr(heavy, kind)
        assert a.share < b.share and a.mean_s < b.mean_s


def test_the_control_draws_nothing() -> None:
    assert PROFILES["none"].quiet and PROFILES["none"].draw(WINDOWS[:100], 0) == []
    assert not PROFILES["light"].quiet


def test_rates_follow_the_robot_order_and_combine_pieces() -> None:
    disturbances = [Disturbance("b", 2.0, 3.0), Disturbance("b", 10.0, 4.0, 0.5)]
    rate_a, rate_b = rates_of(["a", "b"], disturbances)
    assert rate_a.constant
    assert rate_b.progress(0.0, 20.0) == pytest.approx(20.0 - 3.0 - 2.0)


# ---- playing a trajectory back by a disturbed clock ------------------------------------

# 0-4 s: x 0 -> 4; waits 4-6 s; 6-8 s: y 0 -> 2.
TRAJ = Trajectory(
    np.array([0.0, 4.0, 6.0, 8.0]), np.array([[0, 0], [4, 0], [4, 0], [4, 2]], float), 0.4
)


def test_an_undisturbed_playback_is_the_trajectory() -> None:
    out = played_by_clock(TRAJ, Rate())
    np.testing.assert_array_equal(out.t, TRAJ.t)
    np.testing.assert_array_equal(out.xy, TRAJ.xy)
    assert out.radius == TRAJ.radius


def test_a_stop_delays_everything_after_it_and_the_robot_stands_meanwhile() -> None:
    out = played_by_clock(TRAJ, Rate.of([(2.0, 3.0, 0.0)]))  # stopped at x=2 from t=2 to 5
    np.testing.assert_allclose(out.t, [0.0, 2.0, 5.0, 7.0, 9.0, 11.0])
    np.testing.assert_allclose(out.xy, [[0, 0], [2, 0], [2, 0], [4, 0], [4, 0], [4, 2]])


def test_a_slow_down_stretches_the_motion_inside_it() -> None:
    out = played_by_clock(TRAJ, Rate.of([(0.0, 4.0, 0.5)]))  # half speed for 4 s: x=2 at t=4
    np.testing.assert_allclose(out.t, [0.0, 4.0, 6.0, 8.0, 10.0])
    np.testing.assert_allclose(out.xy, [[0, 0], [2, 0], [4, 0], [4, 0], [4, 2]])
