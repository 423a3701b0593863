"""``POST /v1/simulations``: play back trajectories or execute a dependency plan with delays."""

from __future__ import annotations

from functools import partial

from fastapi import APIRouter, Depends, Response

from service.api.body import BodyRoute
from service.api.deps import RuntimeDep, SettingsDep, require_token
from service.api.encoding import json_response, with_json
from service.api.errors import TooLarge
from service.api.paths import check_path_caps, run_paths_work
from service.core.path_schemas import SimulationRequest, SimulationResponse
from service.simulation.simulate import simulate

__all__ = ["router"]

router = APIRouter(
    prefix="/v1", tags=["paths"], route_class=BodyRoute, dependencies=[Depends(require_token)]
)


@router.post(
    "/simulations",
    response_model=SimulationResponse,
    responses={413: {"description": "Too many robots, path points or trajectory points."}},
)
async def create_simulation(
    body: SimulationRequest, settings: SettingsDep, runtime: RuntimeDep
) -> Response:
    """Run ``body`` and report clearance, overlaps, deadlocks and completion times.

    With ``trajectories``: play them back. With ``dependencies`` (a paths-form
    answer's plan) and optional ``disturbances`` (late starts, stops, slow-downs):
    execute the plan and return the trajectories it produces.
    """
    check_path_caps(body.robots, settings)
    waypoints = sum(len(t.points) for t in body.trajectories or ())
    waits = sum(len(w["after"]) for d in body.dependencies or () for w in d["waits"])
    items = max(waypoints, waits, len(body.disturbances))
    if items > settings.max_total_path_points:
        raise TooLarge(
            f"{items} waypoints, dependencies or disturbances exceed "
            f"max_total_path_points ({settings.max_total_path_points})"
        )
    _, content = await run_paths_work(with_json(partial(simulate, body)), runtime.limiter)
    return json_response(content)
