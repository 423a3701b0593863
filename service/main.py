"""The FastAPI app: :func:`create_app` builds it, the lifespan warms it up.

``service.main:app`` is what ``python -m service`` (and any ASGI server) runs.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version

import anyio
from anyio import CapacityLimiter, to_thread
from fastapi import FastAPI
from fastapi.exceptions import RequestValidationError

from service.api.deps import resolve_settings
from service.api.errors import (
    ApiError,
    CatchAllMiddleware,
    handle_api_error,
    handle_validation_error,
)
from service.api.metrics import Metrics
from service.api.middleware import RequestMetricsMiddleware
from service.api.routes import coordination_graphs, health, metrics, schedules, simulations
from service.api.runtime import Runtime, warm_up

__all__ = ["app", "create_app", "lifespan"]


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Build the runtime, then warm up in the background: live at once, ready after warm-up."""
    settings = resolve_settings(app)
    runtime = Runtime(
        settings.dispatch_policy(),
        CapacityLimiter(settings.solve_concurrency),
        model_store=settings.model_store,
    )
    app.state.runtime = runtime
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(to_thread.run_sync, warm_up, runtime)
        yield


def create_app() -> FastAPI:
    """A new app with its own metrics registry; settings are read when it starts."""
    app = FastAPI(
        title="Coordination scheduler",
        version=version("coordination-scheduler"),
        summary="Deadlock-free, density-feasible schedules for multi-robot coordination.",
        lifespan=lifespan,
    )
    app.state.metrics = Metrics()
    for module in (schedules, coordination_graphs, simulations, health, metrics):
        app.include_router(module.router)
    app.add_exception_handler(ApiError, handle_api_error)
    app.add_exception_handler(RequestValidationError, handle_validation_error)
    # Added innermost first: metrics see every response, the catch-all every exception.
    app.add_middleware(CatchAllMiddleware, metrics=app.state.metrics)
    app.add_middleware(RequestMetricsMiddleware, metrics=app.state.metrics)
    return app


app = create_app()
