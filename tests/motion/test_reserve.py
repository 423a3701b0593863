"""The time a paths-form answer keeps for motion: learned from what motion took, and
taken off the solve's deadline."""

from __future__ import annotations

import json
import time
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from service.geometry.graph import GeometrySettings
from service.motion import plan as plan_module
from service.motion.plan import derive, plan_paths
from service.motion.reserve import MotionReserve, work_units
from service.solvers.dispatch import DispatchPolicy
from tests.motion.scenarios import SCENARIOS
from tests.motion.worlds import request

observations = st.lists(
    st.tuples(st.integers(0, 100_000), st.floats(0.0, 5.0, allow_nan=False)), max_size=20
)


def test_seconds_grow_with_the_problem() -> None:
    reserve = MotionReserve(seconds_per_unit=1e-5, base_s=0.01, margin=1.5)
    assert reserve.seconds(0) == pytest.approx(0.015)
    assert reserve.seconds(10_000) == pytest.approx(1.5 * (0.01 + 0.1))


def test_a_slower_motion_is_followed_at_once_a_faster_one_gradually() -> None:
    reserve = MotionReserve(seconds_per_unit=1e-5, base_s=0.01, min_units=1_000, decay=0.25)
    reserve.observe(10_000, 0.01 + 0.3)  # 3e-5 per unit
    assert reserve.seconds_per_unit == pytest.approx(3e-5)
    reserve.observe(10_000, 0.01 + 0.1)  # 1e-5 per unit: a quarter of the way down
    assert reserve.seconds_per_unit == pytest.approx(3e-5 - 0.25 * 2e-5)


def test_small_problems_teach_nothing() -> None:
    reserve = MotionReserve(seconds_per_unit=1e-5, min_units=2_000)
    reserve.observe(1_999, 10.0)
    assert reserve.seconds_per_unit == 1e-5


@given(observations)
def test_the_rate_stays_within_what_was_observed(seen: list[tuple[int, float]]) -> None:
    """Never below the least rate observed (or the start), never above the largest."""
    reserve = MotionReserve(seconds_per_unit=1e-5, base_s=0.01, min_units=100)
    rates = [1e-5]
    for units, seconds in seen:
        reserve.observe(units, seconds)
        if units >= 100:
            rates.append(max(seconds - 0.01, 0.0) / units)
    assert min(rates) - 1e-15 <= reserve.seconds_per_unit <= max(rates) + 1e-15
    if len(rates) > 1 and rates[-1] >= max(rates[:-1]):
        assert reserve.seconds_per_unit == pytest.approx(rates[-1])


@given(observations, st.integers(0, 50_000), st.integers(0, 50_000))
def test_a_larger_problem_keeps_no_less(
    seen: list[tuple[int, float]], small: int, extra: int
) -> None:
    reserve = MotionReserve(min_units=100)
    for units, seconds in seen:
        reserve.observe(units, seconds)
    assert reserve.seconds(small + extra) >= reserve.seconds(small) > 0


def test_the_solve_stops_early_enough_for_motion(monkeypatch: pytest.MonkeyPatch) -> None:
    """The dispatcher's deadline is the request's, less the reserve for the problem's
    work units; the reserve then learns what motion took."""
    req = request(SCENARIOS["three_way"](), solver="fcfs", time_limit_s=2.0)
    problem = derive(req, GeometrySettings()).problem()
    assert problem is not None
    units = work_units(problem)
    seen: dict[str, Any] = {}
    dispatch_problem = plan_module.dispatch_problem

    def spy(*args: Any, deadline: float, **kwargs: Any) -> Any:
        seen["deadline"] = deadline
        return dispatch_problem(*args, deadline=deadline, **kwargs)

    monkeypatch.setattr(plan_module, "dispatch_problem", spy)
    reserve = MotionReserve(seconds_per_unit=0.5 / units, base_s=0.0, margin=1.0, min_units=0)
    due = time.monotonic() + 2.0
    out = plan_paths(req, DispatchPolicy(), GeometrySettings(), deadline=due, reserve=reserve)
    assert seen["deadline"] == pytest.approx(due - 0.5)
    # Motion of a few robots takes milliseconds: the rate came down a fifth of the way.
    observed = (out.response.timings.motion_s + out.encode_s) / units
    assert observed < 0.5 / units
    assert reserve.seconds_per_unit == pytest.approx(0.5 / units + 0.2 * (observed - 0.5 / units))


def test_a_reserve_past_the_deadline_still_leaves_the_solve_its_least_time(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    req = request(SCENARIOS["three_way"](), solver="fcfs", time_limit_s=0.1)
    seen: dict[str, float] = {}
    dispatch_problem = plan_module.dispatch_problem

    def spy(*args: Any, deadline: float, **kwargs: Any) -> Any:
        seen["left"] = deadline - time.monotonic()
        return dispatch_problem(*args, deadline=deadline, **kwargs)

    monkeypatch.setattr(plan_module, "dispatch_problem", spy)
    reserve = MotionReserve(seconds_per_unit=1.0)  # seconds per unit: far past the limit
    out = plan_paths(req, DispatchPolicy(), GeometrySettings(), reserve=reserve)
    assert plan_module.MIN_SOLVE_S - 0.01 <= seen["left"] <= plan_module.MIN_SOLVE_S
    assert out.response.checks.collision_free


def test_the_reserve_learns_the_answers_encoding_too() -> None:
    """What the reserve keeps covers the answer's JSON body, which the route sends as
    :func:`plan_paths` encoded it."""
    req = request(SCENARIOS["three_way"](), solver="fcfs", time_limit_s=2.0)
    problem = derive(req, GeometrySettings()).problem()
    assert problem is not None
    units = work_units(problem)
    reserve = MotionReserve(seconds_per_unit=0.0, base_s=0.0, min_units=0)  # any rate is slower
    out = plan_paths(req, DispatchPolicy(), GeometrySettings(), reserve=reserve)
    assert out.encode_s > 0
    motion_s = out.response.timings.motion_s
    assert reserve.seconds_per_unit == pytest.approx((motion_s + out.encode_s) / units)
    assert json.loads(out.content) == out.response.model_dump(mode="json", by_alias=True)
