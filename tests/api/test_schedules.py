"""POST /v1/schedules on valid requests: every solver, every objective, the wire format."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from service.core.schemas import OBJECTIVES, SOLVER_NAMES

from .helpers import assert_valid_answer, post_json

pytestmark = pytest.mark.anyio


async def test_tiny_request_is_answered_and_valid(
    client: httpx.AsyncClient, tiny: dict[str, Any]
) -> None:
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert_valid_answer(tiny, answer)
    assert answer["solver"]["name"] == "exact" and answer["solver"]["optimal"]
    assert all(set(x) == {"from", "to", "type"} for x in answer["assignment"])


@pytest.mark.parametrize("solver", SOLVER_NAMES)
async def test_every_solver_answers(
    client: httpx.AsyncClient, tiny: dict[str, Any], solver: str
) -> None:
    tiny["options"]["solver"] = solver
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert_valid_answer(tiny, answer)
    if solver == "auto":
        assert answer["solver"]["name"] == "exact"  # 3 conflicts: under exact_max_conflicts
    elif solver == "gnn_vae":  # the shipped model answers
        assert answer["solver"]["name"] == "gnn_vae"
        assert answer["solver"]["model"].startswith(f"gnn_vae/{tiny['objective']}/")
        assert answer["solver"]["samples"] == 100
    else:
        assert answer["solver"]["name"] == solver


@pytest.mark.parametrize("objective", OBJECTIVES)
async def test_every_objective(
    client: httpx.AsyncClient, tiny: dict[str, Any], objective: str
) -> None:
    tiny["objective"] = objective
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    assert_valid_answer(tiny, response.json())


async def test_defaults_apply_without_options_and_conflicts(client: httpx.AsyncClient) -> None:
    request = {"robots": [{"id": "solo", "nodes": [{"id": "n", "enter": 1.0, "exit": 2.0}]}]}
    response = await post_json(client, request)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert_valid_answer(request, answer)
    assert answer["assignment"] == [] and answer["cost"] == 2.0


async def test_openapi_docs(client: httpx.AsyncClient) -> None:
    assert (await client.get("/docs")).status_code == 200
    schema = (await client.get("/openapi.json")).json()
    post = schema["paths"]["/v1/schedules"]["post"]
    assert {"200", "413", "422", "503"} <= set(post["responses"])
    assignment = schema["components"]["schemas"]["AssignmentOut"]
    assert "from" in assignment["properties"]
