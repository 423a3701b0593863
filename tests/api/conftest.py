"""Fixtures of the HTTP tests: an app with its lifespan running, served in-process over httpx.

Starlette's ``TestClient`` is not used: with httpx (rather than httpx2) it warns
that this pairing is deprecated. ``httpx.ASGITransport`` plus the app's own
lifespan context runs the same code in the test's event loop.
"""

from __future__ import annotations

import copy
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import httpx
import pytest
from fastapi import FastAPI

from service.main import create_app
from service.settings import Settings, get_settings

from .helpers import TINY, Serve, wait_ready


@pytest.fixture
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture
def tiny() -> dict[str, Any]:
    """A fresh copy of the committed tiny example request."""
    return copy.deepcopy(json.loads(TINY.read_text()))


@asynccontextmanager
async def _serve(
    settings: Settings | None = None, ready: bool = True, app: FastAPI | None = None
) -> AsyncIterator[httpx.AsyncClient]:
    """An app (by default a new one, with its own metrics), its lifespan running, and a client.

    Args:
        settings: replaces :func:`get_settings` through a dependency override.
        ready: wait for ``/readyz`` before yielding.
        app: serve this app (to inspect its state) instead of a new one.
    """
    app = app or create_app()
    if settings is not None:
        app.dependency_overrides[get_settings] = lambda: settings
    transport = httpx.ASGITransport(app=app)
    async with (
        app.router.lifespan_context(app),
        httpx.AsyncClient(transport=transport, base_url="http://test") as client,
    ):
        if ready:
            await wait_ready(client)
        yield client


@pytest.fixture
def serve() -> Serve:
    """``async with serve(settings) as client``: a client for an app with custom settings."""
    return _serve


@pytest.fixture
async def client() -> AsyncIterator[httpx.AsyncClient]:
    """A client for a ready app with the default settings."""
    async with _serve() as c:
        yield c
