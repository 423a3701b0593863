"""Move feasibility and backtracking enumeration, against the brute-force reference."""

from __future__ import annotations

import numpy as np
import pytest

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


def test_enumeration_resumes_where_it_stopped() -> None:
    graph = _graph(tiny_request(3))
    m = graph.problem.n_conflicts
    args = (np.arange(m), np.ones(m, dtype=bool), True)
    whole = _keys(graph.enumerate(*args).next(100_000))
    search = graph.enumerate(*args)
    pieces: list = []
    while not search.done:
        pieces += _keys(search.next(3))
    assert pieces == whole


def test_first_leaves_of_a_large_problem_are_valid_and_distinct() -> None:
    graph = _graph(stitched_problem(0, 120, 3.0))
    m = graph.problem.n_conflicts
    leaves = graph.enumerate(np.arange(m), np.ones(m, dtype=bool), True).next(200)
    assert leaves.n_samples == 200
    assert len(set(_keys(leaves))) == 200
    assert check(graph.problem, graph.cliques, leaves).ok.all()


@pytest.mark.parametrize("seed", range(6))
def test_move_feasibility_agrees_with_the_checker(seed: int) -> None:
    req = stitched_problem(seed, 15, 3.0) if seed % 2 else tiny_request(seed)
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
