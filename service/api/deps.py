"""Dependencies of the routes, as ``Annotated`` aliases."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, FastAPI, Request

from service.api.errors import Unavailable
from service.api.metrics import Metrics
from service.api.runtime import Runtime
from service.settings import Settings, get_settings

__all__ = ["MetricsDep", "RuntimeDep", "SettingsDep", "resolve_settings"]

SettingsDep = Annotated[Settings, Depends(get_settings)]


def resolve_settings(app: FastAPI) -> Settings:
    """The settings in force outside a dependency (lifespan, body cap), honouring overrides."""
    return app.dependency_overrides.get(get_settings, get_settings)()


def get_runtime(request: Request) -> Runtime:
    """The state the lifespan built; 503 if the lifespan has not run."""
    runtime: Runtime | None = getattr(request.app.state, "runtime", None)
    if runtime is None:
        raise Unavailable("the service is starting up")
    return runtime


def get_metrics(request: Request) -> Metrics:
    """The app's metrics."""
    return request.app.state.metrics


RuntimeDep = Annotated[Runtime, Depends(get_runtime)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]
