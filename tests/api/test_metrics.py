"""GET /metrics: request, solve, size and rejection metrics in the app's own registry."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

from service.api.metrics import REJECT_REASONS
from service.api.middleware import PROBE_ROUTES
from service.settings import Settings
from service.solvers import dispatch as dispatch_module

from .helpers import Serve, post_json

pytestmark = pytest.mark.anyio

Samples = dict[tuple[str, frozenset[tuple[str, str]]], float]


async def scrape(client: httpx.AsyncClient) -> Samples:
    """Every sample of ``/metrics`` keyed by (name, labels)."""
    response = await client.get("/metrics")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain")
    return {
        (s.name, frozenset(s.labels.items())): s.value
        for family in text_string_to_metric_families(response.text)
        for s in family.samples
    }


def value(samples: Samples, name: str, **labels: str) -> float:
    return samples.get((name, frozenset(labels.items())), 0.0)


async def test_metrics_count_requests_solves_sizes_and_rejections(
    serve: Serve, monkeypatch: pytest.MonkeyPatch, tiny: dict[str, Any], tmp_path: Path
) -> None:
    no_models = Settings(max_robots=3, max_body_bytes=4000, model_store=tmp_path)
    async with serve(no_models) as client:
        assert (await post_json(client, tiny)).status_code == 200
        assert (await post_json(client, {**tiny, "objective": "fastest"})).status_code == 422
        bad_goal = {
            **tiny,
            "robots": [{**tiny["robots"][0], "goal_time": 1.0}, *tiny["robots"][1:]],
        }
        assert (await post_json(client, bad_goal)).status_code == 422
        many = {
            **tiny,
            "robots": [
                *tiny["robots"],
                {"id": "r4", "nodes": [{"id": "n", "enter": 0, "exit": 1}]},
            ],
        }
        assert (await post_json(client, many)).status_code == 413
        assert (await post_json(client, {**tiny, "pad": " " * 4000})).status_code == 413
        gnn = {**tiny, "options": {"solver": "gnn_vae"}}  # no model loaded: falls back
        assert (await post_json(client, gnn)).status_code == 200
        monkeypatch.setattr(dispatch_module, "get_solver", lambda name: 1 / 0)  # a bug: 503
        assert (await post_json(client, tiny)).status_code == 503
        for probe in ("/healthz", "/readyz", "/metrics"):
            await client.get(probe)
        samples = await scrape(client)

    route = {"route": "/v1/schedules", "method": "POST"}
    counts = {
        s: value(samples, "scheduler_http_requests_total", **route, status=s)
        for s in ("200", "413", "422", "503")
    }
    assert counts == {"200": 2, "413": 2, "422": 2, "503": 1}
    latency = value(samples, "scheduler_http_request_duration_seconds_count", **route, status="200")
    assert latency == 2
    assert not [k for k in samples if dict(k[1]).get("route") in PROBE_ROUTES]

    assert value(samples, "scheduler_solves_total", solver="auto", outcome="optimal") == 1
    assert value(samples, "scheduler_solves_total", solver="gnn_vae", outcome="fallback") == 1
    assert value(samples, "scheduler_solve_duration_seconds_count", solver="auto") == 1
    # Problems within the caps: the two answered, the one breaking a rule, the one failing.
    assert value(samples, "scheduler_problem_size_count", dimension="robots") == 4
    assert value(samples, "scheduler_problem_size_sum", dimension="conflicts") == 4 * 3

    rejected = {
        r: value(samples, "scheduler_rejected_requests_total", reason=r) for r in REJECT_REASONS
    }
    assert rejected == {
        "unauthorized": 0,
        "validation": 1,
        "too_large": 2,
        "problem_rule": 1,
        "internal": 1,
        "saturated": 0,
        "not_ready": 0,
    }


async def test_each_app_has_its_own_registry(serve: Serve, tiny: dict[str, Any]) -> None:
    solved = {"solver": "auto", "outcome": "optimal"}
    async with serve() as first, serve() as second:
        assert (await post_json(first, tiny)).status_code == 200
        assert value(await scrape(first), "scheduler_solves_total", **solved) == 1
        assert value(await scrape(second), "scheduler_solves_total", **solved) == 0
