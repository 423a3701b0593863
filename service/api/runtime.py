"""What the lifespan prepares and the routes read: solve policy, solve pool, readiness."""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TypeVar, get_args

import numba
from anyio import CapacityLimiter, WouldBlock, to_thread

from service.api.errors import InvalidProblem, Saturated, TooLarge
from service.api.request_log import RequestRecord
from service.core.cliques import CliqueBound, TooManyCliques, clique_budget
from service.core.path_schemas import PathsRequest
from service.core.problem import ProblemError
from service.core.schemas import OBJECTIVES, OptionsIn, ScheduleRequest, SolverName
from service.core.threads import available_cores
from service.geometry.graph import GeometrySettings
from service.memory import settle
from service.motion.plan import derived_request, plan_paths
from service.scenarios import generate
from service.settings import Settings
from service.solvers.dispatch import LAST_RESORT, DispatchPolicy, dispatch
from service.solvers.registry import solver_names

__all__ = [
    "PATHS_WARMUP_REQUEST",
    "WARMUP_REQUEST",
    "Runtime",
    "SolvePool",
    "build_runtime",
    "compiled_signatures",
    "dispatch_policy",
    "load_models",
    "missing_solvers",
    "solve_every_way",
    "warm_solvers",
    "warm_up",
]

T = TypeVar("T")

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
# Warms every solver and auto's large-problem stages up (:func:`warm_solvers`): a two-way
# warehouse of 16 robots, 92 conflicts, 12 fixed directions, 3 binding density cliques.
WARMUP_WORLD = ("wh_two_way", 16, 0)
# Each solve's time limit: long enough for LNS's first steps once compiled (at 0.05 s it
# took none in 2 of 3 runs); a cold cache compiles past it.
WARMUP_SOLVER_S = 0.2
WARMUP_PASSES = 3  # at most; see warm_solvers
# Warms the paths form up the same way: a crossing (exclusive) and a same-way pair.
PATHS_WARMUP_REQUEST = PathsRequest.model_validate(
    {
        "robots": [
            {"id": "a", "path": [[0.0, 0.0], [6.0, 0.0]], "radius": 0.4, "speed": 1.0},
            {"id": "b", "path": [[3.0, -3.0], [3.0, 3.0]], "radius": 0.4, "speed": 1.0},
            {"id": "c", "path": [[-2.0, 0.0], [6.0, 0.0]], "radius": 0.4, "speed": 2.0},
        ],
        "options": {"solver": "exact", "time_limit_s": 10.0},
    }
)


class SolvePool:
    """Where requests' blocking work runs: worker threads, bounded in number, queue and work.

    At most ``slots`` run at once; at most ``queue_size`` more wait for a slot, and a
    request beyond that is refused at once (:class:`Saturated`, 503 with Retry-After)
    rather than queued without bound. Each work item runs within the clique budget.
    Only the event loop touches the counters, so they need no lock.
    """

    def __init__(
        self, slots: int, queue_size: int, retry_after_s: int, clique_bound: CliqueBound
    ) -> None:
        self.slots = CapacityLimiter(slots)
        self.queue_size = queue_size
        self.retry_after_s = retry_after_s
        self.clique_bound = clique_bound
        self.waiting = 0

    @property
    def running(self) -> int:
        """Work items holding a slot."""
        return int(self.slots.borrowed_tokens)

    async def run(self, work: Callable[[], T], record: RequestRecord | None = None) -> T:
        """``work()`` in a worker thread once a slot is free, with the core's errors as API errors.

        The time spent waiting and working goes to ``record`` (the request's log line).

        Raises:
            Saturated: every slot busy and ``queue_size`` items already waiting.
            InvalidProblem: the problem breaks a cross-field rule (422).
            TooLarge: the conflict graph's cliques exceed the budget (413).
        """
        queued = time.monotonic()
        await self._take_slot()
        started = time.monotonic()
        try:
            return await to_thread.run_sync(self._bounded, work)
        except ProblemError as exc:
            raise InvalidProblem.from_problem_error(exc) from exc
        except TooManyCliques as exc:
            raise TooLarge(str(exc)) from exc
        finally:
            self.slots.release()
            if record is not None:
                record.fields.update(
                    queue_s=round(started - queued, 6), solve_s=round(time.monotonic() - started, 6)
                )

    async def _take_slot(self) -> None:
        """A free slot at once, else a place in the queue until one frees; :class:`Saturated`."""
        try:
            self.slots.acquire_nowait()
            return
        except WouldBlock:
            if self.waiting >= self.queue_size:
                raise Saturated(self.retry_after_s) from None
        self.waiting += 1
        try:
            await self.slots.acquire()
        finally:
            self.waiting -= 1

    def _bounded(self, work: Callable[[], T]) -> T:
        """``work()`` within the clique budget (in the worker thread's own context)."""
        with clique_budget(self.clique_bound):
            return work()


@dataclass(eq=False)
class Runtime:
    """Per-app state built by the lifespan; ``ready`` turns true once warm-up succeeded.

    ``limiter`` is the pool every route's blocking work goes through.
    """

    policy: DispatchPolicy
    limiter: SolvePool
    model_store: Path | None = None
    torch_threads: int | None = None  # intra-op threads of torch (None: torch's default)
    ready: bool = False
    detail: str = "warming up"
    model_errors: dict[str, str] = field(default_factory=dict)

    @property
    def models(self) -> dict[str, str]:
        """Loaded learned models: objective -> model name."""
        return {objective: m.name for objective, m in self.policy.models.items()}


def dispatch_policy(settings: Settings) -> DispatchPolicy:
    """The routing and limits :func:`service.solvers.dispatch.dispatch` applies."""
    return DispatchPolicy(
        default_time_limit_s=settings.default_time_limit_s,
        exact_max_conflicts=settings.exact_max_conflicts,
        exact_stage_max_conflicts=settings.exact_stage_max_conflicts,
        lns_min_conflicts=settings.lns_min_conflicts,
        large_solver=settings.large_solver,
        exact_workers=settings.exact_workers,
        exact_deterministic=settings.exact_deterministic,
    )


def build_runtime(settings: Settings) -> Runtime:
    """A runtime (not ready, no models yet) with the policy, pool and threads of ``settings``.

    Torch gets the cores left per concurrent solve unless ``torch_threads`` says otherwise:
    by default every solve's torch would use every core, and concurrent solves would
    oversubscribe them.
    """
    pool = SolvePool(
        settings.solve_concurrency,
        settings.queue_size,
        settings.retry_after_s,
        CliqueBound(settings.max_cliques, settings.max_clique_incidences),
    )
    cores_per_solve = max(1, available_cores() // settings.solve_concurrency)
    return Runtime(
        dispatch_policy(settings),
        pool,
        model_store=settings.model_store,
        torch_threads=settings.torch_threads or cores_per_solve,
    )


def missing_solvers(policy: DispatchPolicy) -> list[str]:
    """Solvers the policy can route to that are not registered."""
    needed = ("exact", policy.large_solver, LAST_RESORT)
    return sorted(set(needed) - set(solver_names()))


def load_models(runtime: Runtime, store: Path) -> None:
    """Load every objective's default GNN-VAE into the runtime's policy.

    An objective whose model is missing or corrupt is logged and listed in
    ``runtime.model_errors``; requests for it degrade to the exact solver.
    """
    import torch  # torch is imported only here

    from service.learning.store import load_all

    if runtime.torch_threads is not None:
        torch.set_num_threads(runtime.torch_threads)
    models, errors = load_all(store, OBJECTIVES)
    runtime.policy = replace(runtime.policy, models=models)
    runtime.model_errors = errors
    for objective, error in errors.items():
        log.warning("no GNN-VAE for %s (exact solver serves it): %s", objective, error)


def stage_policies(policy: DispatchPolicy) -> list[DispatchPolicy]:
    """``policy`` and the variants that send a small problem down each large-problem path
    of ``auto``: first stage, LNS and CP-SAT; plans, turns and LNS; turns alone."""
    large = replace(policy, exact_max_conflicts=0)
    planned = replace(large, lns_min_conflicts=0)
    return [policy, large, planned, replace(planned, exact_stage_max_conflicts=0)]


def warm_solvers(policy: DispatchPolicy) -> None:
    """Solve WARMUP_WORLD with every solver, ``auto`` down each of its paths
    (:func:`stage_policies`), so that every compiled kernel a request can reach is
    loaded (or compiled) before the service reports ready. The one-conflict
    WARMUP_REQUEST reaches none of those that fixed directions, binding density
    cliques and the large-problem stages need; a cold numba cache (a new container)
    then compiled them inside the first large request: 1.7 s over a 1-s budget at 250
    robots (session 28). ``tests/api/warm_check.py`` checks that other worlds compile
    nothing more.

    Passes repeat until one compiles (or loads) nothing: on a cold cache the first pass
    compiles past each solve's limit, so the steps a solver takes only when time is left
    (an LNS step after its start) are reached in the next one; one pass missed LNS's
    held-reach kernel on CI (session 30)."""
    request = derived_request(generate(*WARMUP_WORLD))
    if request is None:
        raise RuntimeError(f"the warm-up world {WARMUP_WORLD} derives no problem")
    before = compiled_signatures()
    for _ in range(WARMUP_PASSES):
        solve_every_way(request, policy, WARMUP_SOLVER_S)
        after = compiled_signatures()
        if after == before:
            return
        before = after


def solve_every_way(request: ScheduleRequest, policy: DispatchPolicy, time_limit_s: float) -> None:
    """``request`` solved by every solver (two samples where it samples) with
    ``time_limit_s``, ``auto`` down each of its paths (:func:`stage_policies`)."""
    for solver in get_args(SolverName):
        options = OptionsIn(solver=solver, samples=2, time_limit_s=time_limit_s)
        for staged in stage_policies(policy) if solver == "auto" else [policy]:
            dispatch(request.model_copy(update={"options": options}), staged)


def compiled_signatures() -> dict[str, set[str]]:
    """Every loaded numba kernel of the service -> the signatures it has compiled (or
    loaded from its cache) in this process."""
    out: dict[str, set[str]] = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("service"):
            for attr, value in vars(module).items():
                if isinstance(value, numba.core.registry.CPUDispatcher):
                    out[f"{name}.{attr}"] = {str(sig) for sig in value.signatures}
    return out


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
        warm_solvers(runtime.policy)
        # The paths form: geometry, dependency plan, executor and clearance kernels.
        plan_paths(PATHS_WARMUP_REQUEST, runtime.policy, GeometrySettings())
    except Exception as exc:
        runtime.detail = f"warm-up failed: {type(exc).__name__}: {exc}"
        log.exception("not ready: warm-up failed")
        return
    # Everything alive now (models, compiled kernels, the app) lives as long as the
    # process: out of the cyclic collector's reach, and full collections rarer.
    settle()
    runtime.ready, runtime.detail = True, "ready"
    log.info("ready: warm-up took %.2f s", time.perf_counter() - start)
