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
from dataclasses import dataclass

from service.core.check import check
from service.core.problem import problem_from_request
from service.core.schemas import (
    AssignmentOut,
    ChecksOut,
    CostsOut,
    NodeTimesOut,
    RobotScheduleOut,
    ScheduleRequest,
    ScheduleResponse,
    SolverInfoOut,
)
from service.solvers import exact, fcfs  # noqa: F401  (registers the solvers)
from service.solvers.registry import SolveContext, SolverOutput, get_solver

__all__ = ["DispatchPolicy", "InvalidAnswerError", "dispatch"]

log = logging.getLogger(__name__)

FALLBACK_SOLVER = "fcfs"


class InvalidAnswerError(RuntimeError):
    """Even the fallback produced an assignment the checker rejects (a bug, never expected)."""


@dataclass(frozen=True)
class DispatchPolicy:
    """How requests are routed and limited (built from the settings)."""

    default_time_limit_s: float = 5.0
    exact_max_robots: int = 30
    large_solver: str = "exact"
    exact_workers: int = 1


def choose_solver(request: ScheduleRequest, n_robots: int, policy: DispatchPolicy) -> str:
    """The solver that answers: the requested one, or by size for ``auto``."""
    name = request.options.solver
    if name != "auto":
        return name
    return "exact" if n_robots <= policy.exact_max_robots else policy.large_solver


def dispatch(request: ScheduleRequest, policy: DispatchPolicy) -> ScheduleResponse:
    """Solve ``request`` and return a checked response.

    Raises:
        ProblemError: the request breaks a cross-field rule of the contract.
    """
    problem = problem_from_request(request)
    opts = request.options
    ctx = SolveContext(
        problem=problem,
        objective=request.objective,
        time_limit_s=opts.time_limit_s or policy.default_time_limit_s,
        seed=opts.seed,
        samples=opts.samples,
        workers=policy.exact_workers,
    )
    name = choose_solver(request, problem.n_robots, policy)
    start = time.perf_counter()
    output = get_solver(name)(ctx)
    used, fallback_from = name, None
    if output is None or not check(problem, ctx.cliques, output.assignment).ok[0]:
        if output is not None:
            log.error("solver %s returned an invalid assignment; falling back to fcfs", name)
        used, fallback_from = FALLBACK_SOLVER, name
        output = get_solver(FALLBACK_SOLVER)(ctx)
    checks = check(problem, ctx.cliques, output.assignment)
    if not checks.ok[0]:
        raise InvalidAnswerError(f"fallback {FALLBACK_SOLVER} answer failed the checker")
    runtime = time.perf_counter() - start
    info = SolverInfoOut(
        name=used,
        optimal=output.optimal,
        runtime_s=runtime,
        model=output.model,
        samples=output.samples,
        fallback_from=fallback_from,
        detail=output.detail,
    )
    checked = ChecksOut(acyclic=bool(checks.acyclic[0]), density=bool(checks.density[0]))
    return _render(request, ctx, output, info, checked)


def _render(
    request: ScheduleRequest,
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
    assignment = [
        AssignmentOut(from_=ids[u], to=ids[v], type="following" if f else "exclusive")
        for u, v, f in zip(first.tolist(), second.tolist(), following.tolist(), strict=True)
    ]
    enter = problem.node_enter + ev.delays_at(result, 0, problem.tp_node_enter)  # (V,)
    exit_ = problem.node_exit + ev.delays_at(result, 0, problem.tp_node_exit)  # (V,)
    final_delay = ev.delays_at(result, 0, problem.last_tp)  # (R,)
    schedule = []
    for r, rid in enumerate(problem.robot_ids):
        nodes = range(problem.robot_start[r], problem.robot_start[r + 1])
        schedule.append(
            RobotScheduleOut(
                robot=rid,
                completion=float(result.completion[0, r]),
                delay=float(final_delay[r]),
                nodes=[NodeTimesOut(id=ids[v], enter=float(enter[v]), exit=float(exit_[v])) for v in nodes],
            )
        )
    costs = {k: float(v[0]) for k, v in result.costs.items()}
    return ScheduleResponse(
        objective=request.objective,
        cost=costs[request.objective],
        costs=CostsOut(**costs),
        assignment=assignment,
        schedule=schedule,
        solver=info,
        checks=checks,
    )

