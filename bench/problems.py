"""Deterministic benchmark problem sets, built from :mod:`service.learning.generate`.

Every problem's seed is derived from the set's base seed and the problem's place
in the set (family, robots, density, index) through ``numpy.random.SeedSequence``,
so a set is the same on every machine and growing one group (say from 5 to 50
problems) keeps the problems it already had.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.core.cliques import Cliques, find_cliques
from service.core.problem import Problem, problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import GeneratorConfig, small_problem, stitched_problem

__all__ = ["BenchProblem", "derive_seed", "prepare", "small_set", "stitched_set"]

# Family tags mixed into the seeds, so the small and the stitched sets never share one.
_SMALL, _STITCHED = 1, 2


@dataclass(frozen=True, eq=False)
class BenchProblem:
    """One validated problem of a set, with where it came from."""

    family: str  # "small" or "stitched"
    robots: int
    conflicts_per_robot: float | None  # stitched density asked for; None for small problems
    index: int
    seed: int
    request: dict
    problem: Problem
    cliques: Cliques


def derive_seed(base_seed: int, *key: int) -> int:
    """A 32-bit seed from the base seed and a problem's integer key (stable across runs)."""
    return int(np.random.SeedSequence([base_seed, *key]).generate_state(1)[0])


def prepare(request: dict) -> tuple[Problem, Cliques]:
    """Validate a request dict the way the service does and build its cliques."""
    problem = problem_from_request(ScheduleRequest.model_validate(request))
    return problem, find_cliques(problem)


def small_set(robots: int, count: int, base_seed: int = 0) -> list[BenchProblem]:
    """``count`` small problems (the training-set generator) with exactly ``robots`` robots."""
    cfg = GeneratorConfig(min_robots=robots, max_robots=robots)
    out = []
    for i in range(count):
        seed = derive_seed(base_seed, _SMALL, robots, i)
        request = small_problem(seed, cfg=cfg)
        out.append(BenchProblem("small", robots, None, i, seed, request, *prepare(request)))
    return out


def stitched_set(
    robots: int,
    conflicts_per_robot: float,
    count: int,
    base_seed: int = 0,
    cfg: GeneratorConfig | None = None,
) -> list[BenchProblem]:
    """``count`` stitched problems of ``robots`` robots and about that many conflicts each.

    ``cfg`` sets the parts' sizes (default: the generator's): a fleet smaller
    than two default parts needs smaller parts, or there is no pair of parts to
    add conflicts between.
    """
    cfg = cfg or GeneratorConfig()
    out = []
    density_key = int(round(conflicts_per_robot * 1000))
    for i in range(count):
        seed = derive_seed(base_seed, _STITCHED, robots, density_key, i)
        request = stitched_problem(seed, robots, conflicts_per_robot, cfg=cfg)
        out.append(
            BenchProblem(
                "stitched", robots, conflicts_per_robot, i, seed, request, *prepare(request)
            )
        )
    return out
