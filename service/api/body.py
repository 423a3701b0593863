"""A route class that reads the body first: capped, and a JSON body validated from its bytes.

**The cap.** A body over ``max_body_bytes`` is refused (413), checked against the declared
Content-Length first, then against the bytes actually received (chunked bodies declare
none), before anything parses the body. It is a route class rather than an app
middleware so the refusal is rendered by the API's error handler and counted under its
route. FastAPI's own ``max_body_size`` fixes the limit when the app is built; this one
follows the settings in force when the request arrives (tests override them).

**The parse.** Left to FastAPI, a JSON body is decoded (``json.loads``) and then validated
against the route's model: for the 4.4 MB graph of 250 two-way robots 110 ms + 123 ms in
the event loop (session 43, profiled through the app). Here a body declared JSON is
validated straight from its bytes by pydantic's own JSON parser, and FastAPI is handed
the validated model, which it passes through without validating it again: through HTTP
the 250-robot FCFS request took 401-446 ms instead of 528-554 (p50 of eight, the two
servers interleaved, two runs), 100 robots 71-79 instead of 88-105. It still holds the
interpreter while it parses (pydantic does not release it), so a tiny request beside
back-to-back 250-robot ones waits as long at p95 (~0.2 s), if less at p50 (31-42 instead
of 57-86 ms). A body that fails here is left to FastAPI as before, so that every 4xx
names its fault exactly as it always has.

A callable discriminator (the schedule route's two forms, told apart by the first robot)
makes pydantic build the body's Python objects before it validates, which costs as much as
``json.loads``; the members tried in turn are validated from the JSON as one model is
(wh_two_way/250/0, 3.8 MB, least of 15, session 61: 176-256 -> 115-151 ms, the graph form
alone 123-129; 68-75 since conflicts and limits are TypedDicts). A paths body pays a failed
graph-form attempt first.
"""

from __future__ import annotations

import email.message
from collections.abc import Awaitable, Callable
from typing import Annotated, Any

from fastapi import Request, Response
from fastapi.routing import APIRoute
from pydantic import Discriminator, Field, TypeAdapter
from pydantic.fields import FieldInfo
from starlette.datastructures import Headers
from starlette.exceptions import HTTPException
from starlette.types import Message, Receive, Scope

from service.api.deps import resolve_settings
from service.api.errors import InvalidRequest, TooLarge

__all__ = ["BodyRoute"]


class BodyRoute(APIRoute):
    """An :class:`APIRoute` whose handler first reads the body, up to the configured cap,
    and validates a body declared JSON against the route's model from its bytes."""

    def get_route_handler(self) -> Callable[[Request], Awaitable[Response]]:
        handler = super().get_route_handler()
        field = self.body_field
        model = None if field is None else _body_model(field.field_info)

        async def limited(request: Request) -> Response:
            limit = resolve_settings(request.app).max_body_bytes
            body = await read_body(request, limit)
            parsed = None
            if model is not None and body and declared_json(request.headers):
                parsed = _validated(model, body)
            replayed = _ParsedRequest(request.scope, _replay(body, request.receive), parsed)
            try:
                return await handler(replayed)
            except HTTPException as exc:
                raise _unparsable(exc) or exc from exc.__cause__

        return limited


def _body_model(info: FieldInfo) -> TypeAdapter[Any]:
    """The route's body model as FastAPI validates it: its annotation with its field info;
    but a union told apart by a callable discriminator is tried member by member, left to
    right (see the module). Where the members exclude each other (no body valid for two)
    and the discriminator sends each valid body to the member that accepts it, both give
    the same model; a body that neither accepts is left to FastAPI, which names its faults
    by the discriminator's choice."""
    if any(_callable_discriminator(meta) for meta in info.metadata):
        return TypeAdapter(Annotated[info.annotation, Field(union_mode="left_to_right")])
    return TypeAdapter(Annotated[info.annotation, info])


def _callable_discriminator(meta: object) -> bool:
    return isinstance(meta, Discriminator) and callable(meta.discriminator)


class _ParsedRequest(Request):
    """A request whose JSON body is, where given, the model already validated from it."""

    def __init__(self, scope: Scope, receive: Receive, parsed: object | None) -> None:
        super().__init__(scope, receive)
        self._parsed = parsed

    async def json(self) -> Any:
        return await super().json() if self._parsed is None else self._parsed


def declared_json(headers: Headers) -> bool:
    """Whether the body is declared JSON (``application/json`` or ``application/*+json``),
    as FastAPI reads a declared content type."""
    message = email.message.Message()
    message["content-type"] = headers.get("content-type", "")
    subtype = message.get_content_subtype()
    return message.get_content_maintype() == "application" and (
        subtype == "json" or subtype.endswith("+json")
    )


def _validated(model: TypeAdapter[Any], body: bytes) -> object | None:
    """``body`` validated by ``model`` from its JSON bytes; None where it fails (FastAPI
    then parses it again and names its faults)."""
    try:
        return model.validate_json(body)
    except ValueError:  # pydantic's ValidationError, invalid JSON included
        return None


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
