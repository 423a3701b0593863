"""``POST /v1/schedules``: solve a coordination problem, given as a graph or as robot paths."""

from __future__ import annotations

from functools import partial
from typing import Annotated

from fastapi import APIRouter, Depends, Response
from pydantic import Discriminator, Tag

from service.api.body import BodyRoute
from service.api.deps import MetricsDep, ReadyRuntimeDep, RecordDep, SettingsDep, require_token
from service.api.encoding import json_response, with_json
from service.api.errors import TooLarge
from service.api.metrics import Metrics
from service.api.paths import check_path_caps, geometry_settings, run_paths_work
from service.api.request_log import RequestRecord
from service.api.runtime import Runtime
from service.core.path_schemas import PathsRequest, PathsScheduleResponse, request_form
from service.core.schemas import ScheduleRequest, ScheduleResponse
from service.motion.plan import plan_paths
from service.settings import Settings
from service.solvers.dispatch import dispatch

__all__ = ["router"]

router = APIRouter(
    prefix="/v1",
    tags=["schedules"],
    route_class=BodyRoute,
    dependencies=[Depends(require_token)],
)

# The two forms of the body: robots with nodes (graph form) or with paths (paths form),
# told apart by the first robot; a 422 names the field at fault within the chosen form.
ScheduleBody = Annotated[
    Annotated[ScheduleRequest, Tag("graph")] | Annotated[PathsRequest, Tag("paths")],
    Discriminator(request_form),
]

ERROR_RESPONSES = {
    413: {"description": "The body, or its robots, nodes or conflicts, exceed a cap."},
    503: {"description": "Unexpected failure (logged); retry later."},
}


@router.post(
    "/schedules",
    response_model=ScheduleResponse | PathsScheduleResponse,
    response_model_by_alias=True,
    responses=ERROR_RESPONSES,
)
async def create_schedule(
    body: ScheduleBody,
    settings: SettingsDep,
    runtime: ReadyRuntimeDep,
    metrics: MetricsDep,
    record: RecordDep,
) -> Response:
    """Schedule the conflicts of ``body``: who passes first, and how, at least cost.

    The answer always passes the constraint checker (``checks``). Solving runs in a
    worker thread, at most ``solve_concurrency`` at once, so the service stays responsive.
    A paths-form body is answered with the derived graph and trajectories that the
    service has executed and checked for clearance (docs/paths.md).
    """
    if isinstance(body, PathsRequest):
        return await schedule_paths(body, settings, runtime, metrics, record)
    note_problem(record, body)
    check_caps(body, settings)
    metrics.observe_problem(len(body.robots), len(body.conflicts))
    time_limit_s = body.options.time_limit_s or runtime.policy.default_time_limit_s
    solve = partial(dispatch, body, runtime.policy, deadline=record.arrival + time_limit_s)
    response, content = await runtime.limiter.run(with_json(solve), record)
    metrics.observe_solve(response)
    note_answer(record, response)
    return json_response(content)


async def schedule_paths(
    body: PathsRequest,
    settings: Settings,
    runtime: Runtime,
    metrics: Metrics,
    record: RequestRecord,
) -> Response:
    """The paths form: derive the graph, solve it, execute and check the trajectories."""
    record.fields.update(
        robots=len(body.robots),
        path_points=sum(len(r.path) for r in body.robots),
        solver=body.options.solver,
    )
    check_path_caps(body.robots, settings)
    time_limit_s = body.options.time_limit_s or runtime.policy.default_time_limit_s
    work = partial(
        plan_paths,
        body,
        runtime.policy,
        geometry_settings(settings),
        deadline=record.arrival + time_limit_s,
    )
    answer = await run_paths_work(work, runtime.limiter, record)
    metrics.observe_problem(len(body.robots), len(answer.response.assignment))
    metrics.observe_solve(answer.response)
    note_answer(record, answer.response)
    return json_response(answer.content)


def note_problem(record: RequestRecord, body: ScheduleRequest) -> None:
    """Add the problem's sizes and the solver asked for to the request's log line."""
    record.fields.update(
        robots=len(body.robots),
        nodes=sum(len(r.nodes) for r in body.robots),
        conflicts=len(body.conflicts),
        solver=body.options.solver,
    )


def note_answer(record: RequestRecord, response: ScheduleResponse) -> None:
    """Add the solver that answered, and how, to the request's log line."""
    record.fields.update(
        answered_by=response.solver.name,
        fallback_from=response.solver.fallback_from,
        outcome="optimal" if response.solver.optimal else "feasible",
    )


def check_caps(request: ScheduleRequest, settings: Settings) -> None:
    """Refuse (413) a problem with more robots, nodes or conflicts than the settings allow."""
    caps = {
        "robots": (len(request.robots), settings.max_robots),
        "nodes": (sum(len(r.nodes) for r in request.robots), settings.max_nodes),
        "conflicts": (len(request.conflicts), settings.max_conflicts),
    }
    over = [f"{n} {what} exceed max_{what} ({cap})" for what, (n, cap) in caps.items() if n > cap]
    if over:
        raise TooLarge("problem too large: " + "; ".join(over))
