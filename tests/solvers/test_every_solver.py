"""Every registered solver, on random problems: a valid answer within the time limit.

A property test over the whole registry (hypothesis draws the problem family,
size, density and seed), so a solver added later is covered without a new test.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import get_args

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core.check import check
from service.core.problem import problem_from_request
from service.core.schemas import OBJECTIVES, ScheduleRequest, SolverName
from service.learning.generate import small_problem, stitched_problem
from service.learning.store import load_all
from service.solvers.dispatch import DispatchPolicy  # noqa: F401  (registers every solver)
from service.solvers.registry import SolveContext, get_solver, solver_names
from tests.reference import tiny_request

STORE = Path(__file__).resolve().parents[2] / "model_store"
MODELS, _ = load_all(STORE, OBJECTIVES)
TIME_LIMIT_S = 0.5
SLACK_S = 1.5  # a correctness bound on overrunning the limit, not a performance figure


def test_the_registry_is_the_wire_contract() -> None:
    assert set(solver_names()) == set(get_args(SolverName))


def _request(family: str, seed: int, robots: int, density: float) -> dict:
    if family == "tiny":
        return tiny_request(seed)
    if family == "small":
        return small_problem(seed)
    return stitched_problem(seed, robots, density)


@pytest.mark.parametrize("name", sorted(get_args(SolverName)))
@settings(
    max_examples=6, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    family=st.sampled_from(["tiny", "small", "stitched"]),
    seed=st.integers(0, 10_000),
    robots=st.integers(2, 40),
    density=st.floats(0.5, 5.0),
    objective=st.sampled_from(OBJECTIVES),
)
def test_every_answer_is_valid_and_in_time(
    name: str, family: str, seed: int, robots: int, density: float, objective: str
) -> None:
    request = {**_request(family, seed, robots, density), "objective": objective}
    problem = problem_from_request(ScheduleRequest.model_validate(request))
    ctx = SolveContext(problem, objective, TIME_LIMIT_S, seed=seed, models=MODELS)
    start = time.perf_counter()
    out = get_solver(name)(ctx)
    assert time.perf_counter() - start < TIME_LIMIT_S + SLACK_S
    if out is None:  # only CP-SAT may find nothing in time
        assert name in ("exact",)
        return
    assert out.assignment.a_first.shape == (1, problem.n_conflicts)
    checks = check(problem, ctx.cliques, out.assignment)
    assert checks.acyclic[0] and checks.density[0]
