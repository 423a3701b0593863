"""The API's errors and the one function that renders them (the catch-all is in middleware).

Exception tree (each class carries its HTTP status and the ``reason`` label of
the rejected-requests metric)::

    ApiError
    ├── Unauthorized     401  a POST without the configured bearer token      (unauthorized)
    ├── InvalidRequest   422  the body fails the schema, or is not JSON       (validation)
    ├── InvalidProblem   422  well-typed, but breaks a cross-field rule       (problem_rule)
    ├── TooLarge         413  body bytes, robots, nodes, conflicts or cliques over cap
    │                                                                          (too_large)
    └── Unavailable      503  anything unexpected; logged, never a 500        (internal)
        ├── Saturated    503  every solve slot busy and the queue full        (saturated)
        └── NotReady     503  models not loaded yet (warm-up)                 (not_ready)

Saturated and NotReady carry a ``Retry-After`` header (seconds, ``retry_after_s``);
Unauthorized carries ``WWW-Authenticate: Bearer``. No body ever holds a stack trace
or a file path: the catch-all names only the exception's class.

422 bodies keep FastAPI's format, ``{"detail": [{"loc", "msg", "type"}]}``; the
others are ``{"detail": "<message>"}``. Validation errors do not echo the
offending input back: it may be huge, and NaN is not valid JSON.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, ClassVar

from fastapi import Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse

from service.api.metrics import Metrics
from service.api.request_log import note
from service.core.problem import ProblemError

__all__ = [
    "ApiError",
    "InvalidRequest",
    "InvalidProblem",
    "NotReady",
    "Saturated",
    "TooLarge",
    "Unauthorized",
    "Unavailable",
    "error_response",
    "handle_api_error",
    "handle_validation_error",
]

Detail = str | list[dict[str, Any]]
# Tags of the two body forms of POST /v1/schedules (service.api.routes.schedules).
FORM_TAGS = ("graph", "paths")


class ApiError(Exception):
    """Base of every error the API renders; subclasses fix the status and metric reason."""

    status_code: ClassVar[int]
    reason: ClassVar[str]

    def __init__(self, detail: Detail, headers: Mapping[str, str] | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.headers = dict(headers or {})


class Unauthorized(ApiError):
    """A POST without ``Authorization: Bearer <token>`` matching the configured token."""

    status_code = 401
    reason = "unauthorized"

    def __init__(self) -> None:
        super().__init__(
            "missing or wrong bearer token (Authorization: Bearer <token>)",
            {"WWW-Authenticate": "Bearer"},
        )


class InvalidRequest(ApiError):
    """The body is not JSON or does not match the request schema."""

    status_code = 422
    reason = "validation"

    @classmethod
    def from_validation(cls, exc: RequestValidationError) -> InvalidRequest:
        """Keep ``loc``, ``msg`` and ``type`` of each pydantic error (and JSON syntax details)."""
        items = []
        for err in exc.errors():
            msg = err["msg"]
            if err["type"] == "json_invalid" and "error" in err.get("ctx", {}):
                msg = f"{msg}: {err['ctx']['error']}"
            items.append({"loc": _without_form_tag(err["loc"]), "msg": msg, "type": err["type"]})
        return cls(items)


def _without_form_tag(loc: tuple[str | int, ...]) -> list[str | int]:
    """``loc`` without the body-form tag (``paths``/``graph``) pydantic puts after ``body``.

    ``POST /v1/schedules`` takes two forms of body; the tag says which one was read,
    not where the field is, so ``["body", "paths", "robots", 0]`` becomes
    ``["body", "robots", 0]``, as the contract documents locations.
    """
    parts = list(loc)
    if len(parts) >= 2 and parts[0] == "body" and parts[1] in FORM_TAGS:
        del parts[1]
    return parts


class InvalidProblem(ApiError):
    """The request is well-typed but breaks a rule spanning several fields."""

    status_code = 422
    reason = "problem_rule"

    @classmethod
    def from_problem_error(cls, exc: ProblemError) -> InvalidProblem:
        """The core's violations, each as ``{"loc", "msg", "type"}``."""
        return cls([e.as_dict() for e in exc.errors])


class TooLarge(ApiError):
    """The body or the problem exceeds a configured cap."""

    status_code = 413
    reason = "too_large"


class Unavailable(ApiError):
    """Something unexpected went wrong; the cause is in the log."""

    status_code = 503
    reason = "internal"


class Saturated(Unavailable):
    """Every solve slot is busy and the queue of waiting solves is full."""

    reason = "saturated"

    def __init__(self, retry_after_s: int) -> None:
        super().__init__(
            "the scheduler is saturated (every solve slot busy, the queue full); retry later",
            {"Retry-After": str(retry_after_s)},
        )


class NotReady(Unavailable):
    """The service is warming up (loading models); it takes requests once ``/readyz`` is 200."""

    reason = "not_ready"

    def __init__(self, retry_after_s: int, detail: str) -> None:
        super().__init__(
            f"the scheduler is not ready yet ({detail}); retry later",
            {"Retry-After": str(retry_after_s)},
        )


def error_response(exc: ApiError, metrics: Metrics) -> JSONResponse:
    """Render ``exc`` and count the rejection."""
    metrics.rejected.labels(exc.reason).inc()
    return JSONResponse({"detail": exc.detail}, status_code=exc.status_code, headers=exc.headers)


async def handle_api_error(request: Request, exc: ApiError) -> JSONResponse:
    """Exception handler for :class:`ApiError` raised in routes and dependencies."""
    note(request.scope, outcome=exc.reason)
    return error_response(exc, request.app.state.metrics)


async def handle_validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
    """Exception handler replacing FastAPI's default for request validation errors."""
    return await handle_api_error(request, InvalidRequest.from_validation(exc))
