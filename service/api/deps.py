"""Dependencies of the routes, as ``Annotated`` aliases."""

from __future__ import annotations

import secrets
from typing import Annotated

from fastapi import Depends, FastAPI, Request

from service.api.errors import NotReady, Unauthorized, Unavailable
from service.api.metrics import Metrics
from service.api.request_log import RequestRecord, record_of
from service.api.runtime import Runtime
from service.settings import Settings, get_settings

__all__ = [
    "MetricsDep",
    "ReadyRuntimeDep",
    "RecordDep",
    "RuntimeDep",
    "SettingsDep",
    "require_token",
    "resolve_settings",
]

SettingsDep = Annotated[Settings, Depends(get_settings)]


def resolve_settings(app: FastAPI) -> Settings:
    """The settings in force outside a dependency (lifespan, body cap), honouring overrides."""
    return app.dependency_overrides.get(get_settings, get_settings)()


def require_token(request: Request, settings: SettingsDep) -> None:
    """401 unless ``Authorization: Bearer <token>`` matches ``api_token`` (when one is set).

    The comparison takes the same time wherever the tokens differ (:func:`secrets.compare_digest`).
    """
    if settings.api_token is None:
        return
    scheme, _, given = request.headers.get("authorization", "").partition(" ")
    expected = settings.api_token.get_secret_value().encode()
    if scheme.lower() != "bearer" or not secrets.compare_digest(given.strip().encode(), expected):
        raise Unauthorized()


def get_runtime(request: Request) -> Runtime:
    """The state the lifespan built; 503 if the lifespan has not run."""
    runtime: Runtime | None = getattr(request.app.state, "runtime", None)
    if runtime is None:
        raise Unavailable("the service is starting up")
    return runtime


def get_ready_runtime(request: Request) -> Runtime:
    """The runtime once warm-up finished; before, 503 with Retry-After (every solve needs it)."""
    runtime = get_runtime(request)
    if not runtime.ready:
        raise NotReady(runtime.limiter.retry_after_s, runtime.detail)
    return runtime


def get_record(request: Request) -> RequestRecord:
    """The request's log record, opened by :class:`service.api.middleware.RequestLogMiddleware`."""
    record = record_of(request.scope)
    if record is None:
        raise RuntimeError("RequestLogMiddleware is not installed")
    return record


def get_metrics(request: Request) -> Metrics:
    """The app's metrics."""
    return request.app.state.metrics


RuntimeDep = Annotated[Runtime, Depends(get_runtime)]
ReadyRuntimeDep = Annotated[Runtime, Depends(get_ready_runtime)]
RecordDep = Annotated[RequestRecord, Depends(get_record)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]
