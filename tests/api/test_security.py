"""Security: the optional bearer token of the POST endpoints, and no internals in any answer."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import pytest

from service.api.routes import schedules as schedules_route
from service.settings import Settings

from .helpers import Serve, post_json

pytestmark = pytest.mark.anyio

TOKEN = "s3cret-token"
PATHS_TINY = Path(__file__).parents[2] / "schemas" / "examples" / "paths" / "tiny.json"
POSTS = ("/v1/schedules", "/v1/coordination-graphs", "/v1/simulations")
# What no response body may contain: a traceback, a file of ours, a Python source path.
INTERNALS = ("Traceback", "/work/", ".py")


def bearer(token: str) -> dict[str, str]:
    """The ``Authorization`` header for ``token``."""
    return {"Authorization": f"Bearer {token}"}


def assert_no_internals(response: httpx.Response) -> None:
    """The body names no stack trace and no path of the service's files."""
    for leak in INTERNALS:
        assert leak not in response.text, response.text


def test_the_token_is_secret_and_empty_means_none(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SCHEDULER_API_TOKEN", TOKEN)
    settings = Settings()
    assert settings.api_token is not None and TOKEN not in repr(settings)
    monkeypatch.setenv("SCHEDULER_API_TOKEN", "")
    assert Settings().api_token is None


async def test_without_a_token_configured_posts_are_open(
    client: httpx.AsyncClient, tiny: dict[str, Any]
) -> None:
    assert (await post_json(client, tiny)).status_code == 200


@pytest.mark.parametrize("route", POSTS)
@pytest.mark.parametrize(
    "headers",
    [
        {},
        bearer("wrong"),
        bearer(""),
        {"Authorization": TOKEN},
        {"Authorization": f"Basic {TOKEN}"},
    ],
    ids=["none", "wrong", "empty", "no scheme", "basic"],
)
async def test_with_a_token_configured_posts_without_it_are_401(
    serve: Serve, route: str, headers: dict[str, str]
) -> None:
    async with serve(Settings(api_token=TOKEN)) as client:
        response = await client.post(route, json={"robots": []}, headers=headers)
        assert response.status_code == 401
        assert response.headers["www-authenticate"] == "Bearer"
        assert "bearer token" in response.json()["detail"]
        metrics = (await client.get("/metrics")).text
        assert 'scheduler_rejected_requests_total{reason="unauthorized"} 1.0' in metrics


async def test_with_the_right_token_posts_are_served_and_probes_stay_open(
    serve: Serve, tiny: dict[str, Any]
) -> None:
    paths = json.loads(PATHS_TINY.read_text())
    async with serve(Settings(api_token=TOKEN)) as client:
        for probe in ("/healthz", "/readyz", "/metrics"):
            assert (await client.get(probe)).status_code == 200
        answer = await client.post("/v1/schedules", json=tiny, headers=bearer(TOKEN))
        assert answer.status_code == 200, answer.text
        scheme_any_case = {"Authorization": f"bearer {TOKEN}"}
        graph = await client.post("/v1/coordination-graphs", json=paths, headers=scheme_any_case)
        assert graph.status_code == 200, graph.text


async def test_an_internal_error_shows_no_traceback_nor_path(
    client: httpx.AsyncClient, tiny: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    def explode(*args: object, **kwargs: object) -> None:
        raise RuntimeError(f"Traceback: boom in {Path(__file__).resolve()}")

    monkeypatch.setattr(schedules_route, "dispatch", explode)
    response = await post_json(client, tiny)
    assert response.status_code == 503
    assert "RuntimeError" in response.json()["detail"]
    assert_no_internals(response)


@pytest.mark.parametrize(
    ("route", "content"),
    [
        ("/v1/schedules", "{not json"),
        ("/v1/schedules", json.dumps({"robots": [{"id": 1, "nodes": "x"}]})),
        ("/v1/schedules", "[" * 100_000),
        ("/v1/coordination-graphs", json.dumps({"robots": [{"id": "a", "path": [[0, "x"]]}]})),
        ("/v1/simulations", json.dumps({"robots": None})),
    ],
    ids=["syntax", "types", "deep", "paths", "simulation"],
)
async def test_validation_errors_show_no_internals(
    client: httpx.AsyncClient, route: str, content: str
) -> None:
    response = await client.post(
        route, content=content, headers={"content-type": "application/json"}
    )
    assert response.status_code == 422
    assert_no_internals(response)
