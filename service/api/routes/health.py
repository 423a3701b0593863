"""Probes: ``/healthz`` (liveness) and ``/readyz`` (readiness)."""

from __future__ import annotations

from fastapi import APIRouter, Response
from pydantic import BaseModel

from service.api.deps import RuntimeDep
from service.solvers.registry import solver_names

__all__ = ["router"]

router = APIRouter(tags=["health"])


class Liveness(BaseModel):
    """The process is up."""

    status: str = "ok"


class Readiness(BaseModel):
    """Whether the service takes traffic, why not if not, and what it can solve with."""

    ready: bool
    detail: str
    solvers: list[str]
    models: dict[str, str]
    model_errors: dict[str, str]


@router.get("/healthz")
async def healthz() -> Liveness:
    """Always 200 while the process serves requests."""
    return Liveness()


@router.get("/readyz", responses={503: {"model": Readiness, "description": "Not ready yet."}})
async def readyz(runtime: RuntimeDep, response: Response) -> Readiness:
    """200 once warm-up finished and every solver the policy routes to is registered; else 503."""
    if not runtime.ready:
        response.status_code = 503
    return Readiness(
        ready=runtime.ready,
        detail=runtime.detail,
        solvers=list(solver_names()),
        models=runtime.models,
        model_errors=runtime.model_errors,
    )
