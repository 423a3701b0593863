"""End to end: ``python -m service`` in a subprocess, on a free loopback port."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from .helpers import TINY, assert_valid_answer, service_process, wait_ready_sync


@pytest.fixture
def server(tmp_path: Path) -> Iterator[str]:
    """Base URL of a running ``python -m service``; the process is stopped afterwards."""
    with service_process(tmp_path / "server.log") as url:
        yield url


def test_python_m_service_serves_the_tiny_request(server: str) -> None:
    with httpx.Client(base_url=server, timeout=30.0) as client:
        wait_ready_sync(client)
        assert client.get("/healthz").status_code == 200
        request = json.loads(TINY.read_text())
        response = client.post("/v1/schedules", json=request)
        assert response.status_code == 200, response.text
        assert_valid_answer(request, response.json())
        assert 'route="/v1/schedules"' in client.get("/metrics").text
        traced = client.post("/v1/schedules", json=request, headers={"X-Request-ID": "trace-1"})
        assert traced.headers["x-request-id"] == "trace-1"


def test_every_log_line_is_json_with_one_line_per_request(server: str, tmp_path: Path) -> None:
    with httpx.Client(base_url=server, timeout=30.0) as client:
        wait_ready_sync(client)
        request = json.loads(TINY.read_text())
        client.post("/v1/schedules", json=request, headers={"X-Request-ID": "trace-2"})
        client.post("/v1/schedules", json={"robots": []})
    time.sleep(0.5)  # the line is written once the response is sent
    lines = [json.loads(line) for line in (tmp_path / "server.log").read_text().splitlines()]
    access = [line for line in lines if line["logger"] == "service.access"]
    solved, refused = access
    assert solved["request_id"] == "trace-2" and solved["status"] == 200
    assert (solved["robots"], solved["nodes"], solved["conflicts"]) == (3, 5, 3)
    assert solved["solver"] == "auto" and solved["answered_by"] == "auto"
    assert solved["queue_s"] >= 0 and solved["solve_s"] > 0 and solved["outcome"] == "optimal"
    assert refused["status"] == 422 and refused["outcome"] == "validation"
    assert len(refused["request_id"]) == 32  # generated
