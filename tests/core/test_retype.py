"""Types refitted to an assignment's directions: valid, never dearer, directions kept."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder
from service.core.evaluate import Evaluator
from service.core.problem import Problem, problem_from_request
from service.core.retype import refit_types, updated_pair_times
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.generate import stitched_problem
from service.solvers.fcfs import fcfs_priorities
from tests.worlds import world_request


@cache
def _setup(seed: int) -> tuple[Problem, Cliques, Decoder, Evaluator]:
    problem = problem_from_request(ScheduleRequest.model_validate(stitched_problem(seed, 30, 4.0)))
    cliques = find_cliques(problem)
    return problem, cliques, Decoder(problem, cliques), Evaluator(problem)


def _random_start(decoder: Decoder, problem: Problem, seed: int) -> Assignments:
    """A valid assignment from random bids and type scores (the decoder guarantees it)."""
    rng = np.random.default_rng(seed)
    bids = rng.uniform(0.1, 10.0, (1, problem.n_nodes))
    return decoder.decode(bids, rng.uniform(size=(1, problem.n_conflicts)))


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 40),
    draw=st.integers(0, 10_000),
    objective=st.sampled_from(OBJECTIVES),
    rounds=st.integers(0, 4),
)
def test_refitted_types_keep_the_directions_and_never_cost_more(
    seed: int, draw: int, objective: str, rounds: int
) -> None:
    problem, cliques, decoder, evaluator = _setup(seed)
    start = _random_start(decoder, problem, draw)
    start_cost = float(evaluator.evaluate(start).costs[objective][0])
    found, cost = refit_types(decoder, evaluator, objective, start, rounds)
    assert check(problem, cliques, found).ok.tolist() == [True]
    assert np.array_equal(found.a_first, start.a_first)
    assert cost <= start_cost
    assert cost == pytest.approx(float(evaluator.evaluate(found).costs[objective][0]), rel=1e-12)
    if rounds == 0:  # only the planned times' types were tried
        planned = Assignments(start.a_first, decoder.gain_types(start.a_first))
        planned_cost = float(evaluator.evaluate(planned).costs[objective][0])
        assert cost == pytest.approx(min(start_cost, planned_cost), rel=1e-12)


@cache
def _warehouse() -> tuple[Problem, Decoder, Evaluator]:
    """A congested two-way warehouse of 25 robots: waits there move the pair times far
    from the planned ones."""
    request = ScheduleRequest.model_validate(world_request("wh_two_way", 25, 60))
    problem = problem_from_request(request)
    return problem, Decoder(problem, find_cliques(problem)), Evaluator(problem)


def test_updated_times_refit_what_planned_times_leave() -> None:
    """The rounds at updated times are not idle: on a congested warehouse they go below
    the planned times' types (FCFS's start: 54.26 at planned times, 50.83 after)."""
    problem, decoder, evaluator = _warehouse()
    ranks, scores = fcfs_priorities(problem)
    start = decoder.decode_ranks(ranks[None], scores[None])
    planned = refit_types(decoder, evaluator, "avg_completion", start, rounds=0)[1]
    updated = refit_types(decoder, evaluator, "avg_completion", start)[1]
    assert updated < planned - 1e-6


@pytest.mark.parametrize("draw", range(4))
def test_updated_pair_times_are_the_schedules_least_times_at_the_pair_points(draw: int) -> None:
    """Each side's updated pair times are its planned ones plus its waits, and they hold
    every conflict's rule (the second side enters once the first has left, or entered)."""
    problem, decoder, evaluator = _warehouse()
    start = _random_start(decoder, problem, draw)
    enter, exit_ = updated_pair_times(evaluator, evaluator.evaluate(start))  # (M, 2) each
    assert enter.shape == exit_.shape == (problem.n_conflicts, 2)
    assert np.all(enter >= problem.pair_enter - 1e-9) and np.all(exit_ >= problem.pair_exit - 1e-9)
    assert np.all(exit_ >= enter - 1e-9)
    first = np.where(start.a_first[0], 0, 1)  # (M,) side passing first
    rows = np.arange(problem.n_conflicts)
    released = np.where(start.following[0], enter[rows, first], exit_[rows, first])  # (M,)
    assert np.all(enter[rows, 1 - first] >= released - 1e-6)
