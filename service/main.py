"""The FastAPI app: :func:`create_app` builds it, the lifespan warms it up.

``service.main:app`` is what ``python -m service`` (and any ASGI server) runs.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version

import anyio
from anyio import to_thread
from fastapi import FastAPI
from fastapi.exceptions import RequestValidationError

from service.api.deps import resolve_settings
from service.api.errors import ApiError, handle_api_error, handle_validation_error
from service.api.metrics import Metrics
from service.api.middleware import (
    CatchAllMiddleware,
    RequestLogMiddleware,
    RequestMetricsMiddleware,
)
from service.api.routes import coordination_graphs, health, metrics, schedules, simulations
from service.api.runtime import build_runtime, warm_up

__all__ = ["app", "create_app", "lifespan"]


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Build the runtime, then warm up in the background: live at once, ready after warm-up."""
    runtime = build_runtime(resolve_settings(app))
    app.state.runtime = runtime
    app.state.metrics.watch_pool(runtime.limiter)
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
    # Added innermost first: the log and metrics see every response, the catch-all every
    # exception, and the log's record (request id, arrival) exists before anything else runs.
    app.add_middleware(CatchAllMiddleware, metrics=app.state.metrics)
    app.add_middleware(RequestMetricsMiddleware, metrics=app.state.metrics)
    app.add_middleware(RequestLogMiddleware, metrics=app.state.metrics)
    return app


app = create_app()
