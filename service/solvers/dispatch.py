"""From a request to a checked, evaluated response: the work behind ``POST /v1/schedules``.

The HTTP layer, the benchmark and the CLIs all call :func:`dispatch`. It
validates the problem, picks the solver (``auto`` routes by size), runs it,
falls back to FCFS when the solver found nothing in time, checks the answer
with the one constraint checker, evaluates it with the one evaluator, and
renders the response. An answer that fails the checker is never returned.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, NamedTuple, Protocol

import numpy as np

from service.core.assignment import Assignments
from service.core.check import CheckResult, check
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder
from service.core.dependency_plan import dependency_plan
from service.core.orientation import OrientationGraph
from service.core.problem import ErrorItem, Problem, ProblemError, problem_from_request
from service.core.progress import previous_from_wire, progress_from_wire, residual_problem
from service.core.schemas import (
    ChecksOut,
    CostsOut,
    NodeTimesOut,
    Objective,
    OptionsIn,
    PreviousConflictIn,
    ProgressIn,
    RobotScheduleOut,
    ScheduleRequest,
    ScheduleResponse,
    SolverInfoOut,
)
from service.core.threads import solving
from service.solvers import (  # noqa: F401  (registers the solvers)
    bbts,
    cmaes,
    exact,
    fcfs,
    gnn_vae,
    hybrid,
    lns,
    portfolio,
    priority,
    random_search,
    refine,
    reinsert,
    tabu,
)
from service.solvers.registry import SolveContext, SolverOutput, get_solver

if TYPE_CHECKING:
    from service.learning.store import StoredModel

__all__ = [
    "CHECK_RESERVE_S",
    "FALLBACKS",
    "LAST_RESORT",
    "Checked",
    "DispatchPolicy",
    "InvalidAnswerError",
    "Job",
    "dispatch",
    "dispatch_problem",
    "render_reserve",
    "solve_problem",
]

log = logging.getLogger(__name__)

# What answers when a solver has no answer (no solution in time, no model loaded):
# the learned model degrades to the exact solver with the request's time limit,
# and everything ends at FCFS, which is instant and valid by construction.
FALLBACKS: dict[str, tuple[str, ...]] = {
    "gnn_vae": ("exact", "fcfs"),
    "gnn_vae_refined": ("exact", "fcfs"),
    "gnn_vae_exact": ("exact", "fcfs"),
}
LAST_RESORT = "fcfs"

# The solver stops this early for the answer's check, evaluation and rendering: measured
# 14 ms mean, 25 ms p95 over 145 re-schedules at 250 robots and 22,000 conflicts with the
# dependency plan (1.1 us per conflict at p95).
RENDER_S_PER_ITEM = 2e-6
RENDER_S_MIN = 0.008  # the fixed part: checking, evaluating, the response model
# ... and where the answer is only checked, not rendered (a paths-form answer renders its
# own from the executed motion): the fixed part alone. The check of a 250-robot answer
# (21,835 conflicts) took 1.6-2.3 ms (session 61); the rest is slack for the solver's stop.
CHECK_RESERVE_S = RENDER_S_MIN


class InvalidAnswerError(RuntimeError):
    """Even the fallback produced an assignment the checker rejects (a bug, never expected)."""


@dataclass(frozen=True)
class DispatchPolicy:
    """How requests are routed and limited (built from the settings)."""

    default_time_limit_s: float = 5.0
    exact_max_conflicts: int = 60
    exact_stage_max_conflicts: int = 10_000
    lns_min_conflicts: int = 700
    large_solver: str = "priority_tabu"
    exact_workers: int = 1
    exact_deterministic: bool = False
    models: Mapping[str, StoredModel] = field(default_factory=dict)  # loaded GNN-VAEs by objective


class Job(Protocol):
    """What a solve reads of its request besides the problem (both request forms have it)."""

    @property
    def objective(self) -> Objective: ...

    @property
    def options(self) -> OptionsIn: ...


def dispatch(
    request: ScheduleRequest, policy: DispatchPolicy, *, deadline: float | None = None
) -> ScheduleResponse:
    """Solve ``request`` and return a checked response.

    A request with ``progress`` is a re-schedule: its residual problem
    (:mod:`service.core.progress`) is solved, warm-started from ``previous``.

    Args:
        deadline: ``time.monotonic()`` by which the solver must stop (the request's
            arrival plus its time limit, so time spent queueing counts); the solver gets
            the time left if that is less than its time limit.

    Raises:
        ProblemError: the request breaks a cross-field rule of the contract.
    """
    return dispatch_problem(
        problem_from_request(request),
        request,
        policy,
        deadline=deadline,
        previous=request.previous,
        progress=request.progress,
    ).response()


def dispatch_problem(
    problem: Problem,
    job: Job,
    policy: DispatchPolicy,
    *,
    deadline: float | None = None,
    previous: list[PreviousConflictIn] | None = None,
    progress: ProgressIn | None = None,
    reserve_s: float | None = None,
) -> Checked:
    """:func:`dispatch` for a problem already built (e.g. derived from paths), with the
    graph-form ``previous`` and ``progress`` of a re-schedule: the checked answer, not yet
    rendered (a paths-form answer renders its own, from the executed motion, and keeps
    only CHECK_RESERVE_S: ``reserve_s`` as :func:`solve_problem`'s).

    Raises:
        ProblemError: ``previous`` or ``progress`` contradict the problem.
    """
    warm = None if previous is None else previous_from_wire(problem, previous)
    if progress is not None:
        problem = residual_problem(problem, progress_from_wire(problem, progress), warm)
    return solve_problem(problem, job, policy, deadline=deadline, warm=warm, reserve_s=reserve_s)


class Checked(NamedTuple):
    """A solve's answer before it is rendered: the context it was solved in, the answer,
    who gave it and how, and the checks it passed. Rendering the graph-form response
    (:meth:`response`) costs ~30 ms at 250 robots, which a paths-form answer skips."""

    ctx: SolveContext
    output: SolverOutput
    info: SolverInfoOut
    checks: ChecksOut

    def response(self) -> ScheduleResponse:
        """The graph-form wire response (evaluated, with its schedule and dependencies)."""
        return _render(self.ctx.objective, self.ctx, self.output, self.info, self.checks)


def solve_problem(
    problem: Problem,
    job: Job,
    policy: DispatchPolicy,
    *,
    deadline: float | None = None,
    warm: Assignments | None = None,
    cliques: Cliques | None = None,
    decoder: Decoder | None = None,
    orientation: OrientationGraph | None = None,
    reserve_s: float | None = None,
) -> Checked:
    """Solve a validated ``problem`` with ``job``'s objective and options -> the checked
    answer (:class:`Checked`; its ``response()`` is the graph-form wire response).

    Args:
        warm: a valid assignment to start local search from (the previous answer of a
            re-schedule); ignored if the checker rejects it.
        cliques: the problem's cliques if already known (they depend only on the
            conflict graph and densities, so a re-schedule reuses its base problem's).
        decoder, orientation: likewise, already built for this problem (e.g. by
            ``for_problem`` from the base problem's).
        reserve_s: seconds before the deadline at which the solver stops, for checking
            and rendering its answer (default :func:`render_reserve`, a model of that work).
    """
    opts = job.options
    if cliques is None:  # found before the solver's time is read: they count against it
        cliques = find_cliques(problem)  # (seconds at 14 million clique incidences)
    ctx = SolveContext(
        problem=problem,
        objective=job.objective,
        time_limit_s=max(
            0.0,
            _time_left(opts.time_limit_s or policy.default_time_limit_s, deadline)
            - (render_reserve(problem) if reserve_s is None else reserve_s),
        ),
        seed=opts.seed,
        samples=opts.samples,
        workers=policy.exact_workers,
        models=policy.models,
        exact_max_conflicts=policy.exact_max_conflicts,
        exact_stage_max_conflicts=policy.exact_stage_max_conflicts,
        lns_min_conflicts=policy.lns_min_conflicts,
        first_stage=policy.large_solver,
        exact_deterministic=policy.exact_deterministic,
    )
    prepared = {"cliques": cliques, "decoder": decoder, "orientation": orientation}
    ctx.__dict__.update({k: v for k, v in prepared.items() if v is not None})  # cached props
    start = time.perf_counter()
    # The cliques were found first: every solver and the checker need them, and a problem
    # whose cliques exceed the work budget (TooManyCliques) is refused before any solver
    # runs, instead of each solver of the fallback chain failing on it in turn.
    _check_realized_density(problem, ctx.cliques)
    if warm is not None and check(problem, ctx.cliques, warm).ok[0]:
        ctx.warm = warm
    name = opts.solver  # "auto" is the anytime portfolio (solvers/portfolio.py)
    with solving():  # a search may take the cores no other solve holds
        used, output, checks = _first_valid_answer(ctx, name)
    runtime = time.perf_counter() - start
    info = SolverInfoOut(
        name=used,
        optimal=output.optimal,
        runtime_s=runtime,
        model=output.model,
        samples=output.samples,
        fallback_from=None if used == name else name,
        detail=output.detail
        if used == name
        else f"{name} gave no answer (no solution in time, no model loaded, or it failed)",
    )
    checked = ChecksOut(
        acyclic=bool(checks.acyclic[0]),
        density=bool(checks.density[0]),
        forced=bool(checks.forced[0]),
    )
    return Checked(ctx, output, info, checked)


def _check_realized_density(problem: Problem, cliques: Cliques) -> None:
    """Realized following-type conflicts of a re-schedule must fit every clique's budget.

    Raises:
        ProblemError: they do not (the progress reports more robots crowding a place
            than its density allows), naming ``progress``.
    """
    if not problem.realized.any():
        return
    counts = cliques.following_counts((problem.fixed_type == 1)[None])[0]  # (Q,)
    over = np.flatnonzero(counts > cliques.budget)
    if over.size:
        raise ProblemError(
            [
                ErrorItem(
                    ("body", "progress"),
                    f"the past this progress describes has {int(counts[q])} following-type "
                    f"conflicts in a density clique that allows {int(cliques.budget[q])}",
                )
                for q in over[:50].tolist()
            ]
        )


def render_reserve(problem: Problem) -> float:
    """Seconds kept after the solve for checking, evaluating and rendering its answer."""
    return RENDER_S_PER_ITEM * (problem.n_conflicts + problem.n_nodes) + RENDER_S_MIN


def _time_left(time_limit_s: float, deadline: float | None) -> float:
    """``time_limit_s``, or less if ``deadline`` comes sooner (never negative)."""
    if deadline is None:
        return time_limit_s
    return max(0.0, min(time_limit_s, deadline - time.monotonic()))


def _first_valid_answer(ctx: SolveContext, name: str) -> tuple[str, SolverOutput, CheckResult]:
    """Run ``name``, then its fallbacks, until one answer passes the checker.

    A solver that raises is logged and skipped like one without an answer;
    only the last resort (FCFS, which cannot fail on a validated problem) may raise.

    Raises:
        InvalidAnswerError: not even the last resort gave a valid answer (a bug).
    """
    chain = dict.fromkeys((name, *FALLBACKS.get(name, ()), LAST_RESORT))
    for candidate in chain:
        try:
            output = get_solver(candidate)(ctx)
        except Exception:  # a solver bug must cost the request its answer quality, not a 500
            if candidate == LAST_RESORT:
                raise
            log.exception("solver %s failed; trying its fallback", candidate)
            continue
        if output is None:
            continue
        checks = check(ctx.problem, ctx.cliques, output.assignment)
        if checks.ok[0]:
            return candidate, output, checks
        log.error("solver %s returned an invalid assignment; trying its fallback", candidate)
    raise InvalidAnswerError(f"no solver in {list(chain)} gave a valid answer")


def _render(
    objective: Objective,
    ctx: SolveContext,
    output: SolverOutput,
    info: SolverInfoOut,
    checks: ChecksOut,
) -> ScheduleResponse:
    """Evaluate the assignment and build the wire response."""
    problem, ev = ctx.problem, ctx.evaluator
    result = ev.evaluate(output.assignment)
    first, second = output.assignment.from_to(problem)
    following = output.assignment.following[0]
    ids = problem.node_ids
    # Plain dicts (AssignmentOut is a TypedDict): 20,000 assignment models built one by
    # one in Python cost 70 ms of a 250-robot re-schedule.
    assignment = [
        {"from": ids[u], "to": ids[v], "type": "following" if f else "exclusive"}
        for u, v, f in zip(first.tolist(), second.tolist(), following.tolist(), strict=True)
    ]
    enter = (problem.node_enter + ev.delays_at(result, 0, problem.tp_node_enter)).tolist()
    exit_ = (problem.node_exit + ev.delays_at(result, 0, problem.tp_node_exit)).tolist()
    final_delay = ev.delays_at(result, 0, problem.last_tp).tolist()  # (R,)
    completion = result.completion[0].tolist()  # (R,)
    bounds = problem.robot_start.tolist()
    schedule = [
        RobotScheduleOut.model_construct(
            robot=rid,
            completion=completion[r],
            delay=final_delay[r],
            nodes=[
                NodeTimesOut.model_construct(id=ids[v], enter=enter[v], exit=exit_[v])
                for v in range(bounds[r], bounds[r + 1])
            ],
        )
        for r, rid in enumerate(problem.robot_ids)
    ]
    costs = {k: float(v[0]) for k, v in result.costs.items()}
    # Constructed, not validated: every part is built above, in the models' own types,
    # from the problem's ids and Python floats of checked arrays (tests validate rendered
    # answers against the models and the JSON Schema). Validating 20,000 assignment
    # entries again cost 25 ms of a 250-robot re-schedule.
    return ScheduleResponse.model_construct(
        dependencies=dependency_plan(problem, output.assignment),
        objective=objective,
        cost=costs[objective],
        costs=CostsOut(**costs),
        assignment=assignment,
        schedule=schedule,
        solver=info,
        checks=checks,
    )
