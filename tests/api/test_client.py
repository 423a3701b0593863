"""The Python client (service.client) against the app in-process, and its 503 retries."""

from __future__ import annotations

import copy
import json
import time
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
from anyio.from_thread import BlockingPortal, start_blocking_portal
from fastapi import FastAPI

from service.client import RequestRejected, ScheduleClient, ServiceUnavailable
from service.main import create_app
from service.settings import Settings, get_settings

from .helpers import READY_TIMEOUT_S, TINY, assert_valid_answer

PATHS_TINY = Path(__file__).parents[2] / "schemas" / "examples" / "paths" / "tiny.json"
TOKEN = "client-token"

# ``with connect(settings) as transport``: a sync transport to a new app, its lifespan running.
Connect = Callable[..., AbstractContextManager[httpx.BaseTransport]]


class PortalTransport(httpx.BaseTransport):
    """A sync httpx transport serving requests with an ASGI app in a blocking portal's loop."""

    def __init__(self, portal: BlockingPortal, app: FastAPI) -> None:
        self.portal = portal
        self.asgi = httpx.ASGITransport(app=app)

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        content = request.read()

        async def forward() -> tuple[int, httpx.Headers, bytes]:
            inner = httpx.Request(
                request.method, request.url, headers=request.headers, content=content
            )
            response = await self.asgi.handle_async_request(inner)
            return response.status_code, response.headers, await response.aread()

        status, headers, body = self.portal.call(forward)
        return httpx.Response(status, headers=headers, content=body)


@pytest.fixture
def connect() -> Connect:
    """``with connect(settings) as transport``: an app with ``settings`` served in-process."""

    @contextmanager
    def serve(settings: Settings | None = None) -> Iterator[httpx.BaseTransport]:
        app = create_app()
        if settings is not None:
            app.dependency_overrides[get_settings] = lambda: settings
        with (
            start_blocking_portal() as portal,
            portal.wrap_async_context_manager(app.router.lifespan_context(app)),
        ):
            yield PortalTransport(portal, app)

    return serve


def ready_client(transport: httpx.BaseTransport, token: str | None = None) -> ScheduleClient:
    """A client of ``transport`` once the app reports ready (it retries 503s while warming)."""
    client = ScheduleClient("http://test", token=token, transport=transport)
    deadline = time.monotonic() + READY_TIMEOUT_S
    while not client.ready()["ready"]:
        assert time.monotonic() < deadline, "app not ready"
        time.sleep(0.05)
    return client


def test_every_endpoint_in_process(connect: Connect) -> None:
    tiny = json.loads(TINY.read_text())
    paths = json.loads(PATHS_TINY.read_text())
    with connect() as transport, ready_client(transport) as client:
        assert client.health() == {"status": "ok"}
        assert client.ready()["ready"] is True
        assert_valid_answer(tiny, client.schedule(tiny))
        assert client.coordination_graph(paths)["graph"] is not None
        answer = client.schedule(paths)
        run = client.simulate({"robots": paths["robots"], "dependencies": answer["dependencies"]})
        assert run["collision_free"] is True and run["deadlocked"] == []


def test_a_4xx_raises_with_status_and_detail(connect: Connect) -> None:
    tiny = json.loads(TINY.read_text())
    broken = copy.deepcopy(tiny)
    broken["robots"][0]["nodes"][0]["exit"] = "soon"
    with (
        connect() as transport,
        ready_client(transport) as client,
        pytest.raises(RequestRejected) as caught,
    ):
        client.schedule(broken)
    assert caught.value.status == 422
    assert caught.value.detail[0]["loc"][:2] == ["body", "robots"]


def test_the_token_is_sent_as_a_bearer_token(connect: Connect) -> None:
    tiny = json.loads(TINY.read_text())
    with connect(Settings(api_token=TOKEN)) as transport:
        with ready_client(transport) as anonymous, pytest.raises(RequestRejected) as caught:
            anonymous.schedule(tiny)
        assert caught.value.status == 401 and "bearer token" in caught.value.detail
        with ready_client(transport, token=TOKEN) as client:
            assert_valid_answer(tiny, client.schedule(tiny))


def scripted(statuses: list[int], retry_after: str = "2") -> httpx.MockTransport:
    """A fake service answering ``statuses`` in turn (503s with ``Retry-After``)."""
    answers = iter(statuses)

    def handle(request: httpx.Request) -> httpx.Response:
        status = next(answers)
        if status == 503:
            return httpx.Response(
                503, headers={"Retry-After": retry_after}, json={"detail": "busy"}
            )
        return httpx.Response(status, json={"solver": {"name": "fcfs"}})

    return httpx.MockTransport(handle)


def fake_client(
    transport: httpx.MockTransport, **kwargs: Any
) -> tuple[ScheduleClient, list[float]]:
    """A client of ``transport`` whose waits are recorded instead of slept."""
    waits: list[float] = []
    return ScheduleClient("http://fake", transport=transport, sleep=waits.append, **kwargs), waits


def test_a_503_is_retried_after_retry_after() -> None:
    client, waits = fake_client(scripted([503, 503, 200]))
    assert client.schedule({}) == {"solver": {"name": "fcfs"}}
    assert waits == [2.0, 2.0]


def test_retries_stop_after_max_attempts() -> None:
    client, waits = fake_client(scripted([503] * 3), max_attempts=3)
    with pytest.raises(ServiceUnavailable) as caught:
        client.schedule({})
    assert (caught.value.status, caught.value.detail, waits) == (503, "busy", [2.0, 2.0])


def test_retries_stop_when_the_wait_would_pass_the_budget() -> None:
    client, waits = fake_client(scripted([503], retry_after="100"), retry_budget_s=30.0)
    with pytest.raises(ServiceUnavailable):
        client.schedule({})
    assert waits == []
