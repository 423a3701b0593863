"""Shared helpers of the paths-form tests: request builders, random fleets, motion checks.

The checks here read only the wire answer (trajectories as ``[t, x, y]`` lists and
the schedule) and the request's paths, and test the acceptance property of the
paths form (issue 10) independently of the service's own clearance check:

* no two footprints overlap (the sampled reference of :mod:`.reference_clearance`);
* each trajectory starts at ``path[0]`` no earlier than its start time and ends at
  the last point at its schedule completion;
* it moves along the path in order without cutting corners, never faster than the
  planned speed of the segment it is on.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.evaluate import Evaluator
from service.core.path_schemas import (
    CoordinationGraphResponse,
    PathsRequest,
    PathsScheduleResponse,
)
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.geometry.graph import GeometrySettings
from service.geometry.paths import RobotPath
from service.motion.plan import plan_paths
from service.simulation.clearance import Trajectory, check_clearance
from service.solvers.dispatch import DispatchPolicy
from tests.motion.reference_clearance import ReferenceClearance, position, reference_clearance

__all__ = [
    "ON_PATH_TOL",
    "OVERLAP_TOL",
    "SPEED_TOL",
    "assert_motion_valid",
    "distance_to_path",
    "evaluated",
    "fleets",
    "path_arcs",
    "paths_of",
    "plan",
    "request",
    "robot",
    "wire_trajectories",
]

# A sampled gap below -OVERLAP_TOL metres is an overlap (sampling error is far smaller
# than a footprint at the speeds used here, and plans keep a 0.05 m margin).
OVERLAP_TOL = 1e-3
# Waypoints are interpolated from times; they lie on the path up to rounding.
ON_PATH_TOL = 1e-6
SPEED_TOL = 1e-6
# What an answer's solver detail says when the solver's plan failed to execute cleanly and
# was replaced by its all-exclusive version: a dependency plan that deadlocked or collided.
FALLBACK_DETAIL = "executed with every conflict exclusive"


def robot(
    rid: str,
    path: Sequence[Sequence[float]],
    *,
    radius: float = 0.4,
    speed: float | None = 1.0,
    start_time: float | None = None,
    times: Sequence[float] | None = None,
) -> dict[str, Any]:
    """A wire robot of the paths form (``times`` replaces ``speed``/``start_time``)."""
    out: dict[str, Any] = {"id": rid, "path": [list(map(float, p)) for p in path]}
    out["radius"] = radius
    if times is not None:
        out["times"] = list(map(float, times))
    else:
        out["speed"] = speed
        if start_time is not None:
            out["start_time"] = start_time
    return out


def request(
    robots: Sequence[dict[str, Any]],
    *,
    solver: str = "exact",
    time_limit_s: float = 0.5,
    objective: str = "avg_completion",
    seed: int = 0,
) -> PathsRequest:
    """A validated paths-form request."""
    return PathsRequest.model_validate(
        {
            "objective": objective,
            "robots": list(robots),
            "options": {"solver": solver, "time_limit_s": time_limit_s, "seed": seed},
        }
    )


def plan(req: PathsRequest) -> PathsScheduleResponse:
    """``plan_paths`` with the default policy and geometry."""
    return plan_paths(req, DispatchPolicy(), GeometrySettings()).response


def paths_of(req: PathsRequest) -> list[RobotPath]:
    """The request's robots as arrays."""
    return [RobotPath.from_wire(r) for r in req.robots]


def wire_trajectories(req: PathsRequest, out: PathsScheduleResponse) -> list[Trajectory]:
    """The answer's trajectories (request order) with the request's radii."""
    by_id = {tr.robot: np.asarray(tr.points, dtype=np.float64) for tr in out.trajectories}
    result = []
    for r in req.robots:
        pts = by_id[r.id]  # (K, 3) t x y
        result.append(Trajectory(pts[:, 0], pts[:, 1:], float(r.radius)))
    return result


def distance_to_path(
    q: np.ndarray, path: RobotPath, s0: float = 0.0, s1: float | None = None
) -> float:
    """Least distance from point q (2,) to the stretch [s0, s1] of ``path`` (default: all)."""
    s1 = path.length if s1 is None else s1
    inner = path.arc[(path.arc > s0) & (path.arc < s1)]
    pts = path.position_at(np.concatenate([[s0], inner, [s1]]))  # (K, 2) the stretch's vertices
    p0, d = pts[:-1], np.diff(pts, axis=0)
    denom = np.maximum(np.einsum("nd,nd->n", d, d), 1e-300)
    f = np.clip(np.einsum("nd,nd->n", q - p0, d) / denom, 0.0, 1.0)
    return float(np.linalg.norm(p0 + f[:, None] * d - q, axis=1).min())


def path_arcs(path: RobotPath, xy: np.ndarray) -> np.ndarray:
    """Arc length of every waypoint on ``path``, asserting the motion follows it in order.

    Each waypoint must lie on the path at an arc length no smaller than the previous
    one, and the straight move between two consecutive waypoints must be the path
    itself (its length equals the arc length travelled: no corner cut). Among the
    candidates (a self-crossing path passes a point more than once) the least one
    reachable by a straight move is taken; it is unique unless the robot stood still.
    Shapes: xy (K, 2) -> (K,).
    """
    p0, p1 = path.points[:-1], path.points[1:]  # (N-1, 2)
    seg = np.diff(path.arc)  # (N-1,)
    arcs = np.empty(xy.shape[0])
    for k, q in enumerate(xy):
        f = np.clip(np.einsum("nd,nd->n", q - p0, p1 - p0) / seg**2, 0.0, 1.0)  # (N-1,)
        off = np.linalg.norm(p0 + f[:, None] * (p1 - p0) - q, axis=1)
        cand = path.arc[:-1] + f * seg
        ok = off < ON_PATH_TOL
        if k:
            step = float(np.linalg.norm(q - xy[k - 1]))
            ok &= (cand >= arcs[k - 1] - ON_PATH_TOL) & (np.abs(cand - arcs[k - 1] - step) < 1e-5)
        assert ok.any(), f"{path.id}: waypoint {k} {q.tolist()} is not on the path in order"
        arcs[k] = float(cand[ok].min())
    return arcs


def _assert_speeds(path: RobotPath, t: np.ndarray, arcs: np.ndarray) -> None:
    """Between consecutive waypoints, never faster than any segment crossed."""
    speeds = path.segment_speeds()
    for k in range(t.size - 1):
        ds, dt = arcs[k + 1] - arcs[k], t[k + 1] - t[k]
        if ds <= ON_PATH_TOL:
            continue
        assert dt > 0, f"{path.id}: moves {ds} m in no time at waypoint {k}"
        crossed = (path.arc[1:] > arcs[k] + ON_PATH_TOL) & (path.arc[:-1] < arcs[k + 1])
        limit = float(speeds[crossed].min()) if crossed.any() else float(speeds.min())
        assert ds / dt <= limit * (1 + SPEED_TOL) + SPEED_TOL, (
            f"{path.id}: {ds / dt} m/s > planned {limit} m/s after waypoint {k}"
        )


def assert_motion_valid(req: PathsRequest, out: PathsScheduleResponse) -> None:
    """The acceptance property of one answer, checked from the wire answer alone."""
    _assert_rendered_is_valid(out)
    assert out.checks.collision_free
    assert out.checks.acyclic and out.checks.density and out.checks.forced
    assert out.solver.detail != FALLBACK_DETAIL, "the solver's own plan did not execute"
    trajs = wire_trajectories(req, out)
    ref = reference_clearance(trajs)
    assert not ref.overlapping(-OVERLAP_TOL), f"overlaps: {ref.pair_gap}"
    _assert_clearance_agrees(out, trajs, ref)
    completion = {s.robot: s.completion for s in out.schedule}
    assert set(completion) == {r.id for r in req.robots}
    for path, tr in zip(paths_of(req), trajs, strict=True):
        assert np.all(np.diff(tr.t) >= 0), f"{path.id}: time goes back"
        assert tr.t[0] >= path.start_time - 1e-9
        np.testing.assert_allclose(tr.xy[0], path.points[0], atol=ON_PATH_TOL)
        np.testing.assert_allclose(tr.xy[-1], path.points[-1], atol=ON_PATH_TOL)
        assert tr.t[-1] == completion[path.id]
        assert completion[path.id] >= path.finish_time - 1e-9
        arcs = path_arcs(path, tr.xy)
        assert abs(arcs[-1] - path.length) < 1e-5
        _assert_speeds(path, tr.t, arcs)
    _assert_schedule_describes_trajectories(req, out, trajs)


def _assert_rendered_is_valid(out: PathsScheduleResponse) -> None:
    """The answer, constructed without validation, is what validating its JSON gives, and
    serializes without a warning (every field already of its declared type; the graph is
    built as its JSON body, exactly what the validated request writes)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        body = out.model_dump_json()
    validated = PathsScheduleResponse.model_validate_json(body)
    assert validated.model_dump_json() == body
    assert validated.model_dump(exclude={"graph"}) == out.model_dump(exclude={"graph"})
    graph = None if validated.graph is None else validated.graph.model_dump(mode="json")
    assert graph == out.graph


def _assert_clearance_agrees(
    out: PathsScheduleResponse, trajs: list[Trajectory], ref: ReferenceClearance
) -> None:
    """The answer's least clearance is the clearance check's, and the reference confirms it:
    at the reported time the pair is that far apart, and never less at any sample."""
    check = check_clearance(trajs)
    assert check.ok
    assert out.checks.min_clearance_m == check.min_gap
    if check.min_gap is None:
        assert ref.min_gap is None or ref.min_gap > 0
        return
    assert check.pair is not None and check.time is not None
    i, j = check.pair
    a, b = trajs[i], trajs[j]
    at = float(np.linalg.norm(position(a, check.time) - position(b, check.time)))
    assert at - a.radius - b.radius == pytest.approx(check.min_gap, abs=1e-6)
    assert check.min_gap <= ref.pair_gap[check.pair] + 1e-9


def _assert_schedule_describes_trajectories(
    req: PathsRequest, out: PathsScheduleResponse, trajs: list[Trajectory]
) -> None:
    """Node times are when the trajectory leaves the node's ends; costs are of completions."""
    paths = {p.id: p for p in paths_of(req)}
    by_id = {r.id: tr for r, tr in zip(req.robots, trajs, strict=True)}
    for entry in out.schedule:
        path, tr = paths[entry.robot], by_id[entry.robot]
        assert entry.delay == pytest.approx(entry.completion - path.finish_time, abs=1e-9)
        for node in entry.nodes:
            s_enter, s_exit = out.node_spans[node.id]
            assert tr.t[0] - 1e-9 <= node.enter <= node.exit <= tr.t[-1] + 1e-9
            for t, s in ((node.enter, s_enter), (node.exit, s_exit)):
                np.testing.assert_allclose(position(tr, t), path.position_at(s), atol=1e-6)
    completion = np.array([s.completion for s in out.schedule])
    mean = float(completion.mean())
    assert out.costs.avg_completion == pytest.approx(mean)
    assert out.costs.max_completion == pytest.approx(float(completion.max()))
    sync = mean + float(np.abs(completion - mean).mean())
    assert out.costs.sync_completion == pytest.approx(sync)
    assert out.costs.avg_delay >= -1e-9
    assert out.cost == getattr(out.costs, out.objective)


def graph_of(out: PathsScheduleResponse | CoordinationGraphResponse) -> ScheduleRequest | None:
    """The answer's graph validated as a graph-form request (the service builds it as its
    JSON body)."""
    graph = out.graph
    return ScheduleRequest.model_validate(graph) if isinstance(graph, dict) else graph


def evaluated(out: PathsScheduleResponse) -> tuple[dict[str, float], dict[str, float]]:
    """The dispatcher evaluator's view of the answer's own assignment on its graph: per
    robot of the graph its completion, and the four costs."""
    graph = graph_of(out)
    assert graph is not None
    a_first = np.array(
        [a["from"] == c["a"] for a, c in zip(out.assignment, graph.conflicts, strict=True)]
    )
    following = np.array([a["type"] == "following" for a in out.assignment], dtype=bool)
    problem = problem_from_request(graph)
    evaluation = Evaluator(problem).evaluate(Assignments.single(a_first, following))
    completion = evaluation.completion[0].tolist()
    costs = {k: float(v[0]) for k, v in evaluation.costs.items()}
    return {r.id: c for r, c in zip(graph.robots, completion, strict=True)}, costs


@st.composite
def fleets(
    draw: st.DrawFn, min_robots: int = 2, max_robots: int = 8, side: float = 6.0
) -> list[dict[str, Any]]:
    """Random wire robots in a ``side`` x ``side`` square: 2-5 point polylines (points at
    least 0.3 m apart), radii 0.2-0.6, speeds 0.3-2 from random start times, or ``times``."""
    n = draw(st.integers(min_robots, max_robots))
    coord = st.floats(0.0, side, allow_nan=False).map(lambda v: round(v, 2))
    robots = []
    for r in range(n):
        k = draw(st.integers(2, 5))
        pts = [(draw(coord), draw(coord))]
        while len(pts) < k:
            (x0, y0), (x, y) = pts[-1], (draw(coord), draw(coord))
            if np.hypot(x - x0, y - y0) < 0.3:  # too close: step 0.5 m aside instead
                x = x0 + 0.5 if x0 + 0.5 <= side else x0 - 0.5
            pts.append((x, y))
        radius = draw(st.floats(0.2, 0.6))
        start = draw(st.floats(0.0, 5.0))
        if draw(st.booleans()):
            robots.append(
                robot(
                    f"r{r}", pts, radius=radius, speed=draw(st.floats(0.3, 2.0)), start_time=start
                )
            )
        else:
            lengths = np.hypot(*np.diff(np.asarray(pts), axis=0).T)
            speeds = draw(st.lists(st.floats(0.3, 2.0), min_size=k - 1, max_size=k - 1))
            times = start + np.concatenate([[0.0], np.cumsum(lengths / np.asarray(speeds))])
            robots.append(robot(f"r{r}", pts, radius=radius, times=times.tolist()))
    return robots
