"""Scenario worlds as graph-form requests, for tests that need the congestion real paths make
(random and stitched graphs rarely have it): derived as the service derives them, or, where
a test needs density budgets that bind, as the service derived them before session 57."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

from service.core.path_schemas import PathsRequest
from service.geometry.graph import GeometrySettings
from service.motion.plan import derive
from service.scenarios import generate


@cache
def _derived(kind: str, robots: int, seed: int) -> str:
    paths = PathsRequest.model_validate(generate(kind, robots, seed).to_request("avg_completion"))
    request = derive(paths, GeometrySettings()).to_request(paths)
    assert request is not None, f"{kind}/{robots}/{seed}: no two robots interfere"
    return request.model_dump_json(by_alias=True)


def world_request(kind: str, robots: int, seed: int) -> dict[str, Any]:
    """The graph-form request (JSON) of the world ``kind``/``robots``/``seed``, derived once.

    ``wh_two_way``/25/60 is a benchmark world (bench.anytime) whose FCFS start waits long
    in its corridors: 252 conflicts.
    """
    return json.loads(_derived(kind, robots, seed))


CONGESTED_WAREHOUSE = Path(__file__).resolve().parent / "data" / "congested_warehouse.json"


def congested_warehouse() -> dict[str, Any]:
    """``wh_two_way``/25/60 as the service derived it until session 57 (252 conflicts):
    each node held as many robots as fit nose to tail along it, so its density cliques
    bind (which the service's derivation no longer makes: every node holds the fleet) and
    the choice of types matters, as it does on a graph-form client's graph with such
    densities."""
    return json.loads(CONGESTED_WAREHOUSE.read_text())
