"""The executor: planned motion, waits at wait points, disturbances, deadlocks.

Expected times are worked out by hand: each robot drives at its planned speed
from its start time, stops exactly at a blocking ``wait_s`` until the waitee
reaches ``until_s``, and a disturbance scales its progress rate.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import event, example, given, settings
from hypothesis import strategies as st

from service.geometry.paths import RobotPath
from service.motion.trajectories import trajectories
from service.simulation.disturbances import Rate
from service.simulation.executor import DependencyPlan, Execution, Run, execute
from tests.motion.worlds import paths_of, request, robot
from tests.simulation.reference_executor import step_execute

# Three parallel lanes 10 m long (far apart: constraints here are abstract).
LANE = [[[0.0, 5.0 * k], [10.0, 5.0 * k]] for k in range(3)]


def _paths(*robots: dict[str, Any]) -> list[RobotPath]:
    return paths_of(request(list(robots)))


def _plan(*constraints: tuple[int, float, int, float]) -> DependencyPlan:
    """From (waiter, wait_s, waitee, until_s) rows."""
    if not constraints:
        return DependencyPlan.empty()
    waiter, wait_s, waitee, until_s = zip(*constraints, strict=True)
    return DependencyPlan(
        np.array(waiter, dtype=np.int64),
        np.array(wait_s, dtype=float),
        np.array(waitee, dtype=np.int64),
        np.array(until_s, dtype=float),
    )


def _track(paths: list[RobotPath], run: Run, r: int) -> list[tuple[float, float]]:
    """Robot r's waypoints as (wall time, arc length), rounded for comparison."""
    arcs = run.arcs(paths)[r]
    pairs = zip(run.wall[r].tolist(), arcs.tolist(), strict=True)
    return [(round(w, 9), round(s, 9)) for w, s in pairs]


def _assert_never_faster(paths: list[RobotPath], run: Run) -> None:
    """Between waypoints, progress never outruns the planned clock (rate <= 1)."""
    for wall, clock in zip(run.wall, run.clock, strict=True):
        assert np.all(np.diff(wall) >= 0) and np.all(np.diff(clock) >= 0)
        assert np.all(np.diff(clock) <= np.diff(wall) + 1e-9)


def test_unconstrained_robot_follows_its_planned_times_exactly() -> None:
    paths = _paths(robot("r", [[0, 0], [2, 0], [2, 3], [6, 3]], times=[1.0, 3.0, 4.5, 12.0]))
    run = execute(paths, DependencyPlan.empty())
    assert run.deadlocked == ()
    assert run.completion.tolist() == [12.0]
    np.testing.assert_allclose(run.wall[0], [1.0, 3.0, 4.5, 12.0])
    (traj,) = trajectories(paths, run)
    np.testing.assert_allclose(traj.t, [1.0, 3.0, 4.5, 12.0])
    np.testing.assert_allclose(traj.xy, paths[0].points)
    assert traj.radius == paths[0].radius


def test_waiter_stops_exactly_at_its_wait_point_until_the_waitee_passes() -> None:
    """b (2 m/s) reaches s=4 at t=2, waits until a (1 m/s) reaches s=6 at t=6, then 3 s more."""
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    run = execute(paths, _plan((1, 4.0, 0, 6.0)))
    assert run.completion.tolist() == [10.0, 9.0]
    assert _track(paths, run, 1) == [(0.0, 0.0), (2.0, 4.0), (6.0, 4.0), (9.0, 10.0)]
    assert _track(paths, run, 0) == [(0.0, 0.0), (10.0, 10.0)]
    (_, traj_b) = trajectories(paths, run)
    np.testing.assert_allclose(traj_b.xy, [[0, 5], [4, 5], [4, 5], [10, 5]])


def test_constraint_already_satisfied_costs_nothing() -> None:
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    run = execute(paths, _plan((1, 4.0, 0, 1.0)))  # a is at 1 m at t=1, b at 4 m at t=2
    assert run.completion.tolist() == [10.0, 5.0]


def test_late_waitee_and_a_chain_of_waits() -> None:
    """a starts at t=5; b waits at 4 for a at 6 (t=11); c (2 m/s from t=1) waits at 2 for b
    at 8 (t=13), then drives 8 m in 4 s."""
    paths = _paths(
        robot("a", LANE[0], start_time=5.0),
        robot("b", LANE[1], speed=2.0),
        robot("c", LANE[2], times=[1.0, 6.0]),
    )
    run = execute(paths, _plan((1, 4.0, 0, 6.0), (2, 2.0, 1, 8.0)))
    assert run.completion.tolist() == [15.0, 14.0, 17.0]
    assert _track(paths, run, 2) == [(1.0, 0.0), (2.0, 2.0), (13.0, 2.0), (17.0, 10.0)]


def test_several_wait_points_of_one_waiter() -> None:
    """b waits at 2 for a at 3, and at 6 for a at 9 (a staircase)."""
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    run = execute(paths, _plan((1, 6.0, 0, 9.0), (1, 2.0, 0, 3.0)))
    assert _track(paths, run, 1) == [
        (0.0, 0.0),
        (1.0, 2.0),
        (3.0, 2.0),
        (5.0, 6.0),
        (9.0, 6.0),
        (11.0, 10.0),
    ]


def test_a_finished_waitee_has_reached_every_point() -> None:
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    run = execute(paths, _plan((1, 0.0, 0, 10.0)))
    assert run.completion.tolist() == [10.0, 15.0]
    assert _track(paths, run, 1)[:2] == [(0.0, 0.0), (10.0, 0.0)]


def test_a_cyclic_plan_reports_the_deadlocked_robots() -> None:
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1]), robot("c", LANE[2]))
    run = execute(paths, _plan((0, 3.0, 1, 5.0), (1, 3.0, 0, 5.0)))
    assert run.deadlocked == (0, 1)
    assert np.isnan(run.completion[:2]).all() and run.completion[2] == 10.0
    assert _track(paths, run, 0)[-1] == (3.0, 3.0)  # it stopped at its wait point


# ---- disturbances --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("pieces", "completion"),
    [
        ([(2.0, 3.0, 0.0)], 13.0),  # a stop delays by its duration
        ([(2.0, 4.0, 0.5)], 12.0),  # a slow-down by duration x (1 - factor)
        ([(0.0, 4.0, 0.0)], 14.0),  # a late start is a stop from the start time
        ([(-5.0, 3.0, 0.0)], 10.0),  # before the start: nothing
        ([(8.0, 10.0, 0.25)], 16.0),  # 2 s at full speed left: 8 s at a quarter
        ([(2.0, 3.0, 0.0), (4.0, 2.0, 0.5)], 13.5),  # overlap takes the smaller factor
    ],
)
def test_disturbances_delay_completion(
    pieces: list[tuple[float, float, float]], completion: float
) -> None:
    paths = _paths(robot("a", LANE[0]))
    run = execute(paths, DependencyPlan.empty(), [Rate.of(pieces)])
    assert run.completion[0] == pytest.approx(completion)
    _assert_never_faster(paths, run)


def test_a_stopped_waitee_holds_its_waiter() -> None:
    """a stops from t=3 for 4 s, so it reaches s=6 at t=10; b waits at 4 until then."""
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    rates = [Rate.of([(3.0, 4.0, 0.0)]), Rate()]
    run = execute(paths, _plan((1, 4.0, 0, 6.0)), rates)
    assert run.completion.tolist() == [14.0, 13.0]
    assert _track(paths, run, 1) == [(0.0, 0.0), (2.0, 4.0), (10.0, 4.0), (13.0, 10.0)]
    assert _track(paths, run, 0) == [(0.0, 0.0), (3.0, 3.0), (7.0, 3.0), (14.0, 10.0)]


def test_a_slowed_waiter_resumes_at_its_rate() -> None:
    """b waits at 4 until t=6, then drives at half speed (1 m/s) for 6 m."""
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    run = execute(paths, _plan((1, 4.0, 0, 6.0)), [Rate(), Rate.of([(5.0, 100.0, 0.5)])])
    assert run.completion[1] == pytest.approx(12.0)
    _assert_never_faster(paths, run)


pieces_st = st.lists(
    st.tuples(st.floats(0.0, 20.0), st.floats(0.01, 5.0), st.sampled_from([0.0, 0.3, 0.5, 0.9])),
    max_size=4,
)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(pieces=pieces_st, t0=st.floats(0.0, 25.0), gain=st.floats(0.0, 20.0))
def test_advance_and_progress_are_inverse(
    pieces: list[tuple[float, float, float]], t0: float, gain: float
) -> None:
    rate = Rate.of(pieces)
    t1 = rate.advance(t0, gain)
    assert t1 >= t0 + gain - 1e-9, "never faster than rate 1"
    assert rate.progress(t0, t1) == pytest.approx(gain, abs=1e-9)
    # The earliest such time: any earlier one has gained less.
    if gain > 1e-6:
        assert rate.progress(t0, t1 - 1e-6) < gain
    t2 = t0 + gain
    back = rate.advance(t0, rate.progress(t0, t2))
    assert back <= t2 + 1e-9
    assert rate.progress(t0, back) == pytest.approx(rate.progress(t0, t2), abs=1e-9)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(pieces=pieces_st, start=st.floats(0.0, 5.0), speed=st.floats(0.3, 2.0))
# The clock at the stop's start rounded one ulp behind the one at its end (fixed in
# executor._expand): the robot drove back by 1e-15 m.
@example(pieces=[(6.0, 4.549359826459009, 0.0)], start=1.953534914790887, speed=1.0)
def test_a_disturbed_robot_finishes_when_its_progress_is_complete(
    pieces: list[tuple[float, float, float]], start: float, speed: float
) -> None:
    paths = _paths(robot("a", [[0, 0], [3, 0], [3, 4]], speed=speed, start_time=start))
    rate = Rate.of(pieces)
    run = execute(paths, DependencyPlan.empty(), [rate])
    duration = paths[0].finish_time - start
    assert run.completion[0] == pytest.approx(rate.advance(start, duration), abs=1e-9)
    assert run.completion[0] >= paths[0].finish_time - 1e-9
    _assert_never_faster(paths, run)
    # Path vertices are waypoints (positions are linear between waypoints).
    nearest = np.abs(run.clock[0][:, None] - paths[0].times[None, :]).min(axis=0)
    assert np.all(nearest < 1e-9)


# ---- against the time-stepped reference ------------------------------------------------

STEP_DT = 4e-3


@st.composite
def plans_st(draw: st.DrawFn) -> tuple[list[RobotPath], DependencyPlan, list[Rate]]:
    """2-4 robots on lanes of 2-8 m, 0-6 random constraints (cycles allowed), disturbances."""
    n = draw(st.integers(2, 4))
    robots = [
        robot(
            f"r{k}",
            [[0.0, 5.0 * k], [draw(st.floats(2.0, 8.0)), 5.0 * k]],
            speed=draw(st.floats(0.5, 2.0)),
            start_time=draw(st.floats(0.0, 3.0)),
        )
        for k in range(n)
    ]
    paths = _paths(*robots)
    rows = []
    for _ in range(draw(st.integers(0, 6))):
        w, e = draw(st.permutations(range(n)))[:2]
        wait_s = draw(st.floats(0.05, 0.95)) * paths[w].length
        until_s = draw(st.floats(0.05, 1.0)) * paths[e].length
        rows.append((w, wait_s, e, until_s))
    piece = st.tuples(st.floats(0.0, 10.0), st.floats(0.1, 3.0), st.sampled_from([0.0, 0.5]))
    rates = [Rate.of(draw(st.lists(piece, max_size=2))) for _ in range(n)]
    return paths, _plan(*rows), rates


@settings(max_examples=15, deadline=None, derandomize=True)
@given(case=plans_st())
def test_executor_agrees_with_a_time_stepped_reference(
    case: tuple[list[RobotPath], DependencyPlan, list[Rate]],
) -> None:
    paths, plan, rates = case
    run = execute(paths, plan, rates)
    event(f"deadlocked: {bool(run.deadlocked)}")
    horizon = max(p.finish_time for p in paths) * 4 + 20.0
    ref = step_execute(paths, plan, rates, STEP_DT, horizon)
    assert run.deadlocked == ref.stuck
    hops = plan.size + 2  # each dependency hop may lag the reference by a step
    for r in range(len(paths)):
        if r in ref.stuck:
            assert np.isnan(run.completion[r])
        else:
            assert run.completion[r] == pytest.approx(ref.completion[r], abs=4 * hops * STEP_DT)
    _assert_never_faster(paths, run)


def test_the_reference_keeps_a_stop_that_begins_within_a_step_of_the_finish() -> None:
    """a (1 m/s, 4 m) stops from t=3.999 for 1 s: it finishes at 5.0, by the executor and
    by the reference (which once read the rate at each step's middle and finished it at
    4.0, skipping the stop: a falsifying example of the test above in CI)."""
    paths = _paths(robot("a", [[0.0, 0.0], [4.0, 0.0]]))
    rates = [Rate.of([(3.999, 1.0, 0.0)])]
    run = execute(paths, DependencyPlan.empty(), rates)
    ref = step_execute(paths, DependencyPlan.empty(), rates, STEP_DT, 30.0)
    assert run.completion[0] == pytest.approx(5.0, abs=1e-9)
    assert ref.completion[0] == pytest.approx(5.0, abs=STEP_DT)


# ---- pausing and continuing under another plan ----------------------------------------


def test_state_at_a_pause_reads_where_each_robot_stands() -> None:
    """At t=4: a (1 m/s) at 4 m, b (2 m/s) waiting at 4 m since t=2, c not started (t=5)."""
    paths = _paths(
        robot("a", LANE[0]), robot("b", LANE[1], speed=2.0), robot("c", LANE[2], start_time=5.0)
    )
    execution = Execution(paths, _plan((1, 4.0, 0, 6.0)))
    state = execution.advance(4.0)
    assert state.time == 4.0
    np.testing.assert_allclose(state.clock, [4.0, 2.0, 5.0])  # b's clock: 4 m at 2 m/s
    np.testing.assert_allclose(state.arcs(paths), [4.0, 4.0, 0.0])
    assert state.started.tolist() == [True, True, False] and not state.done.any()
    state = execution.advance(10.0)  # b left at t=6 and arrived at t=9; c started at t=5
    assert state.done.tolist() == [True, True, False] and state.started.all()
    np.testing.assert_allclose(state.completion[:2], [10.0, 9.0])
    assert state.clock[2] == 10.0


@settings(max_examples=15, deadline=None, derandomize=True)
@given(case=plans_st(), pauses=st.lists(st.floats(0.0, 30.0), max_size=4))
def test_pausing_and_continuing_with_the_same_plan_changes_nothing(
    case: tuple[list[RobotPath], DependencyPlan, list[Rate]], pauses: list[float]
) -> None:
    paths, plan, rates = case
    whole = execute(paths, plan, rates)
    execution = Execution(paths, plan, rates)
    for t in sorted(pauses):
        execution.advance(t)
        execution.replace_plan(plan)
    paused = execution.finish()
    assert paused.deadlocked == whole.deadlocked
    np.testing.assert_allclose(paused.completion, whole.completion, atol=1e-9)
    for r, path in enumerate(paths):  # the same motion: arc length at the same times
        probe = np.linspace(path.start_time, np.nanmax(whole.completion, initial=0.0) + 1, 50)
        np.testing.assert_allclose(
            np.interp(probe, paused.wall[r], paused.arcs(paths)[r]),
            np.interp(probe, whole.wall[r], whole.arcs(paths)[r]),
            atol=1e-9,
        )
    _assert_never_faster(paths, paused)


@pytest.mark.parametrize(
    ("pause", "track"),
    [
        # at t=1 b is at 2 m: it drives on to the new wait point, 6 m, and waits there
        (1.0, [(0.0, 0.0), (3.0, 6.0), (8.0, 6.0), (10.0, 10.0)]),
        # at t=3 b is exactly at 6 m: that wait point is not passed, so not moot
        (3.0, [(0.0, 0.0), (3.0, 6.0), (8.0, 6.0), (10.0, 10.0)]),
    ],
)
def test_a_new_plan_stops_a_moving_robot_at_its_new_wait_point(
    pause: float, track: list[tuple[float, float]]
) -> None:
    """b (2 m/s) drives freely; at ``pause`` a new plan says: wait at 6 until a reached 8."""
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    execution = Execution(paths, DependencyPlan.empty())
    execution.advance(pause)
    assert execution.replace_plan(_plan((1, 6.0, 0, 8.0))) == 0
    assert _track(paths, execution.finish(), 1) == track


def test_a_new_plan_releases_a_waiting_robot_and_drops_passed_wait_points() -> None:
    """b waits at 4 for a at 6; at t=3 the new plan drops that wait and adds two: one at
    2 (b is past it: moot) and one at 9 that a has not reached."""
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    execution = Execution(paths, _plan((1, 4.0, 0, 6.0)))
    execution.advance(3.0)
    assert execution.replace_plan(_plan((1, 2.0, 0, 9.0), (1, 9.0, 0, 5.0))) == 1
    run = execution.finish()
    # From t=3 b drives on (4 -> 9 m by t=5.5), a has reached 5 m at t=5: no wait at 9.
    assert _track(paths, run, 1) == [(0.0, 0.0), (2.0, 4.0), (3.0, 4.0), (6.0, 10.0)]


def test_a_waitee_that_already_passed_satisfies_the_new_plan_at_once() -> None:
    paths = _paths(robot("a", LANE[0]), robot("b", LANE[1], speed=2.0))
    execution = Execution(paths, _plan((1, 4.0, 0, 9.0)))
    execution.advance(7.0)  # b waits at 4 since t=2, a at 7 m
    execution.replace_plan(_plan((1, 4.0, 0, 6.0)))  # a is past 6: b goes at t=7
    assert _track(paths, execution.finish(), 1)[-2:] == [(7.0, 4.0), (10.0, 10.0)]
