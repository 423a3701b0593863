"""ASGI middleware: the request-body cap and the HTTP request metrics.

Both are plain ASGI (not ``BaseHTTPMiddleware``), so they neither copy the body
nor run the app in a separate task.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from starlette.datastructures import Headers
from starlette.routing import Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.errors import TooLarge
from service.api.metrics import Metrics

__all__ = ["PROBE_ROUTES", "BodyLimitMiddleware", "RequestMetricsMiddleware"]

# Routes kept out of the request metrics: scraped every few seconds, they would drown the rest.
PROBE_ROUTES = frozenset({"/healthz", "/readyz", "/metrics"})
UNMATCHED = "<unmatched>"


class BodyLimitMiddleware:
    """Refuse (413) a body over ``max_bytes()``, by its Content-Length or by its actual size.

    The body is read here, up to the limit, and replayed to the app in one message,
    so an oversized body is refused before anything parses it. The limit is a
    callable so it follows the settings in force (tests override them).
    Starlette's ``RequestBodyLimitMiddleware`` fixes its limit at construction and
    answers in plain text, outside the API's error format; hence this one.
    """

    def __init__(self, app: ASGIApp, max_bytes: Callable[[], int]) -> None:
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit = self.max_bytes()
        declared = Headers(scope=scope).get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > limit:
            raise _too_large(f"Content-Length {declared}", limit)
        body = await _read_body(receive, limit)
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if replayed:
                return await receive()
            replayed = True
            return {"type": "http.request", "body": body, "more_body": False}

        await self.app(scope, replay, send)


async def _read_body(receive: Receive, limit: int) -> bytes:
    """The whole request body, refused as soon as it grows past ``limit`` bytes."""
    chunks: list[bytes] = []
    size = 0
    more = True
    while more:
        message = await receive()
        if message["type"] != "http.request":  # the client went away
            break
        chunk = message.get("body", b"")
        size += len(chunk)
        if size > limit:
            raise _too_large(f"more than {limit} bytes", limit)
        chunks.append(chunk)
        more = message.get("more_body", False)
    return b"".join(chunks)


def _too_large(what: str, limit: int) -> TooLarge:
    return TooLarge(f"request body too large: {what} exceeds max_body_bytes ({limit})")


class RequestMetricsMiddleware:
    """Count every request and its latency by route template, method and status."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        status = 500

        async def send_with_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        start = time.perf_counter()
        try:
            await self.app(scope, receive, send_with_status)
        finally:
            route = _route_template(scope)
            if route not in PROBE_ROUTES:
                elapsed = time.perf_counter() - start
                self.metrics.observe_request(route, scope["method"], status, elapsed)


def _route_template(scope: Scope) -> str:
    """The path template of the route that served ``scope`` (``/v1/schedules``, not a raw path).

    Requests refused before routing (e.g. a body over the cap) are matched here.
    """
    route = scope.get("route")
    if route is None:
        routes = scope["app"].router.routes
        route = next((r for r in routes if r.matches(scope)[0] is Match.FULL), None)
    return getattr(route, "path", UNMATCHED)
