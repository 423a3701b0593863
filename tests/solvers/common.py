"""Helpers shared by the solver tests: a solve context for a request, and an answer's cost."""

from __future__ import annotations

from typing import Any

from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.solvers.registry import SolveContext, SolverOutput


def context(
    request: dict[str, Any], objective: str, time_limit_s: float = 30.0, **options: Any
) -> SolveContext:
    """A context for ``request`` under ``objective``; ``options``: seed, samples, models."""
    validated = ScheduleRequest.model_validate({**request, "objective": objective})
    return SolveContext(problem_from_request(validated), objective, time_limit_s, **options)


def cost(ctx: SolveContext, output: SolverOutput) -> float:
    """The cost of a solver's answer under the context's objective."""
    return float(ctx.evaluator.evaluate(output.assignment).costs[ctx.objective][0])
