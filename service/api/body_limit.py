"""The request-body cap: a route class refusing (413) a body over ``max_body_bytes``.

The cap is checked against the declared Content-Length first, then against the
bytes actually received (chunked bodies declare none), before anything parses
the body. It is a route class rather than an app middleware so the refusal is
rendered by the API's error handler and counted under its route.
FastAPI's own ``max_body_size`` fixes the limit when the app is built; this one
follows the settings in force when the request arrives (tests override them).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from fastapi import Request, Response
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException
from starlette.types import Message, Receive

from service.api.deps import resolve_settings
from service.api.errors import InvalidRequest, TooLarge

__all__ = ["BodyLimitRoute"]


class BodyLimitRoute(APIRoute):
    """An :class:`APIRoute` whose handler first reads the body, up to the configured cap."""

    def get_route_handler(self) -> Callable[[Request], Awaitable[Response]]:
        handler = super().get_route_handler()

        async def limited(request: Request) -> Response:
            limit = resolve_settings(request.app).max_body_bytes
            body = await read_body(request, limit)
            try:
                return await handler(Request(request.scope, _replay(body, request.receive)))
            except HTTPException as exc:
                raise _unparsable(exc) or exc from exc.__cause__

        return limited


def _unparsable(exc: HTTPException) -> InvalidRequest | None:
    """A 422 for JSON that parses as syntax but not as Python (else None).

    FastAPI answers 400 "There was an error parsing the body" when the JSON parser
    raises anything but a syntax error: nesting deeper than the recursion limit, or
    an integer of more than 4,300 digits. Those are bad input like any other.
    """
    cause = exc.__cause__
    if exc.status_code != 400 or not isinstance(cause, RecursionError | ValueError):
        return None
    msg = f"JSON decode error: {cause}"
    return InvalidRequest([{"loc": ["body"], "msg": msg, "type": "json_invalid"}])


async def read_body(request: Request, limit: int) -> bytes:
    """The whole body; :class:`TooLarge` as soon as it is known to exceed ``limit`` bytes."""
    declared = request.headers.get("content-length", "")
    if declared.isdigit() and int(declared) > limit:
        raise _too_large(f"Content-Length {declared}", limit)
    chunks: list[bytes] = []
    size = 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise _too_large(f"more than {limit} bytes", limit)
        chunks.append(chunk)
    return b"".join(chunks)


def _replay(body: bytes, receive: Receive) -> Receive:
    """A receive channel giving ``body`` in one message, then whatever ``receive`` gives."""
    replayed = False

    async def replay() -> Message:
        nonlocal replayed
        if replayed:
            return await receive()
        replayed = True
        return {"type": "http.request", "body": body, "more_body": False}

    return replay


def _too_large(what: str, limit: int) -> TooLarge:
    return TooLarge(f"request body too large: {what} exceeds max_body_bytes ({limit})")
