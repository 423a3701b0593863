"""The API's ASGI middleware (plain ASGI: no body copies), outermost first in the app.

- :class:`RequestLogMiddleware`: a request id and one JSON log line per request;
- :class:`RequestMetricsMiddleware`: request counts and latencies;
- :class:`CatchAllMiddleware`: any exception no handler rendered becomes a logged 503.
"""

from __future__ import annotations

import logging
import time

from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.api.errors import Unavailable, error_response
from service.api.metrics import Metrics
from service.api.request_log import REQUEST_ID_HEADER, note, open_record

__all__ = [
    "PROBE_ROUTES",
    "CatchAllMiddleware",
    "HttpMiddleware",
    "RequestLogMiddleware",
    "RequestMetricsMiddleware",
]

log = logging.getLogger(__name__)
access_log = logging.getLogger("service.access")

# Routes kept out of the request metrics and the access log: scraped every few seconds,
# they would drown the rest.
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


def route_of(scope: Scope) -> str:
    """The route template that matched (set by the router), or :data:`UNMATCHED`."""
    return getattr(scope.get("route"), "path", UNMATCHED)


class RequestLogMiddleware(HttpMiddleware):
    """Open the request's record (id from ``X-Request-ID`` or new, echoed back) and log it.

    The arrival time it records is where the request's time limit starts.
    """

    async def handle_http(self, scope: Scope, receive: Receive, send: Send) -> None:
        record = open_record(scope)
        status = 500

        async def send_with_id(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
                MutableHeaders(scope=message)[REQUEST_ID_HEADER] = record.request_id
            await send(message)

        try:
            await self.app(scope, receive, send_with_id)
        finally:
            route = route_of(scope)
            if route not in PROBE_ROUTES:
                line = {
                    "request_id": record.request_id,
                    "method": scope["method"],
                    "route": route,
                    "status": status,
                    "duration_s": round(time.monotonic() - record.arrival, 6),
                    **record.fields,
                }
                access_log.info("request", extra={"fields": line})


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
            route = route_of(scope)
            if route not in PROBE_ROUTES:
                elapsed = time.perf_counter() - start
                self.metrics.observe_request(route, scope["method"], status, elapsed)


class CatchAllMiddleware(HttpMiddleware):
    """Turns any exception no handler rendered into a logged 503.

    Starlette's own catch-all (``ServerErrorMiddleware``) answers 500 and re-raises;
    this sits inside it so no exception ever reaches it while a response can still be sent.
    """

    async def handle_http(self, scope: Scope, receive: Receive, send: Send) -> None:
        started = False

        async def send_tracked(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, send_tracked)
        except Exception as exc:
            if started:
                raise
            log.exception("unexpected error in %s %s", scope["method"], scope["path"])
            failure = Unavailable(
                f"the scheduler failed unexpectedly ({type(exc).__name__}); the error was "
                "logged, retry later or report it"
            )
            note(scope, outcome=failure.reason)
            await error_response(failure, self.metrics)(scope, receive, send)
