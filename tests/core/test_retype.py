"""Types refitted to an assignment's directions: valid, never dearer, directions kept; types
by descent: valid, directions kept, a local optimum of single type flips."""

from __future__ import annotations

import time
from dataclasses import replace
from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core import retype
from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder
from service.core.evaluate import MONOTONE_OBJECTIVES, Evaluator
from service.core.incremental import apply_moves
from service.core.orientation import OrientationGraph
from service.core.problem import Problem, problem_from_request
from service.core.retype import descend_types, refit_types, updated_pair_times
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.generate import stitched_problem
from service.solvers.fcfs import fcfs_priorities
from tests.reference import feasible_assignments, reference_problem, tiny_request
from tests.worlds import congested_warehouse


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


def _some_following(start: Assignments, seed: int) -> Assignments:
    """``start``'s directions with a random half of its following-type conflicts (valid:
    fewer following-type conflicts never pass a clique's budget), as a descent meets
    them on its way (decoded types leave few binding waits exclusive)."""
    keep = np.random.default_rng(seed).random(start.following.shape) < 0.5
    return Assignments(start.a_first, start.following & keep)


# A stitched problem (seed), a random valid start on it (draw) and an objective.
STARTS = {
    "seed": st.integers(0, 40),
    "draw": st.integers(0, 10_000),
    "objective": st.sampled_from(OBJECTIVES),
}


@settings(max_examples=30, deadline=None)
@given(**STARTS, rounds=st.integers(0, 4))
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
    request = ScheduleRequest.model_validate(congested_warehouse())
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


@settings(max_examples=30, deadline=None)
@given(**STARTS, n_realized=st.integers(0, 3))
def test_types_by_descent_are_valid_and_no_single_flip_is_cheaper(
    seed: int, draw: int, objective: str, n_realized: int
) -> None:
    """From every conflict exclusive (realized types kept), the descent ends valid, with the
    start's directions, at a cost the evaluator confirms, where no feasible type flip is
    cheaper (checked by full evaluation of every one)."""
    problem, cliques, decoder, evaluator = _setup(seed)
    start = _random_start(decoder, problem, draw)
    if n_realized:  # some conflicts' types realized (fixed) as the start has them
        fixed = np.full(problem.n_conflicts, -1, dtype=np.int8)
        rng = np.random.default_rng(draw)
        chosen = rng.choice(problem.n_conflicts, n_realized, replace=False)
        fixed[chosen] = start.following[0, chosen]
        problem = replace(problem, fixed_type=fixed)
    orientation = OrientationGraph(problem, cliques)
    found, cost, flips = descend_types(
        orientation, evaluator, objective, start.a_first, time.monotonic() + 60.0
    )
    assert check(problem, cliques, found).ok.tolist() == [True]
    assert np.array_equal(found.a_first, start.a_first)
    realized_types = problem.fixed_type >= 0  # (M,)
    assert np.array_equal(
        found.following[0][realized_types], problem.fixed_type[realized_types] == 1
    )
    assert cost == float(evaluator.evaluate(found).costs[objective][0])
    flips_all = problem.n_conflicts + np.arange(problem.n_conflicts)
    feasible = flips_all[orientation.feasible(found.a_first[0], found.following[0], flips_all)]
    if feasible.size:
        neighbours = evaluator.evaluate(apply_moves(found, feasible)).costs[objective]
        assert neighbours.min() >= cost - 1e-9 * max(1.0, abs(cost))
    exclusive = Assignments(start.a_first, (problem.fixed_type == 1)[None])
    exclusive_cost = float(evaluator.evaluate(exclusive).costs[objective][0])
    assert cost <= exclusive_cost and (flips == 0) == (cost == exclusive_cost)


def test_types_by_descent_leave_the_refit_types_local_optimum() -> None:
    """On a congested two-way warehouse the descent from exclusive, on FCFS's directions,
    goes below the types refitted by spared waits (the decoder's), which no single flip
    improves."""
    problem, decoder, evaluator = _warehouse()
    ranks, scores = fcfs_priorities(problem)
    start = decoder.decode_ranks(ranks[None], scores[None])
    refit = refit_types(decoder, evaluator, "avg_completion", start)[1]
    orientation = OrientationGraph(problem, decoder.cliques)
    _, cost, flips = descend_types(
        orientation, evaluator, "avg_completion", start.a_first, time.monotonic() + 60.0
    )
    assert flips > 0 and cost < refit - 1e-6


def test_types_by_descent_stop_at_the_deadline() -> None:
    problem, decoder, evaluator = _warehouse()
    ranks, scores = fcfs_priorities(problem)
    start = decoder.decode_ranks(ranks[None], scores[None])
    orientation = OrientationGraph(problem, decoder.cliques)
    found, cost, flips = descend_types(
        orientation, evaluator, "avg_completion", start.a_first, time.monotonic() - 1.0
    )
    assert flips == 0 and not found.following[0][problem.fixed_type < 0].any()


def test_types_by_descent_stop_within_a_round_once_the_deadline_passes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The flips of a round are costed in chunks with the deadline checked between them:
    a clock past it after the round's first chunk ends the descent there, at its start."""
    problem, decoder, evaluator = _warehouse()
    ranks, scores = fcfs_priorities(problem)
    start = decoder.decode_ranks(ranks[None], scores[None])
    orientation = OrientationGraph(problem, decoder.cliques)
    readings = iter([0.0])  # the first look (the round starts), then past the deadline

    class Clock:
        @staticmethod
        def monotonic() -> float:
            return next(readings, 10.0)

    monkeypatch.setattr(retype, "COSTED_PER_CHECK", 1)
    monkeypatch.setattr(retype, "time", Clock)
    found, cost, rounds = descend_types(
        orientation, evaluator, "avg_completion", start.a_first, 5.0
    )
    assert rounds == 0 and not found.following[0][problem.fixed_type < 0].any()


def _round(seed: int, draw: int, objective: str) -> tuple:
    """What a round of the descent starts from on a stitched problem (seed): (problem,
    orientation, evaluator, a random valid answer with some following-type conflicts, its
    evaluation, the flips the round lists)."""
    problem, cliques, decoder, evaluator = _setup(seed)
    start = _some_following(_random_start(decoder, problem, draw), draw)
    orientation = OrientationGraph(problem, cliques)
    evaluation = evaluator.evaluate(start)
    may = (problem.fixed_type < 0) & ~cliques.forbidden()  # (M,)
    counts = cliques.following_counts(start.following)[0]  # (Q,)
    listed = retype._type_flips(orientation, evaluator, start, evaluation, may, objective, counts)
    return problem, orientation, evaluator, start, evaluation, listed


@settings(max_examples=30, deadline=None)
@given(
    seed=STARTS["seed"],
    draw=STARTS["draw"],
    objective=st.sampled_from(retype.MONOTONE_OBJECTIVES),
)
def test_the_flips_a_descent_leaves_uncosted_are_never_cheaper(
    seed: int, draw: int, objective: str
) -> None:
    """For the objectives that never fall when a delay rises, every feasible type flip that
    a round of the descent does not list (following made exclusive, waits that do not bind
    or hold up nothing the cost reads) costs at least as much by full evaluation, from
    any valid answer (decoded types, some following-type)."""
    problem, orientation, evaluator, start, evaluation, listed = _round(seed, draw, objective)
    every = problem.n_conflicts + np.arange(problem.n_conflicts)  # (M,)
    unlisted = np.setdiff1d(
        every[orientation.feasible(start.a_first[0], start.following[0], every)], listed
    )
    cost = float(evaluation.costs[objective][0])
    if unlisted.size:
        costs = evaluator.evaluate(apply_moves(start, unlisted)).costs[objective]
        assert costs.min() >= cost - 1e-9 * max(1.0, abs(cost))


@settings(max_examples=30, deadline=None)
@given(
    seed=STARTS["seed"],
    draw=STARTS["draw"],
    objective=st.sampled_from(retype.MONOTONE_OBJECTIVES),
)
def test_no_flip_gains_more_than_its_bound(seed: int, draw: int, objective: str) -> None:
    """What each listed flip lowers the cost by (full evaluation) is at most its bound,
    the bound by which a round leaves flips uncosted; a bound is zero only where its flip
    gains nothing."""
    _, _, evaluator, start, evaluation, moves = _round(seed, draw, objective)
    bounds = retype._FlipBounds(evaluator, objective).of(start, evaluation, moves)  # (K,)
    if not moves.size:
        return
    cost = float(evaluation.costs[objective][0])
    gains = cost - evaluator.evaluate(apply_moves(start, moves)).costs[objective]  # (K,)
    assert np.all(gains <= bounds)
    assert np.all(gains[bounds == 0] <= 1e-9 * max(1.0, abs(cost)))


def test_the_bounds_leave_the_descent_unchanged(monkeypatch: pytest.MonkeyPatch) -> None:
    """Costing every flip (no bounds) and costing by the bounds take the same flips: the
    same answer, bit for bit, on a congested warehouse, for every objective."""
    problem, decoder, evaluator = _warehouse()
    ranks, scores = fcfs_priorities(problem)
    start = decoder.decode_ranks(ranks[None], scores[None])
    orientation = OrientationGraph(problem, decoder.cliques)
    for objective in OBJECTIVES:
        bounded = descend_types(
            orientation, evaluator, objective, start.a_first, time.monotonic() + 60.0
        )
        with monkeypatch.context() as patch:
            patch.setattr(retype, "MONOTONE_OBJECTIVES", ())
            every = descend_types(
                orientation, evaluator, objective, start.a_first, time.monotonic() + 60.0
            )
        assert bounded[1:] == every[1:] and bounded[2] > 0
        np.testing.assert_array_equal(bounded[0].following, every[0].following)


@pytest.mark.parametrize("seed", range(40))
def test_types_by_descent_are_the_cheapest_types_where_no_budget_binds(seed: int) -> None:
    """On tiny problems whose budgets cannot bind (every node holding every robot), the
    descent's types cost what the cheapest valid types for the same directions cost, by
    brute force over every typing, for the objectives that never fall when a delay rises."""
    req = tiny_request(seed)
    req["density_limits"] = [lim for lim in req.get("density_limits", []) if lim["max_robots"] < 2]
    for robot in req["robots"]:
        for node in robot["nodes"]:
            node["density"] = len(req["robots"])
    ref = reference_problem(req)
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    cliques = find_cliques(problem)
    assert not cliques.binding().any()
    orientation, evaluator = OrientationGraph(problem, cliques), Evaluator(problem)
    candidates = feasible_assignments(ref)
    for directions in sorted({c.a_first for c in candidates})[:3]:
        a_first = np.array(directions, dtype=bool)[None]  # (1, M)
        for objective in MONOTONE_OBJECTIVES:
            _, cost, _ = descend_types(
                orientation, evaluator, objective, a_first, time.monotonic() + 60.0
            )
            best = min(c.costs[objective] for c in candidates if c.a_first == directions)
            assert cost == pytest.approx(best, rel=1e-9, abs=1e-9)
