"""The constraint checker agrees with the brute-force reference, trap included."""

from __future__ import annotations

import numpy as np
import pytest

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import find_cliques
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import small_problem
from tests.reference import (
    density_groups,
    density_ok,
    is_acyclic,
    reference_problem,
    tiny_request,
    trap_request,
)


def test_trap_cycles_are_rejected_and_orders_accepted() -> None:
    problem = problem_from_request(ScheduleRequest.model_validate(trap_request()))
    batch = Assignments(
        np.array(
            [
                [False, False, False],  # b -> a, c -> b, a -> c: cycle, needs no waiting
                [True, True, True],  # a -> b -> c -> a: cycle
                [True, True, False],  # a -> b -> c, a -> c: the order a, b, c
                [False, True, True],  # b -> a, b -> c, c -> a: the order b, c, a
            ]
        ),
        np.zeros((4, 3), dtype=bool),
    )
    result = check(problem, find_cliques(problem), batch)
    assert result.acyclic.tolist() == [False, False, True, True]
    assert result.density.tolist() == [True] * 4
    assert result.ok.tolist() == [False, False, True, True]
    # Following type in a density-1 clique is over budget.
    following = check(
        problem, find_cliques(problem), Assignments.single([True, True, False], [1, 0, 0])
    )
    assert following.density.tolist() == [False]


@pytest.mark.parametrize("seed", range(30))
def test_check_equals_brute_force(seed: int) -> None:
    req = tiny_request(seed) if seed % 2 else small_problem(seed)
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    ref = reference_problem(req)
    groups = density_groups(ref)
    rng = np.random.default_rng(seed)
    shape = (64, problem.n_conflicts)
    batch = Assignments(rng.random(shape) < 0.5, rng.random(shape) < rng.random((64, 1)))
    result = check(problem, find_cliques(problem), batch)
    for s in range(batch.n_samples):
        assert result.acyclic[s] == is_acyclic(ref, batch.a_first[s].tolist())
        assert result.density[s] == density_ok(groups, batch.following[s].tolist())
