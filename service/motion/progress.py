"""Paths-form progress: where robots are, as executor state and as graph-form progress.

A fleet reports each robot's arc length ``s`` reached at ``progress.time``
(:class:`service.core.path_schemas.PathsProgressIn`); the service reads it as an
executor :class:`State` (:func:`state_of`: progress clock = the planned time at
``s``, the robot runs ``time - clock`` late) and that state as the graph form's
``progress`` (:func:`progress_at`), which the re-scheduling core understands.
The disturbance benchmark's re-scheduling loop reads its executor's state the
same way.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from service.core.path_schemas import PathsProgressIn
from service.core.problem import ErrorItem, ProblemError
from service.core.schemas import ProgressIn, RobotProgressIn
from service.geometry.graph import CoordinationGraph
from service.geometry.paths import RobotPath
from service.simulation.executor import State

__all__ = ["progress_at", "state_of"]

# Rounding allowed between a reported arc length and the path's end or the planned clock.
TOLERANCE = 1e-9


def state_of(paths: Sequence[RobotPath], progress: PathsProgressIn) -> State:
    """The executor state a fleet reports: listed robots stand at their ``s`` at ``time``.

    A robot at (or past, within rounding) its path's end is done, arrived by ``time``.

    Raises:
        ProblemError: an unknown robot, ``s`` beyond the path's end, or a robot ahead of
            its plan (robots are never early), naming ``progress.robots.<id>[.s]``.
    """
    index = {p.id: r for r, p in enumerate(paths)}
    n, t = len(paths), progress.time
    clock = np.array([p.start_time for p in paths])  # (R,)
    started, done = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)
    completion = np.full(n, np.nan)
    errors: list[ErrorItem] = []
    for rid, rp in progress.robots.items():
        r = index.get(rid)
        loc = ("body", "progress", "robots", rid)
        if r is None:
            errors.append(ErrorItem(loc, f"unknown robot id '{rid}'"))
            continue
        path = paths[r]
        if rp.s > path.length * (1 + TOLERANCE) + TOLERANCE:
            errors.append(
                ErrorItem((*loc, "s"), f"s ({rp.s}) is beyond the path's end ({path.length})")
            )
            continue
        planned = float(path.time_at(min(rp.s, path.length)))
        if planned > t * (1 + TOLERANCE) + TOLERANCE:
            errors.append(
                ErrorItem(
                    (*loc, "s"),
                    f"robot '{rid}' would be ahead of its plan: s = {rp.s} is planned at "
                    f"{planned}, after progress.time ({t}); robots are never early",
                )
            )
            continue
        started[r], clock[r] = True, min(planned, t)
        if rp.s >= path.length * (1 - TOLERANCE):
            done[r], clock[r], completion[r] = True, path.finish_time, t
    if errors:
        raise ProblemError(errors)
    return State(t, clock, started, done, completion)


def progress_at(graph: CoordinationGraph, state: State) -> ProgressIn:
    """The graph-form progress of the graph's robots in ``state``.

    Robots whose start time has not come are left out (not started). A robot that
    is done has passed everything and ran ``completion - finish`` late. A robot
    standing at progress clock 0 has passed nothing and cannot say so (times are
    >= 0): it is left out too, which the scheduler reads as "cannot reach any point
    before ``state.time``".
    """
    robots = {}
    for r in graph.robots_in_graph().tolist():
        path, clock = graph.paths[r], float(state.clock[r])
        if not state.started[r] or (clock <= 0.0 and not state.done[r]):
            continue
        if state.done[r]:
            passed, delay = path.finish_time, float(state.completion[r]) - path.finish_time
        else:
            passed, delay = float(np.nextafter(clock, -np.inf)), state.time - clock
        robots[path.id] = RobotProgressIn(passed_until=passed, delay=max(delay, 0.0))
    return ProgressIn(time=state.time, robots=robots)
