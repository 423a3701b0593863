"""Re-scheduling paths-form plans while robots run: from executed state to a new plan.

A fleet executes the dependency plan of an answer; robots run late. Every so
often (or on events) the fleet's state goes back to the scheduler as graph-form
progress, the scheduler answers a new assignment from that moment on (realized
decisions keep their direction, docs/contract.md), and the robots continue under
the dependency plan of that assignment:

* :func:`progress_at` (from :mod:`service.motion.progress`): an executor ``State``
  at wall time t as the graph form's ``progress``: a present robot at progress clock
  c (the planned time of where it stands) has passed every time point planned
  before c (not at c: a robot standing exactly at a wait point has not passed it)
  and runs ``t - c`` late;
* :func:`previous_of`: the assignment being executed, as the request's ``previous``;
* :func:`plan_of`: an answer's assignment as the executor's dependency plan (the
  same decision and staircases as :func:`service.motion.plan.plan_paths` builds);
* :func:`execute_rescheduled`: the loop, executing an answer's plan and swapping in
  each new answer's plan at the re-scheduling times (instantly: the simulated clock
  does not run while the scheduler thinks).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from pydantic import TypeAdapter

from service.core.path_schemas import PathsScheduleResponse
from service.core.problem import ProblemError
from service.core.schemas import (
    PreviousConflictIn,
    ProgressIn,
    ScheduleResponse,
)
from service.geometry.graph import CoordinationGraph
from service.motion.dependencies import Decision, dependency_plan
from service.motion.progress import progress_at
from service.simulation.disturbances import Rate
from service.simulation.executor import DependencyPlan, Execution, Run

__all__ = [
    "Replan",
    "Rescheduled",
    "Solve",
    "decision",
    "execute_rescheduled",
    "plan_of",
    "previous_of",
    "progress_at",
]

log = logging.getLogger(__name__)

# What the loop calls to re-schedule: (previous assignment, progress) -> checked answer.
Solve = Callable[[list[PreviousConflictIn], ProgressIn], ScheduleResponse]
# One validation of the whole list: ~30 % faster than a model_validate per entry (~20,000
# entries at 250 robots).
_PREVIOUS = TypeAdapter(list[PreviousConflictIn])


def previous_of(answer: ScheduleResponse) -> list[PreviousConflictIn]:
    """``answer``'s assignment as the ``previous`` of the next re-schedule."""
    return _PREVIOUS.validate_python(answer.assignment)


def decision(
    graph: CoordinationGraph, answer: ScheduleResponse | PathsScheduleResponse
) -> Decision:
    """An answer's assignment (in the graph's conflict order) as arrays: a graph-form
    answer to the graph's request, or the paths-form answer it was derived in."""
    ids = graph.node_ids()
    a_first = np.array(
        [
            ids[a] == out["from"]
            for out, a in zip(answer.assignment, graph.conf_node[:, 0], strict=True)
        ],
        dtype=bool,
    )
    following = np.array([out["type"] == "following" for out in answer.assignment], dtype=bool)
    return Decision(a_first, following)


def plan_of(graph: CoordinationGraph, answer: ScheduleResponse) -> DependencyPlan:
    """The executor's dependency plan of ``answer``'s assignment on ``graph``."""
    return dependency_plan(graph, decision(graph, answer))


@dataclass(frozen=True)
class Replan:
    """One re-schedule of a run: when, how long it took, what it changed.

    ``solve_s`` is the scheduler's call alone; ``total_s`` adds reading the state,
    building the progress and, when the assignment changed, the new dependency plan
    and swapping it in. ``error`` is the scheduler's refusal (the run then kept its plan).
    """

    time: float
    solve_s: float
    total_s: float
    changed: bool  # the answer's assignment differs from the one being executed
    constraints: int  # of the plan executed from now on
    moot: int  # constraints of a new plan whose waiter had already passed its point
    error: str | None = None


@dataclass(frozen=True, eq=False)
class Rescheduled:
    """An executed run with re-scheduling, and every re-schedule it made."""

    run: Run
    replans: list[Replan]


def execute_rescheduled(
    graph: CoordinationGraph,
    answer: ScheduleResponse,
    rates: list[Rate],
    solve: Solve,
    times: Iterable[float],
) -> Rescheduled:
    """Execute ``answer``'s plan and re-schedule at ``times``.

    ``times`` are increasing wall times (an endless one is fine: the loop stops once
    every robot is done or none can move). An answer with the assignment being
    executed keeps the running plan; a refused re-schedule (ProblemError) is recorded
    and the run keeps its plan too.
    """
    current = decision(graph, answer)
    plan, previous = dependency_plan(graph, current), previous_of(answer)
    execution = Execution(graph.paths, plan, rates)
    replans: list[Replan] = []
    for t in times:
        if execution.finished:
            break
        state = execution.advance(t)
        if state.done.all():
            break
        start = time.perf_counter()
        progress = progress_at(graph, state)
        solve_start = time.perf_counter()
        try:
            answer = solve(previous, progress)
        except ProblemError as exc:
            log.error("re-schedule at t=%.3f refused: %s", t, exc)
            elapsed = time.perf_counter() - solve_start
            replans.append(
                Replan(t, elapsed, time.perf_counter() - start, False, plan.size, 0, str(exc))
            )
            continue
        solve_s = time.perf_counter() - solve_start
        new = decision(graph, answer)
        changed = not (
            np.array_equal(new.a_first, current.a_first)
            and np.array_equal(new.following, current.following)
        )
        moot = 0
        if changed:
            plan, current = dependency_plan(graph, new), new
            moot = execution.replace_plan(plan)
            previous = previous_of(answer)
        total_s = time.perf_counter() - start
        replans.append(Replan(t, solve_s, total_s, changed, plan.size, moot))
    return Rescheduled(execution.finish(), replans)
