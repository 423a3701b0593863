"""``POST /v1/schedules``: solve a coordination problem."""

from __future__ import annotations

from anyio import to_thread
from fastapi import APIRouter

from service.api.body_limit import BodyLimitRoute
from service.api.deps import MetricsDep, RuntimeDep, SettingsDep
from service.api.errors import InvalidProblem, TooLarge
from service.core.problem import ProblemError
from service.core.schemas import ScheduleRequest, ScheduleResponse
from service.settings import Settings
from service.solvers.dispatch import dispatch

__all__ = ["router"]

router = APIRouter(prefix="/v1", tags=["schedules"], route_class=BodyLimitRoute)

ERROR_RESPONSES = {
    413: {"description": "The body, or its robots, nodes or conflicts, exceed a cap."},
    503: {"description": "Unexpected failure (logged); retry later."},
}


@router.post(
    "/schedules",
    response_model=ScheduleResponse,
    response_model_by_alias=True,
    responses=ERROR_RESPONSES,
)
async def create_schedule(
    body: ScheduleRequest, settings: SettingsDep, runtime: RuntimeDep, metrics: MetricsDep
) -> ScheduleResponse:
    """Schedule the conflicts of ``body``: who passes first, and how, at least cost.

    The answer always passes the constraint checker (``checks``). Solving runs in a
    worker thread, at most ``solve_concurrency`` at once, so the service stays responsive.
    """
    check_caps(body, settings)
    metrics.observe_problem(len(body.robots), len(body.conflicts))
    try:
        response = await to_thread.run_sync(dispatch, body, runtime.policy, limiter=runtime.limiter)
    except ProblemError as exc:
        raise InvalidProblem.from_problem_error(exc) from exc
    metrics.observe_solve(response)
    return response


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
