"""``POST /v1/coordination-graphs``: the coordination graph that robot paths make."""

from __future__ import annotations

from functools import partial

from fastapi import APIRouter, Depends, Response

from service.api.body import BodyRoute
from service.api.deps import RuntimeDep, SettingsDep, require_token
from service.api.encoding import json_response, with_json
from service.api.paths import check_path_caps, geometry_settings, run_paths_work
from service.core.path_schemas import CoordinationGraphResponse, PathsRequest
from service.motion.plan import coordination_graph

__all__ = ["router"]

router = APIRouter(
    prefix="/v1", tags=["paths"], route_class=BodyRoute, dependencies=[Depends(require_token)]
)


@router.post(
    "/coordination-graphs",
    response_model=CoordinationGraphResponse,
    response_model_by_alias=True,
    responses={413: {"description": "Too many robots or path points, or too much interference."}},
)
async def create_coordination_graph(
    body: PathsRequest, settings: SettingsDep, runtime: RuntimeDep
) -> Response:
    """Derive the graph of ``body`` (paths form): nodes, conflicts, densities, fixed orders.

    ``graph`` is a valid graph-form body of ``POST /v1/schedules`` (null when no two
    robots interfere); ``node_spans`` gives each node's arc-length interval on its path.
    """
    check_path_caps(body.robots, settings)
    work = partial(coordination_graph, body, geometry_settings(settings))
    _, content = await run_paths_work(with_json(work), runtime.limiter)
    return json_response(content)
