"""Answers encoded to JSON where they were computed: in the solve pool's worker thread.

Left to FastAPI, a route's answer is validated against its response model and
encoded in the event loop, where every other request's I/O waits meanwhile: ~0.11 s
for a 250-robot schedule, during which tiny requests beside back-to-back 250-robot
ones stalled (p95 0.21 s through HTTP, 24 ms in-process; session 31). The model's
own JSON encoder takes 0.02 s for the same answer, and runs in the worker.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from fastapi import Response
from pydantic import BaseModel

__all__ = ["json_response", "with_json"]

Answer = TypeVar("Answer", bound=BaseModel)


def with_json(work: Callable[[], Answer]) -> Callable[[], tuple[Answer, bytes]]:
    """``work``, then its answer's JSON body (by alias, as the routes' models document)."""

    def run() -> tuple[Answer, bytes]:
        answer = work()
        return answer, answer.model_dump_json(by_alias=True).encode()

    return run


def json_response(content: bytes) -> Response:
    """An already encoded answer, sent as it is (FastAPI neither validates nor re-encodes
    a :class:`Response`; the route's ``response_model`` still documents it)."""
    return Response(content=content, media_type="application/json")
