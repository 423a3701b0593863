"""One structured record per request: opened by the middleware, filled by routes and handlers.

The middleware writes it as one JSON line (logger ``service.access``) when the
response is done: request id, method, route, status, duration, and what the
route and error handlers added (solver, sizes, queue and solve time, outcome).
"""

from __future__ import annotations

import json
import logging
import re
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

from starlette.types import Scope

__all__ = [
    "REQUEST_ID_HEADER",
    "JsonFormatter",
    "RequestRecord",
    "note",
    "open_record",
    "record_of",
]

REQUEST_ID_HEADER = "x-request-id"
# A client's request id is kept if it looks like one (uuids, trace ids); anything else
# (too long, odd characters) is replaced by a generated id rather than echoed back.
_REQUEST_ID = re.compile(r"[A-Za-z0-9._:-]{1,128}")


@dataclass
class RequestRecord:
    """What one request's log line says."""

    request_id: str
    arrival: float = field(default_factory=time.monotonic)  # time.monotonic() at arrival
    fields: dict[str, Any] = field(default_factory=dict)


def open_record(scope: Scope) -> RequestRecord:
    """A record for the request of ``scope`` (id from ``X-Request-ID`` or new), stored in it."""
    given = dict(scope["headers"]).get(REQUEST_ID_HEADER.encode(), b"").decode("latin-1")
    request_id = given if _REQUEST_ID.fullmatch(given) else uuid.uuid4().hex
    record = RequestRecord(request_id)
    scope.setdefault("state", {})["record"] = record
    return record


def record_of(scope: Scope) -> RequestRecord | None:
    """The record the middleware opened for ``scope`` (None outside the middleware)."""
    return scope.get("state", {}).get("record")


def note(scope: Scope, **fields: Any) -> None:
    """Add ``fields`` to the request's log line (nothing outside the middleware)."""
    record = record_of(scope)
    if record is not None:
        record.fields.update(fields)


class JsonFormatter(logging.Formatter):
    """One JSON object per line: time, level, logger, message, and a record's ``fields``."""

    def format(self, record: logging.LogRecord) -> str:
        line: dict[str, Any] = {
            "time": self.formatTime(record),
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
            **getattr(record, "fields", {}),
        }
        if record.exc_info:
            line["exception"] = self.formatException(record.exc_info)
        return json.dumps(line, default=str)
