"""The paths form re-scheduled from progress ({"s": ...} per robot): answers from the moment
on that never collide, keep what is realized, and 422s naming the field."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from service.core.path_schemas import PathsRequest
from service.core.problem import ProblemError
from service.geometry.graph import GeometrySettings
from service.motion.plan import derive, plan_paths
from service.motion.replan import plan_of
from service.scenarios import generate
from service.simulation.disturbances import PROFILES, rates_of
from service.simulation.executor import Execution
from service.solvers.dispatch import DispatchPolicy, dispatch

POLICY = DispatchPolicy()
GEOMETRY = GeometrySettings()


def _world(seed: int) -> dict[str, Any]:
    body = generate("wh_two_way", 10, seed).to_request()
    body["options"] = {"solver": "auto", "time_limit_s": 1.0, "seed": 0}
    return body


def _disturbed_progress(body: dict[str, Any], seed: int, at: float) -> tuple[dict, dict]:
    """The first answer, and where its robots are at ``at`` under heavy disturbances."""
    request = PathsRequest.model_validate(body)
    graph = derive(request, GEOMETRY)
    graph_request = graph.to_request(request)
    assert graph_request is not None
    answer = dispatch(graph_request, POLICY)
    windows = [(p.id, p.start_time, p.finish_time + 60.0) for p in graph.paths]
    rates = rates_of([p.id for p in graph.paths], PROFILES["heavy"].draw(windows, seed))
    state = Execution(graph.paths, plan_of(graph, answer), rates).advance(at)
    arcs = state.arcs(graph.paths)
    robots = {p.id: {"s": float(arcs[r])} for r, p in enumerate(graph.paths) if state.started[r]}
    return answer.model_dump(by_alias=True), {"time": at, "robots": robots}


@pytest.mark.parametrize("seed", range(4))
def test_a_disturbed_fleet_is_rescheduled_without_collision(seed: int) -> None:
    body = _world(seed)
    first, progress = _disturbed_progress(body, seed, at=15.0 + 5 * seed)
    again = {**body, "previous": first["assignment"], "progress": progress}
    answer = plan_paths(PathsRequest.model_validate(again), POLICY, GEOMETRY).response
    assert answer.checks.collision_free and answer.checks.forced
    assert answer.checks.acyclic and answer.checks.density
    at = progress["time"]
    lengths = {
        r["id"]: np.sum(np.linalg.norm(np.diff(r["path"], axis=0), axis=1)) for r in body["robots"]
    }
    for traj in answer.trajectories:
        s = progress["robots"].get(traj.robot, {}).get("s")
        if s is None or s < lengths[traj.robot] - 1e-9:  # not done: moves from now on
            assert traj.points[0][0] >= at - 1e-9
    for dep in answer.dependencies:  # nothing left behind a robot
        here = progress["robots"].get(dep["robot"], {"s": 0.0})["s"]
        assert all(w["s"] >= here - 1e-9 for w in dep["waits"])
    for row in answer.schedule:
        assert row.completion >= at - 1e-9 or row.robot in progress["robots"]


@pytest.mark.parametrize(
    ("robots", "loc"),
    [
        ({"nope": {"s": 1.0}}, ["body", "progress", "robots", "nope"]),
        ({"r0": {"s": 1e6}}, ["body", "progress", "robots", "r0", "s"]),
        ({"r0": {"s": 5.0}}, ["body", "progress", "robots", "r0", "s"]),  # ahead of plan at 0
    ],
)
def test_bad_progress_is_a_422_naming_the_field(robots: dict[str, Any], loc: list[Any]) -> None:
    body = _world(0)
    body["robots"][0]["id"] = "r0"
    first = body["robots"][0]
    first.pop("start_time", None)
    body["progress"] = {"time": 0.0, "robots": robots}
    with pytest.raises(ProblemError) as err:
        plan_paths(PathsRequest.model_validate(body), POLICY, GEOMETRY)
    assert list(err.value.errors[0].loc) == loc
