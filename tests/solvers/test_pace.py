"""The pace of a stepped search, on a clock the test moves."""

from __future__ import annotations

import sys

from hypothesis import given, settings
from hypothesis import strategies as st

from service.solvers.pace import Pace


class _Clock:
    """A clock that moves only when told."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def test_a_step_fits_only_where_one_as_long_ends_before_the_deadline() -> None:
    clock = _Clock()
    pace = Pace(10.0, clock)
    assert pace.fits() and pace.fits(margin_s=9.9) and not pace.fits(margin_s=10.0)
    clock.now = 3.0  # a step of 3 s
    pace.record(0.0, units=4)
    assert (pace.step_s, pace.per_unit_s, pace.left()) == (3.0, 0.75, 7.0)
    assert pace.fits() and pace.fits(scale=2.0) and not pace.fits(scale=2.0, margin_s=1.0)
    clock.now = 7.5
    assert not pace.fits() and pace.fits(scale=0.5)


def test_units_fit_at_the_last_pace_within_a_slice_and_none_past_the_deadline() -> None:
    clock = _Clock()
    pace = Pace(1.0, clock)
    assert pace.units() == sys.maxsize  # no pace yet
    clock.now = 0.1
    pace.record(0.0, units=10)  # 10 ms a unit
    assert pace.units() == 90 and pace.units(within_s=0.05) == 5
    clock.now = 1.0
    assert pace.units() == 0 and pace.units(within_s=0.05) == 0


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    step=st.floats(1e-6, 5.0),
    units=st.integers(1, 10_000),
    now=st.floats(0.0, 10.0),
    within=st.floats(1e-3, 10.0),
)
def test_the_units_that_fit_take_no_more_than_the_time_allowed(
    step: float, units: int, now: float, within: float
) -> None:
    clock = _Clock()
    pace = Pace(10.0, clock)
    clock.now = step
    pace.record(0.0, units)
    clock.now = now
    fit = pace.units(within)
    allowed = min(within, 10.0 - now)
    assert fit >= 0
    assert fit * pace.per_unit_s <= max(allowed, 0.0) + 1e-9
    assert (fit + 1) * pace.per_unit_s > allowed - 1e-9 or fit == 0 and allowed <= 0
