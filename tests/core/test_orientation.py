"""Move feasibility and backtracking enumeration, against the brute-force reference."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import find_cliques
from service.core.decode import Decoder
from service.core.orientation import OrientationGraph
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import stitched_problem
from tests.reference import feasible_assignments, reference_problem, tiny_request, trap_request


def _graph(req: dict) -> OrientationGraph:
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    return OrientationGraph(problem, find_cliques(problem))


def _keys(a: Assignments) -> list[tuple[tuple[bool, ...], tuple[bool, ...]]]:
    return [
        (tuple(a.a_first[s].tolist()), tuple(a.following[s].tolist())) for s in range(a.n_samples)
    ]


TINY = [tiny_request(s) for s in range(40)] + [trap_request()]


@pytest.mark.parametrize("req", TINY, ids=[f"tiny-{s}" for s in range(40)] + ["trap"])
def test_exhaustive_enumeration_is_exactly_the_valid_set(req: dict) -> None:
    graph = _graph(req)
    m = graph.problem.n_conflicts
    rng = np.random.default_rng(m)
    search = graph.enumerate(rng.permutation(m), rng.random(m) < 0.5, follow_first=bool(m % 2))
    leaves = search.next(100_000)
    assert search.done
    assert search.next(10).n_samples == 0
    keys = _keys(leaves)
    assert len(set(keys)) == len(keys), "a leaf was produced twice"
    expected = {(c.a_first, c.following) for c in feasible_assignments(reference_problem(req))}
    assert set(keys) == expected


@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 10_000), count=st.integers(1, 5), moves=st.integers(1, 7))
def test_enumeration_resumes_where_it_stopped(seed: int, count: int, moves: int) -> None:
    """Cut after ``count`` leaves or ``moves`` moves, whichever comes first, and resumed:
    the same leaves in the same order as one uncut enumeration, and the same moves."""
    graph = _graph(tiny_request(seed))
    m = graph.problem.n_conflicts
    if m == 0:
        return  # one leaf, no move
    args = (np.random.default_rng(seed).permutation(m), np.ones(m, dtype=bool), bool(seed % 2))
    uncut = graph.enumerate(*args)
    whole = _keys(uncut.next(100_000))
    search = graph.enumerate(*args)
    pieces: list = []
    while not search.done:
        before = search.moves
        pieces += _keys(search.next(count, moves))
        assert 0 < search.moves - before <= moves
    assert pieces == whole
    assert search.moves == uncut.moves


def test_first_leaves_of_a_large_problem_are_valid_and_distinct() -> None:
    graph = _graph(stitched_problem(0, 120, 3.0))
    m = graph.problem.n_conflicts
    leaves = graph.enumerate(np.arange(m), np.ones(m, dtype=bool), True).next(200)
    assert leaves.n_samples == 200
    assert len(set(_keys(leaves))) == 200
    assert check(graph.problem, graph.cliques, leaves).ok.all()


@pytest.mark.parametrize("seed", range(8))
def test_move_feasibility_agrees_with_the_checker(seed: int) -> None:
    """Every single move of decoded assignments; the direction checks search only between
    the two nodes' places in a topological order, which must lose no path: larger stitched
    problems (robots of many nodes, long detours) check that."""
    sizes = {1: 15, 3: 15, 5: 40, 7: 80}
    req = stitched_problem(seed, sizes[seed], 3.0) if seed % 2 else tiny_request(seed)
    graph = _graph(req)
    problem, m = graph.problem, graph.problem.n_conflicts
    rng = np.random.default_rng(seed)
    decoded = Decoder(problem, graph.cliques).decode(
        rng.exponential(size=(5, problem.n_nodes)) + 1e-3, rng.random((5, m))
    )
    moves = np.arange(2 * m)  # 0..m-1 reverse conflict k, m..2m-1 flip its type
    conflict = np.arange(m)
    for s in range(decoded.n_samples):
        a_first, following = decoded.a_first[s], decoded.following[s]
        neighbours = Assignments(np.tile(a_first, (2 * m, 1)), np.tile(following, (2 * m, 1)))
        neighbours.a_first[conflict, conflict] ^= True
        neighbours.following[m + conflict, conflict] ^= True
        expected = check(problem, graph.cliques, neighbours).ok
        assert graph.feasible(a_first, following, moves).tolist() == expected.tolist()


def test_counts_kept_move_by_move_equal_a_fresh_count() -> None:
    """Tabu keeps the clique counts with count_type_move instead of recounting: after a
    walk of feasible type moves they equal a fresh count, and feasibility with them equals
    feasibility without."""
    graph = _graph(stitched_problem(2, 60, 4.0))
    problem, m = graph.problem, graph.problem.n_conflicts
    rng = np.random.default_rng(2)
    start = Decoder(problem, graph.cliques).decode(
        rng.exponential(size=(1, problem.n_nodes)) + 1e-3, rng.random((1, m))
    )
    a_first, following = start.a_first[0], start.following[0].copy()
    counts = graph.cliques.following_counts(following[None])[0]
    flips = 0
    for _ in range(300):
        moves = m + rng.choice(m, size=8, replace=False)
        ok = graph.feasible(a_first, following, moves, counts)
        assert ok.tolist() == graph.feasible(a_first, following, moves).tolist()
        for move in moves[ok][:1]:
            following[move - m] ^= True
            graph.count_type_move(counts, move - m, bool(following[move - m]))
            flips += 1
    assert flips > 50
    assert counts.tolist() == graph.cliques.following_counts(following[None])[0].tolist()


@pytest.mark.parametrize("seed", range(6))
def test_counts_carried_to_other_types_equal_a_fresh_count(seed: int) -> None:
    """The searches carry clique counts from one answer to the next (``recount``): from
    any types to any others they equal a fresh count of the others."""
    graph = _graph(stitched_problem(seed, 40, 4.0))
    rng = np.random.default_rng(seed)
    before, after = rng.random((2, graph.problem.n_conflicts)) < 0.5  # (M,) each
    after[: graph.problem.n_conflicts // 2] = before[: graph.problem.n_conflicts // 2]
    counts = graph.cliques.following_counts(before[None])[0]
    carried = graph.recount(counts, before, after)
    assert carried.tolist() == graph.cliques.following_counts(after[None])[0].tolist()
    assert counts.tolist() == graph.cliques.following_counts(before[None])[0].tolist()  # kept
