"""Re-scheduling while executing (service.motion.replan): progress, plan swaps, the loop.

Two robots cross: a drives (0,0) -> (10,0) from t=0, b drives (5,-5) -> (5,5) from
t=0.5, both at 1 m/s; their one conflict is a/0 (a at 4-6 s) against b/0 (b at
4.65-6.35 s).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from service.core.problem import ErrorItem, ProblemError
from service.core.schemas import AssignmentOut, PreviousConflictIn, ProgressIn, ScheduleResponse
from service.geometry.graph import CoordinationGraph, GeometrySettings
from service.motion.plan import derive
from service.motion.replan import execute_rescheduled, plan_of, previous_of, progress_at
from service.motion.trajectories import trajectories
from service.scenarios import generate
from service.simulation.clearance import check_clearance
from service.simulation.disturbances import PROFILES, Rate, rates_of
from service.simulation.executor import Execution, execute
from service.simulation.simulate import plan_to_wire
from service.solvers.dispatch import DispatchPolicy, dispatch
from tests.motion.worlds import plan, request, robot


def _crossing() -> tuple[CoordinationGraph, ScheduleResponse]:
    req = request([robot("a", [[0, 0], [10, 0]]), robot("b", [[5, -5], [5, 5]], start_time=0.5)])
    graph = derive(req, GeometrySettings())
    graph_request = graph.to_request(req)
    assert graph_request is not None
    return graph, dispatch(graph_request, DispatchPolicy())


def _swapped(answer: ScheduleResponse) -> ScheduleResponse:
    """The same answer with every direction reversed."""
    flipped: list[AssignmentOut] = [
        {"from": a["to"], "to": a["from"], "type": a["type"]} for a in answer.assignment
    ]
    return answer.model_copy(update={"assignment": flipped})


def test_the_initial_answer_is_a_first() -> None:
    _, answer = _crossing()
    assert [(a["from"], a["to"]) for a in answer.assignment] == [("a/0", "b/0")]


def test_progress_of_moving_late_waiting_unstarted_and_done_robots() -> None:
    graph, answer = _crossing()
    rates = [Rate(), Rate.of([(0.5, 2.0, 0.0)])]  # b starts 2 s late
    execution = Execution(graph.paths, plan_of(graph, _swapped(answer)), rates)  # b first
    early = progress_at(graph, execution.advance(0.25))
    assert set(early.robots) == {"a"}  # b's start time has not come
    assert early.robots["a"].passed_until == pytest.approx(0.25) and early.robots["a"].delay == 0.0
    late = progress_at(graph, execution.advance(3.0))
    assert late.robots["b"].passed_until == pytest.approx(1.0)  # 0.5 s of driving
    assert late.robots["b"].delay == pytest.approx(2.0)
    waiting = progress_at(graph, execution.advance(4.5)).robots["a"]  # at its wait point 4 m
    assert waiting.passed_until < 4.0 <= waiting.passed_until + 1e-9  # not passed a_enter
    assert waiting.delay == pytest.approx(0.5)
    run = execution.finish()
    done = progress_at(graph, execution.advance(100.0)).robots
    assert done["a"].passed_until == 10.0
    assert done["a"].delay == pytest.approx(run.completion[0] - 10.0) and done["a"].delay > 0


def test_a_robot_late_at_clock_zero_is_left_out() -> None:
    graph, answer = _crossing()
    execution = Execution(graph.paths, plan_of(graph, answer), [Rate.of([(0.0, 3.0, 0.0)])] * 2)
    assert set(progress_at(graph, execution.advance(1.0)).robots) == {"b"}


def test_plan_and_previous_are_those_of_the_answer() -> None:
    graph, answer = _crossing()
    req = request([robot("a", [[0, 0], [10, 0]]), robot("b", [[5, -5], [5, 5]], start_time=0.5)])
    assert plan_to_wire(graph.paths, plan_of(graph, answer)) == plan(req).dependencies
    (prev,) = previous_of(answer)
    assert (prev.from_, prev.to, prev.type) == ("a/0", "b/0", "exclusive")


def test_re_scheduling_with_the_same_answer_changes_nothing_and_stops_when_done() -> None:
    graph, answer = _crossing()
    calls: list[ProgressIn] = []

    def keep(previous: list[PreviousConflictIn], progress: ProgressIn) -> ScheduleResponse:
        assert previous == previous_of(answer)
        calls.append(progress)
        return answer

    plan0 = plan_of(graph, answer)
    out = execute_rescheduled(graph, answer, [Rate()] * 2, keep, itertools.count(1.0, 1.0))
    whole = execute(graph.paths, plan0).completion
    np.testing.assert_allclose(out.run.completion, whole)
    last = int(np.ceil(whole.max()))  # every second until the last robot is done
    assert [r.time for r in out.replans] == [float(t) for t in range(1, last)]
    assert [p.time for p in calls] == [r.time for r in out.replans]
    assert all(r.error is None and r.constraints == plan0.size for r in out.replans)
    assert not any(r.changed for r in out.replans)


def test_a_new_order_is_obeyed_from_the_re_schedule_on() -> None:
    """At t=2 (nobody near the crossing) the scheduler lets b go first: a waits for it."""
    graph, answer = _crossing()

    def swap(previous: list[PreviousConflictIn], progress: ProgressIn) -> ScheduleResponse:
        return _swapped(answer)

    out = execute_rescheduled(graph, answer, [Rate()] * 2, swap, [2.0, 3.0])
    assert [r.changed for r in out.replans] == [True, False]
    assert out.run.deadlocked == ()
    assert out.run.completion[1] == pytest.approx(10.5)  # b undisturbed
    assert out.run.completion[0] > 10.0  # a waited
    assert check_clearance(trajectories(graph.paths, out.run)).ok


def test_a_refused_re_schedule_is_recorded_and_the_plan_kept() -> None:
    graph, answer = _crossing()

    def refuse(previous: list[PreviousConflictIn], progress: ProgressIn) -> ScheduleResponse:
        raise ProblemError([ErrorItem(("body", "progress"), "contradiction")])

    plan0 = plan_of(graph, answer)
    out = execute_rescheduled(graph, answer, [Rate()] * 2, refuse, [2.0, 3.0])
    assert [r.error is not None for r in out.replans] == [True, True]
    np.testing.assert_allclose(out.run.completion, execute(graph.paths, plan0).completion)


def test_re_scheduling_a_disturbed_warehouse_never_collides_nor_deadlocks() -> None:
    """The real re-scheduler (once it exists) on a 10-robot warehouse, heavy disturbances."""
    rescheduling = pytest.importorskip("service.solvers.rescheduling")
    world = generate("wh_two_way", 10, 0)
    req = request(world.robots, solver="exact", time_limit_s=1.0)
    graph = derive(req, GeometrySettings())
    graph_request = graph.to_request(req)
    assert graph_request is not None
    policy = DispatchPolicy()
    answer = dispatch(graph_request, policy)
    plan0 = plan_of(graph, answer)
    undisturbed = execute(graph.paths, plan0)
    windows = [
        (p.id, p.start_time, float(c))
        for p, c in zip(graph.paths, undisturbed.completion, strict=True)
    ]
    rescheduler = rescheduling.Rescheduler(graph_request, policy)

    def solve(previous: list[PreviousConflictIn], progress: ProgressIn) -> ScheduleResponse:
        return rescheduler.solve(previous, progress, time_limit_s=0.2)

    for seed in range(3):
        disturbances = PROFILES["heavy"].draw(windows, seed)
        rates = rates_of([p.id for p in graph.paths], disturbances)
        out = execute_rescheduled(graph, answer, rates, solve, itertools.count(5.0, 5.0))
        assert out.run.deadlocked == ()
        assert all(r.error is None for r in out.replans)
        assert check_clearance(trajectories(graph.paths, out.run)).ok
