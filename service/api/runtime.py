"""What the lifespan prepares and the routes read: solve policy, thread limiter, readiness."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from anyio import CapacityLimiter

from service.core.schemas import OBJECTIVES, OptionsIn, ScheduleRequest
from service.solvers.dispatch import LAST_RESORT, DispatchPolicy, dispatch
from service.solvers.registry import solver_names

__all__ = ["WARMUP_REQUEST", "Runtime", "load_models", "missing_solvers", "warm_up"]

log = logging.getLogger(__name__)

# Solved once at start-up so the evaluator's numba kernel is compiled (or loaded from its
# cache) and CP-SAT is loaded before the service reports ready: two robots, one conflict.
WARMUP_REQUEST = ScheduleRequest.model_validate(
    {
        "robots": [
            {"id": "a", "nodes": [{"id": "a0", "enter": 0.0, "exit": 2.0}], "goal_time": 3.0},
            {"id": "b", "nodes": [{"id": "b0", "enter": 1.0, "exit": 3.0, "density": 2}]},
        ],
        "conflicts": [{"a": "a0", "b": "b0", "a_enter": 0.5, "a_exit": 1.5}],
        "options": {"solver": "exact", "time_limit_s": 10.0},
    }
)


@dataclass(eq=False)
class Runtime:
    """Per-app state built by the lifespan; ``ready`` turns true once warm-up succeeded."""

    policy: DispatchPolicy
    limiter: CapacityLimiter
    model_store: Path | None = None
    ready: bool = False
    detail: str = "warming up"
    model_errors: dict[str, str] = field(default_factory=dict)

    @property
    def models(self) -> dict[str, str]:
        """Loaded learned models: objective -> model name."""
        return {objective: m.name for objective, m in self.policy.models.items()}


def missing_solvers(policy: DispatchPolicy) -> list[str]:
    """Solvers the policy can route to that are not registered."""
    needed = ("exact", policy.large_solver, LAST_RESORT)
    return sorted(set(needed) - set(solver_names()))


def load_models(runtime: Runtime, store: Path) -> None:
    """Load every objective's default GNN-VAE into the runtime's policy.

    An objective whose model is missing or corrupt is logged and listed in
    ``runtime.model_errors``; requests for it degrade to the exact solver.
    """
    from service.learning.store import load_all  # torch is imported only here

    models, errors = load_all(store, OBJECTIVES)
    runtime.policy = replace(runtime.policy, models=models)
    runtime.model_errors = errors
    for objective, error in errors.items():
        log.warning("no GNN-VAE for %s (exact solver serves it): %s", objective, error)


def warm_up(runtime: Runtime) -> None:
    """Solve :data:`WARMUP_REQUEST` once (blocking), then mark ``runtime`` ready.

    Failure leaves the service live but not ready, with the reason in ``runtime.detail``.
    """
    missing = missing_solvers(runtime.policy)
    if missing:
        runtime.detail = f"solvers not registered: {', '.join(missing)}"
        log.error("not ready: %s", runtime.detail)
        return
    start = time.perf_counter()
    if runtime.model_store is not None:
        load_models(runtime, runtime.model_store)
    try:
        dispatch(WARMUP_REQUEST, runtime.policy)
        # The large-problem path too (the GNN-VAE, the ES and tabu's kernels), or its fallback.
        large = OptionsIn(solver=runtime.policy.large_solver, samples=2, time_limit_s=10.0)
        dispatch(WARMUP_REQUEST.model_copy(update={"options": large}), runtime.policy)
    except Exception as exc:
        runtime.detail = f"warm-up failed: {type(exc).__name__}: {exc}"
        log.exception("not ready: warm-up failed")
        return
    runtime.ready, runtime.detail = True, "ready"
    log.info("ready: warm-up took %.2f s", time.perf_counter() - start)
