"""ASGI middleware counting every HTTP request and its latency (plain ASGI: no body copies)."""

from __future__ import annotations

import time

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.metrics import Metrics

__all__ = ["PROBE_ROUTES", "HttpMiddleware", "RequestMetricsMiddleware"]

# Routes kept out of the request metrics: scraped every few seconds, they would drown the rest.
PROBE_ROUTES = frozenset({"/healthz", "/readyz", "/metrics"})
# The route label of requests no route matched (404): raw paths would explode the label set.
UNMATCHED = "<unmatched>"


class HttpMiddleware:
    """Plain ASGI middleware with the service's metrics that acts on HTTP requests only.

    Subclasses implement :meth:`handle_http`; lifespan and other scopes pass straight through.
    """

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        await self.handle_http(scope, receive, send)

    async def handle_http(self, scope: Scope, receive: Receive, send: Send) -> None:
        raise NotImplementedError


class RequestMetricsMiddleware(HttpMiddleware):
    """Count every request and its latency by route template, method and status."""

    async def handle_http(self, scope: Scope, receive: Receive, send: Send) -> None:
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
            route = getattr(scope.get("route"), "path", UNMATCHED)
            if route not in PROBE_ROUTES:
                elapsed = time.perf_counter() - start
                self.metrics.observe_request(route, scope["method"], status, elapsed)
