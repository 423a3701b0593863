"""Simulations on the wire: play back trajectories, or execute a dependency plan with delays.

This is what ``POST /v1/simulations`` and ``python -m service.simulation`` run.
Playback checks given trajectories with the one clearance check. Execution runs
each robot's dependency plan (as in a paths-form answer's ``dependencies``) with
optional disturbances, and reports the trajectories that result, their
clearance, deadlocks and completion times: it shows what a plan does when
robots run late.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from service.core.path_schemas import (
    Dependency,
    OverlapOut,
    SimulationRequest,
    SimulationResponse,
    TrajectoryOut,
    WaitAfter,
    WaitPoint,
)
from service.core.problem import ErrorItem, ProblemError
from service.geometry.paths import RobotPath
from service.simulation.clearance import Clearance, Trajectory, check_clearance
from service.simulation.disturbances import Rate
from service.simulation.executor import DependencyPlan, execute

__all__ = ["plan_from_wire", "plan_to_wire", "simulate"]

# Arc lengths beyond a path's end by less than this (metres) are its end (rounding).
ARC_TOL = 1e-6


def plan_to_wire(paths: Sequence[RobotPath], plan: DependencyPlan) -> list[Dependency]:
    """Per robot, its wait points in path order and whom it waits for (the latest point each).

    Plain dicts (the wire types are TypedDicts): a 250-robot plan has ~10^4 entries, so
    the grouping is done in numpy and Python only builds the dicts.
    """
    order = np.lexsort((plan.waitee, plan.wait_s, plan.waiter))  # by robot, point, waitee
    waiter, wait_s, waitee = plan.waiter[order], plan.wait_s[order], plan.waitee[order]
    # One entry per (robot, point, waitee): the latest point of that waitee.
    entry = _run_starts(waiter, wait_s, waitee)  # (E,) first row of each entry
    until = np.maximum.reduceat(plan.until_s[order], entry) if entry.size else entry  # (E,)
    point = _run_starts(waiter[entry], wait_s[entry])  # (P,) first entry of each point
    ids = [p.id for p in paths]
    after: list[WaitAfter] = [
        {"robot": ids[w], "s": u}
        for w, u in zip(waitee[entry].tolist(), until.tolist(), strict=True)
    ]
    bounds = np.append(point, entry.size).tolist()
    heads = entry[point]  # (P,) first row of each point, in order of robot and point
    points: list[WaitPoint] = [
        {"s": s, "after": after[a:b]}
        for s, a, b in zip(wait_s[heads].tolist(), bounds[:-1], bounds[1:], strict=True)
    ]
    by_robot = np.searchsorted(waiter[heads], np.arange(len(paths) + 1)).tolist()  # (R+1,)
    return [
        {"robot": rid, "waits": points[by_robot[r] : by_robot[r + 1]]} for r, rid in enumerate(ids)
    ]


def _run_starts(*keys: np.ndarray) -> np.ndarray:
    """(G,) int: where each run of equal rows of the sorted, equally long ``keys`` starts."""
    if keys[0].size == 0:
        return np.zeros(0, dtype=np.int64)
    change = np.zeros(keys[0].size, dtype=bool)
    change[0] = True
    for key in keys:
        change[1:] |= key[1:] != key[:-1]
    return np.flatnonzero(change)


def plan_from_wire(paths: Sequence[RobotPath], deps: Sequence[Dependency]) -> DependencyPlan:
    """The executor's constraints from wire dependencies.

    Raises:
        ProblemError: an unknown robot, or an arc length beyond its path's end.
    """
    index = {p.id: r for r, p in enumerate(paths)}
    errors: list[ErrorItem] = []
    rows: list[tuple[int, float, int, float]] = []
    for k, dep in enumerate(deps):
        loc = ("body", "dependencies", k)
        waiter = _robot(index, dep["robot"], (*loc, "robot"), errors)
        for w, wait in enumerate(dep["waits"]):
            for a, after in enumerate(wait["after"]):
                at = (*loc, "waits", w, "after", a)
                waitee = _robot(index, after["robot"], (*at, "robot"), errors)
                if waiter is None or waitee is None:
                    continue
                _on_path(paths[waiter], wait["s"], (*loc, "waits", w, "s"), errors)
                _on_path(paths[waitee], after["s"], (*at, "s"), errors)
                rows.append((waiter, wait["s"], waitee, after["s"]))
    if errors:
        raise ProblemError(errors)
    if not rows:
        return DependencyPlan.empty()
    waiter_a, wait_a, waitee_a, until_a = (np.array(col) for col in zip(*rows, strict=True))
    return DependencyPlan(
        waiter_a.astype(np.int64), wait_a.astype(float), waitee_a.astype(np.int64), until_a
    )


def _robot(index: dict[str, int], rid: str, loc: tuple, errors: list[ErrorItem]) -> int | None:
    """The robot index of ``rid``, or None after recording an unknown-robot error."""
    if rid not in index:
        errors.append(ErrorItem(loc, f"unknown robot '{rid}'"))
        return None
    return index[rid]


def _on_path(path: RobotPath, s: float, loc: tuple, errors: list[ErrorItem]) -> None:
    """Record an error if arc length ``s`` lies beyond the end of ``path``."""
    if s > path.length + ARC_TOL:
        errors.append(ErrorItem(loc, f"s = {s} lies beyond the path's end ({path.length} m)"))


def simulate(request: SimulationRequest) -> SimulationResponse:
    """Play back or execute ``request`` and report what happened.

    Raises:
        ProblemError: ids or arc lengths that do not fit the robots.
    """
    paths = RobotPath.all_from_wire(request.robots)
    if request.trajectories is not None:
        trajs = _playback(paths, request)
        completion = {p.id: float(t.t[-1]) for p, t in zip(paths, trajs, strict=True)}
        deadlocked: list[str] = []
    else:
        assert request.dependencies is not None  # the wire model guarantees one mode
        run = execute(paths, plan_from_wire(paths, request.dependencies), _rates(paths, request))
        trajs = [
            Trajectory(w, p.position_at(p.arc_at(c)), p.radius)
            for p, w, c in zip(paths, run.wall, run.clock, strict=True)
        ]
        completion = {
            p.id: None if np.isnan(t) else float(t)
            for p, t in zip(paths, run.completion, strict=True)
        }
        deadlocked = [paths[r].id for r in run.deadlocked]
    return _report(paths, trajs, check_clearance(trajs), completion, deadlocked)


def _playback(paths: Sequence[RobotPath], request: SimulationRequest) -> list[Trajectory]:
    """The given trajectories, one per robot, with the robots' radii.

    Raises:
        ProblemError: a robot without a trajectory, twice, or an unknown one.
    """
    assert request.trajectories is not None
    index = {p.id: r for r, p in enumerate(paths)}
    given: dict[int, np.ndarray] = {}
    errors: list[ErrorItem] = []
    for k, tr in enumerate(request.trajectories):
        r = _robot(index, tr.robot, ("body", "trajectories", k, "robot"), errors)
        if r is not None and r in given:
            errors.append(ErrorItem(("body", "trajectories", k, "robot"), "given twice"))
        elif r is not None:
            given[r] = np.asarray(tr.points, dtype=np.float64)  # (K, 3) t x y
    missing = [p.id for r, p in enumerate(paths) if r not in given]
    if missing:
        errors.append(ErrorItem(("body", "trajectories"), f"no trajectory for {missing[:10]}"))
    if errors:
        raise ProblemError(errors)
    return [Trajectory(given[r][:, 0], given[r][:, 1:], p.radius) for r, p in enumerate(paths)]


def _rates(paths: Sequence[RobotPath], request: SimulationRequest) -> list[Rate]:
    """One progress rate per robot from the request's disturbances.

    Raises:
        ProblemError: a disturbance of an unknown robot.
    """
    index = {p.id: r for r, p in enumerate(paths)}
    pieces: list[list[tuple[float, float, float]]] = [[] for _ in paths]
    errors: list[ErrorItem] = []
    for k, d in enumerate(request.disturbances):
        r = _robot(index, d.robot, ("body", "disturbances", k, "robot"), errors)
        if r is not None:
            pieces[r].append((d.start, d.duration, d.factor))
    if errors:
        raise ProblemError(errors)
    return [Rate.of(p) for p in pieces]


def _report(
    paths: Sequence[RobotPath],
    trajs: Sequence[Trajectory],
    clearance: Clearance,
    completion: dict[str, float | None],
    deadlocked: list[str],
) -> SimulationResponse:
    """The wire report of a run."""
    return SimulationResponse(
        collision_free=clearance.ok,
        min_clearance_m=clearance.min_gap,
        overlaps=[
            OverlapOut(robots=(paths[i].id, paths[j].id), time=t, gap_m=g)
            for i, j, t, g in clearance.overlaps
        ],
        deadlocked=deadlocked,
        completion=completion,
        trajectories=[
            TrajectoryOut(robot=p.id, points=np.column_stack([t.t, t.xy]).tolist())
            for p, t in zip(paths, trajs, strict=True)
        ],
    )
