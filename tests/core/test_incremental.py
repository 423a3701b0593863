"""Incremental evaluation: single-move neighbours cost exactly what the full evaluator says.

Random problems (tiny, small, stitched; with fixed directions; re-schedule
residual problems, whose realized conflicts carry no constraint), random valid
base assignments (decoded random bids) and random moves: the incremental costs
of the neighbours equal the full evaluator's on all four objectives. Feasible
moves (what tabu evaluates) are settled by the kernel alone; any other move,
cyclic ones included, by the full evaluator's fallback.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core import evaluate
from service.core.assignment import Assignments
from service.core.cliques import find_cliques
from service.core.decode import Decoder
from service.core.evaluate import Evaluator
from service.core.incremental import IncrementalEvaluator, apply_moves
from service.core.orientation import OrientationGraph
from service.core.problem import Problem, problem_from_request
from service.core.progress import Progress, residual_problem
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext
from tests.reference import fix_directions, tiny_request, trap_request

KINDS = st.sampled_from(
    ["tiny", "small", "stitched", "tiny_fixed", "stitched_fixed", "residual_small", "residual"]
)
SEEDS = st.integers(0, 200)
DRAWS = st.integers(0, 2**32 - 1)


def _problem(req: dict[str, Any]) -> Problem:
    return problem_from_request(ScheduleRequest.model_validate(req))


def _request(kind: str, seed: int) -> dict[str, Any]:
    if kind.startswith("tiny"):
        req = tiny_request(seed)
    elif kind.startswith("small"):
        req = small_problem(seed)
    else:
        req = stitched_problem(seed, 20, 3.0)
    return fix_directions(req, seed) if kind.endswith("_fixed") else req


def _decoded(decoder: Decoder, draw: int) -> Assignments:
    """A random valid assignment: decoded random bids and scores."""
    rng = np.random.default_rng(draw)
    problem = decoder.problem
    return decoder.decode(
        rng.exponential(size=(1, problem.n_nodes)) + 1e-3, rng.random((1, problem.n_conflicts))
    )


def _residual(problem: Problem, seed: int) -> Problem:
    """The residual problem at a random moment of executing a random assignment, with some
    robots running later than planned."""
    previous = _decoded(Decoder(problem, find_cliques(problem)), seed)
    evaluator = Evaluator(problem)
    delays = evaluator.delays_at(evaluator.evaluate(previous), 0, np.arange(problem.tp_time.size))
    least = problem.tp_time + delays  # (P,)
    rng = np.random.default_rng([seed, 3])
    now = float(np.quantile(least, rng.random()))
    passed = np.flatnonzero(least <= now)
    passed_until = np.full(problem.n_robots, -np.inf)
    np.maximum.at(passed_until, problem.tp_robot[passed], problem.tp_time[passed])
    delay = np.zeros(problem.n_robots)
    delay[problem.tp_robot[passed]] = delays[passed]  # at the last passed point (sorted)
    delay += np.where(rng.random(problem.n_robots) < 0.3, rng.exponential(3.0), 0.0)
    return residual_problem(problem, Progress(now, passed_until, delay), previous)


@cache
def _setup(kind: str, seed: int) -> tuple[Decoder, IncrementalEvaluator, OrientationGraph]:
    if kind.startswith("residual"):
        problem = _residual(_problem(_request(kind.removeprefix("residual_"), seed)), seed)
    else:
        problem = _problem(_request(kind, seed))
    cliques = find_cliques(problem)
    incremental = IncrementalEvaluator(Evaluator(problem))
    return Decoder(problem, cliques), incremental, OrientationGraph(problem, cliques)


def _assert_equal_costs(got: dict[str, np.ndarray], want: dict[str, np.ndarray]) -> None:
    for k in OBJECTIVES:  # +inf where the full evaluator does not converge, in both
        np.testing.assert_allclose(got[k], want[k], rtol=1e-9, atol=1e-12, err_msg=k)


class _NoFullEvaluation:
    """Stands in for the full evaluator where the kernel must settle every move alone."""

    def evaluate(self, assignments: Assignments) -> None:
        raise AssertionError(f"{assignments.n_samples} neighbours fell back to the full evaluator")


@settings(max_examples=80, deadline=None, derandomize=True)
@given(kind=KINDS, seed=SEEDS, draw=DRAWS)
def test_feasible_moves_cost_what_the_full_evaluator_says(kind: str, seed: int, draw: int) -> None:
    """The moves tabu evaluates: valid neighbours, settled by the kernel alone."""
    decoder, incremental, graph = _setup(kind, seed)
    base = _decoded(decoder, draw)
    moves = np.random.default_rng(draw).permutation(2 * decoder.problem.n_conflicts)[:64]
    moves = moves[graph.feasible(base.a_first[0], base.following[0], moves)]
    evaluator = incremental.evaluator
    want = evaluator.evaluate(apply_moves(base, moves)).costs
    incremental.evaluator = _NoFullEvaluation()  # type: ignore[assignment]
    try:
        got = incremental.costs(base, evaluator.evaluate(base), moves)
    finally:
        incremental.evaluator = evaluator
    assert all(np.isfinite(want[k]).all() for k in OBJECTIVES)
    _assert_equal_costs(got, want)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(kind=KINDS, seed=SEEDS, draw=DRAWS)
def test_every_move_costs_what_the_full_evaluator_says(kind: str, seed: int, draw: int) -> None:
    """Any move, also one that closes a cycle, or moves a fixed or realized conflict."""
    decoder, incremental, _ = _setup(kind, seed)
    base = _decoded(decoder, draw)
    moves = np.arange(2 * decoder.problem.n_conflicts)
    evaluator = incremental.evaluator
    want = evaluator.evaluate(apply_moves(base, moves)).costs
    _assert_equal_costs(incremental.costs(base, evaluator.evaluate(base), moves), want)


def test_a_batch_picks_its_base_sample() -> None:
    decoder, incremental, _ = _setup("small", 4)
    first, second = _decoded(decoder, 1), _decoded(decoder, 2)
    batch = Assignments(
        np.concatenate([first.a_first, second.a_first]),
        np.concatenate([first.following, second.following]),
    )
    moves = np.arange(2 * decoder.problem.n_conflicts)
    evaluator = incremental.evaluator
    got = incremental.costs(batch, evaluator.evaluate(batch), moves, sample=1)
    _assert_equal_costs(got, evaluator.evaluate(apply_moves(second, moves)).costs)


def test_a_wait_free_cyclic_base_is_handed_to_the_full_evaluator() -> None:
    """The trap's node cycle needs no waiting: converged, but no topological order."""
    problem = _problem(trap_request())
    incremental = IncrementalEvaluator(Evaluator(problem))
    base = Assignments.single([False] * 3, [False] * 3)
    evaluation = incremental.evaluator.evaluate(base)
    assert evaluation.converged.tolist() == [True]
    moves = np.arange(6)
    want = incremental.evaluator.evaluate(apply_moves(base, moves)).costs
    _assert_equal_costs(incremental.costs(base, evaluation, moves), want)


def test_a_base_without_least_times_is_refused() -> None:
    problem = _problem(trap_request())
    incremental = IncrementalEvaluator(Evaluator(problem))
    base = Assignments.single([True] * 3, [False] * 3)  # a positive cycle
    with pytest.raises(ValueError, match="no least times"):
        incremental.costs(base, incremental.evaluator.evaluate(base), np.arange(6))


def test_apply_moves_changes_one_decision_each() -> None:
    base = Assignments.single([True, False, True], [False, False, True])
    out = apply_moves(base, np.array([1, 3, 5]))  # reverse conflict 1; retype 0; retype 2
    assert out.a_first.tolist() == [[True, True, True], [True, False, True], [True, False, True]]
    assert out.following.tolist() == [
        [False, False, True],
        [True, False, True],
        [False, False, False],
    ]


def test_a_250_robot_graph_from_fcfs() -> None:
    """The benchmark's size: 100 feasible moves from FCFS, binding conflicts among them."""
    problem = _problem(stitched_problem(0, 250, 4.0))
    ctx = SolveContext(problem, "avg_completion", 1.0)
    base = fcfs(ctx).assignment
    evaluation = ctx.evaluator.evaluate(base)
    binding = np.flatnonzero(ctx.evaluator.binding(base, evaluation))
    candidates = np.concatenate([binding, binding + problem.n_conflicts, np.arange(200)])
    moves = candidates[ctx.orientation.feasible(base.a_first[0], base.following[0], candidates)]
    moves = moves[:100]
    got = IncrementalEvaluator(ctx.evaluator).costs(base, evaluation, moves)
    _assert_equal_costs(got, ctx.evaluator.evaluate(apply_moves(base, moves)).costs)


def _rule(costs: np.ndarray, tabu: np.ndarray, best: float) -> tuple[int, float] | None:
    """Tabu search's rule on full costs: the cheapest admissible move, first on ties."""
    admissible = ~tabu | (costs < best)
    if not admissible.any():
        return None
    k = int(np.flatnonzero(admissible)[np.argmin(costs[admissible])])
    return k, float(costs[k])


@settings(max_examples=80, deadline=None, derandomize=True)
@given(
    kind=KINDS,
    seed=SEEDS,
    draw=DRAWS,
    objective=st.sampled_from(OBJECTIVES),
    tabu_share=st.sampled_from([0.0, 0.5, 1.0]),
    best_shift=st.sampled_from([-0.05, 0.0, 0.05, np.inf]),
)
def test_best_move_chooses_what_costing_every_move_would(
    kind: str, seed: int, draw: int, objective: str, tabu_share: float, best_shift: float
) -> None:
    """best_move stops costing moves that cannot win (weighted-sum objectives); its choice
    and cost are the rule's on every move's full cost, also with every move tabu and a
    best cost below, at or above the base's (aspiration)."""
    decoder, incremental, graph = _setup(kind, seed)
    base = _decoded(decoder, draw)
    rng = np.random.default_rng(draw)
    moves = rng.permutation(2 * decoder.problem.n_conflicts)[:64]
    moves = moves[graph.feasible(base.a_first[0], base.following[0], moves)]
    evaluation = incremental.evaluator.evaluate(base)
    tabu = rng.random(moves.size) < tabu_share
    cost = float(evaluation.costs[objective][0])
    best = cost * (1.0 + best_shift) if np.isfinite(best_shift) else np.inf
    want = _rule(incremental.costs(base, evaluation, moves)[objective], tabu, best)
    got = incremental.best_move(base, evaluation, moves, objective, tabu, best)
    if want is None:
        assert got is None
    else:
        assert got is not None and got[0] == want[0]
        assert got[1] == pytest.approx(want[1], rel=1e-12)


def test_best_move_leaves_losing_moves_uncosted_on_a_congested_graph() -> None:
    """The cutoff does cut: on a dense stitched graph most moves stop early."""
    problem = _problem(stitched_problem(5, 60, 4.0))
    cliques = find_cliques(problem)
    incremental = IncrementalEvaluator(Evaluator(problem))
    base = fcfs(SolveContext(problem, "avg_completion", 1.0)).assignment
    graph = OrientationGraph(problem, cliques)
    moves = np.arange(2 * problem.n_conflicts)
    moves = moves[graph.feasible(base.a_first[0], base.following[0], moves)]
    evaluation = incremental.evaluator.evaluate(base)
    tabu = np.zeros(moves.size, dtype=bool)
    weight = incremental._last_weight
    _, cut = incremental._costs(base, evaluation, moves, 0, (weight, tabu, np.inf, 1e-9))
    assert moves.size > 20 and cut.mean() > 0.3


@settings(max_examples=80, deadline=None)
@given(
    kind=KINDS,
    seed=SEEDS,
    draw=DRAWS,
    candidates=st.integers(0, 6),
    decoded=st.booleans(),
    threads=st.sampled_from([1, 3]),
)
def test_flipped_candidates_equal_the_full_evaluator(
    kind: str, seed: int, draw: int, candidates: int, decoded: bool, threads: int
) -> None:
    """Candidates that each reverse a few conflicts of one base, evaluated from the base's
    grouped arcs, get exactly the full evaluator's delays, costs and convergence (cyclic
    candidates and bases, realized conflicts, split over threads included)."""
    decoder, incremental, _ = _setup(kind, seed)
    problem = decoder.problem
    rng = np.random.default_rng(draw)
    if decoded:
        base = _decoded(decoder, draw)
    else:  # any directions and types: cycles too
        shape = (1, problem.n_conflicts)
        base = Assignments(rng.random(shape) < 0.5, rng.random(shape) < 0.5)
    sizes = rng.integers(0, problem.n_conflicts + 1, size=candidates)  # (C,)
    flipped = [rng.choice(problem.n_conflicts, size=n, replace=False) for n in sizes]
    start = np.concatenate([[0], np.cumsum(sizes)])  # (C+1,)
    a_first = np.repeat(base.a_first, candidates, axis=0)  # (C, M)
    for i, conflicts in enumerate(flipped):
        a_first[i, conflicts] ^= True
    want = Evaluator(problem).evaluate(
        Assignments(a_first, np.repeat(base.following, candidates, axis=0))
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(evaluate, "MIN_THREAD_WORK", 1)  # split even the smallest batch
        got = Evaluator(problem, threads=threads).evaluate_flips(
            base, start, np.concatenate([np.zeros(0, dtype=np.int64), *flipped])
        )
    np.testing.assert_array_equal(got.event_delay, want.event_delay)
    np.testing.assert_array_equal(got.converged, want.converged)
    for k in OBJECTIVES:
        np.testing.assert_array_equal(got.costs[k], want.costs[k])


def test_a_candidate_listing_a_conflict_twice_is_refused() -> None:
    decoder, _, _ = _setup("small", 0)
    base = _decoded(decoder, 0)
    evaluator = Evaluator(decoder.problem)
    with pytest.raises(ValueError, match="twice"):
        evaluator.evaluate_flips(base, np.array([0, 2]), np.array([1, 1]))
    with pytest.raises(ValueError, match="single"):
        evaluator.evaluate_flips(base.take(np.array([0, 0])), np.array([0]), np.array([]))
