"""A time-stepped reference of the dependency executor, for tests only.

Plain Python, fixed wall-time step, no events: at every step each started robot
advances its progress clock by its rate's integral over the step (``Rate.progress``,
tested on its own), but never past the planned time of its nearest unsatisfied wait
point; then every constraint whose waitee has reached ``until_s`` (or finished) is
satisfied for good. A robot finishes when its clock reaches its planned finish, at the
time its rate gives inside the step (``Rate.advance``). Each dependency hop can lag by
about one step, so it agrees with the exact executor up to a few steps. (With the rate
read at the step's middle instead, a stop beginning within a step of a robot's finish
was skipped: the reference finished it a whole stop earlier than the executor.)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from service.geometry.paths import RobotPath
from service.simulation.disturbances import Rate
from service.simulation.executor import DependencyPlan

__all__ = ["StepResult", "step_execute"]


@dataclass(frozen=True)
class StepResult:
    """Completion per robot (NaN if it never finished) and the robots that never did."""

    completion: list[float]
    stuck: tuple[int, ...]


def _clock(path: RobotPath, s: float) -> float:
    """Planned time at arc length s."""
    return float(path.time_at(s))


def step_execute(
    paths: Sequence[RobotPath],
    plan: DependencyPlan,
    rates: Sequence[Rate],
    dt: float,
    horizon: float,
) -> StepResult:
    """Run ``plan`` with a fixed step until ``horizon`` (wall seconds)."""
    n = len(paths)
    clock = [p.start_time for p in paths]
    done = [False] * n
    completion = [math.nan] * n
    satisfied = [False] * plan.size
    waiter, waitee = plan.waiter.tolist(), plan.waitee.tolist()
    wait_clock = [_clock(paths[w], s) for w, s in zip(waiter, plan.wait_s.tolist(), strict=True)]
    until_clock = [_clock(paths[w], s) for w, s in zip(waitee, plan.until_s.tolist(), strict=True)]

    def release(t: float) -> None:
        for c in range(plan.size):
            r = waitee[c]
            if not satisfied[c] and t >= paths[r].start_time:
                satisfied[c] = done[r] or clock[r] >= until_clock[c]

    t = min(p.start_time for p in paths)
    release(t)
    while t < horizon and not all(done):
        for r, path in enumerate(paths):
            if done[r] or t < path.start_time:
                continue
            limit = path.finish_time
            for c in range(plan.size):
                if waiter[c] == r and not satisfied[c]:
                    limit = min(limit, wait_clock[c])
            gain = rates[r].progress(t, t + dt)
            new = min(clock[r] + gain, limit)
            if new >= path.finish_time and gain > 0:
                done[r] = True
                completion[r] = rates[r].advance(t, path.finish_time - clock[r])
            clock[r] = max(clock[r], new)
        t += dt
        release(t)
    return StepResult(completion, tuple(r for r in range(n) if not done[r]))
