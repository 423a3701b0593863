"""The decoder: any bids and scores give a valid assignment, and every valid one is reachable."""

from __future__ import annotations

import itertools
import warnings
from functools import cache
from graphlib import TopologicalSorter

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder, bids_from_ranks, following_gain
from service.core.evaluate import Evaluator
from service.core.problem import Problem, problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from tests.reference import density_groups, density_ok, is_acyclic, reference_problem, tiny_request

SEEDS = st.integers(min_value=0, max_value=400)
# Positive bids from subnormal to huge, with favourite values (and so ties) drawn often.
# Capped at 1e300: chains hold at most 4 nodes, so rank sums stay finite (see
# test_huge_bids_overflowing_ranks for what happens past that).
BIDS = st.one_of(
    st.floats(min_value=0.0, max_value=1e300, exclude_min=True),
    st.sampled_from([5e-324, 1e-300, 1e-9, 1.0, 2.0, 1e9, 1e300]),
)
# Any float at all, NaN and infinities included, with ties.
SCORES = st.one_of(st.floats(), st.sampled_from([0.0, 0.5, 1.0, -1.0]))
THRESHOLDS = st.one_of(st.none(), st.floats(allow_nan=False), st.just(0.5))


@cache
def _setup(seed: int, tiny: bool) -> tuple[Problem, Cliques, Decoder]:
    req = tiny_request(seed) if tiny else small_problem(seed)
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    cliques = find_cliques(problem)
    return problem, cliques, Decoder(problem, cliques)


def _topological_ranks(problem: Problem, a_first: np.ndarray) -> np.ndarray:
    """(V,) position + 1 of every node in a topological order of the node graph."""
    preds: dict[int, set[int]] = {v: set() for v in range(problem.n_nodes)}
    for v in range(1, problem.n_nodes):
        if problem.node_robot[v] == problem.node_robot[v - 1]:
            preds[v].add(v - 1)
    for c, a_wins in enumerate(a_first.tolist()):
        a, b = int(problem.conf_a[c]), int(problem.conf_b[c])
        first, second = (a, b) if a_wins else (b, a)
        preds[second].add(first)
    ranks = np.empty(problem.n_nodes)
    for position, v in enumerate(TopologicalSorter(preds).static_order()):
        ranks[v] = position + 1
    return ranks


@settings(max_examples=150, deadline=None)
@given(data=st.data(), seed=SEEDS, tiny=st.booleans(), samples=st.integers(1, 3))
def test_decode_is_always_valid(data: st.DataObject, seed: int, tiny: bool, samples: int) -> None:
    problem, cliques, decoder = _setup(seed, tiny)
    bids = np.array(
        data.draw(
            st.lists(BIDS, min_size=problem.n_nodes * samples, max_size=problem.n_nodes * samples)
        )
    )
    scores = np.array(
        data.draw(
            st.lists(
                SCORES,
                min_size=problem.n_conflicts * samples,
                max_size=problem.n_conflicts * samples,
            )
        )
    )
    threshold = data.draw(THRESHOLDS)
    bids = bids.reshape(samples, problem.n_nodes)
    scores = scores.reshape(samples, problem.n_conflicts)

    out = decoder.decode(bids, scores, threshold)

    assert out.a_first.shape == out.following.shape == (samples, problem.n_conflicts)
    result = check(problem, cliques, out)
    assert result.acyclic.all()
    assert result.density.all()
    # Only candidates are following-type: a real score above the threshold, never forbidden.
    candidate = ~np.isnan(scores) & ~cliques.forbidden()
    if threshold is not None:
        candidate &= scores > threshold
    assert not np.any(out.following & ~candidate)
    # Greedy is maximal: an unchosen candidate would overfill some clique.
    counts = cliques.following_counts(out.following)  # (S, Q)
    full = counts >= cliques.budget  # (S, Q)
    for s, c in zip(*np.nonzero(candidate & ~out.following), strict=True):
        holders = np.repeat(np.arange(cliques.budget.size), cliques.size)[cliques.edge == c]
        assert full[s, holders].any()


@settings(max_examples=100, deadline=None)
@given(seed=SEEDS, bits=st.lists(st.booleans(), min_size=14, max_size=14))
def test_every_acyclic_direction_is_decoded_from_its_topological_ranks(
    seed: int, bits: list[bool]
) -> None:
    problem, _, decoder = _setup(seed, False)
    a_first = np.array(bits[: problem.n_conflicts], dtype=bool)
    assume(is_acyclic(reference_problem(small_problem(seed)), a_first.tolist()))
    ranks = _topological_ranks(problem, a_first)
    bids = bids_from_ranks(problem, ranks)
    assert np.all(bids > 0)
    np.testing.assert_array_equal(decoder.ranks(bids)[0], ranks)
    out = decoder.decode(bids[None, :], np.zeros((1, problem.n_conflicts)))
    np.testing.assert_array_equal(out.a_first[0], a_first)


@pytest.mark.parametrize("seed", range(40))
def test_every_valid_assignment_of_a_tiny_problem_is_reachable(seed: int) -> None:
    """Exhaustively: all acyclic directions from bids, all feasible type choices from scores."""
    problem, cliques, decoder = _setup(seed, True)
    ref = reference_problem(tiny_request(seed))
    m = problem.n_conflicts
    choices = np.array(list(itertools.product((False, True), repeat=m)), dtype=bool).reshape(-1, m)

    acyclic = np.array([is_acyclic(ref, d.tolist()) for d in choices])
    assert acyclic.any()
    ranks = np.stack([_topological_ranks(problem, d) for d in choices[acyclic]])
    bids = bids_from_ranks(problem, ranks)  # (S, V)
    out = decoder.decode(bids, np.zeros((len(bids), m)))
    np.testing.assert_array_equal(out.a_first, choices[acyclic])

    groups = density_groups(ref)
    feasible = choices[[density_ok(groups, f.tolist()) for f in choices]]
    assert len(feasible) >= 1  # all exclusive
    scores = feasible.astype(np.float64)  # 1 following, 0 exclusive
    out = decoder.decode(np.ones((len(feasible), problem.n_nodes)), scores, threshold=0.5)
    np.testing.assert_array_equal(out.following, feasible)
    # ... and the infeasible ones are not (the decoder never exceeds a budget).
    assert check(problem, cliques, out).density.all()


def test_bids_from_ranks_batch() -> None:
    problem, _, decoder = _setup(3, False)
    ranks = np.cumsum(np.ones((2, problem.n_nodes)), axis=1) * np.array([[1.0], [3.0]])
    bids = bids_from_ranks(problem, ranks)
    first = problem.robot_start[:-1]
    np.testing.assert_array_equal(bids[:, first], ranks[:, first])
    np.testing.assert_array_equal(decoder.ranks(bids), ranks)


def test_ties_go_to_the_lower_node_index() -> None:
    problem, cliques, decoder = _setup(5, False)
    out = decoder.decode_ranks(np.zeros((1, problem.n_nodes)), np.zeros((1, problem.n_conflicts)))
    np.testing.assert_array_equal(out.a_first[0], problem.conf_a < problem.conf_b)
    assert check(problem, cliques, out).ok.all()


@pytest.mark.parametrize("bad", [0.0, -1.0, np.nan, -np.inf])
def test_non_positive_bids_are_rejected(bad: float) -> None:
    problem, _, decoder = _setup(1, False)
    bids = np.ones((1, problem.n_nodes))
    bids[0, -1] = bad
    with pytest.raises(ValueError, match="positive"):
        decoder.decode(bids, np.zeros((1, problem.n_conflicts)))


def test_infinite_bids_are_rejected() -> None:
    """The decoder says "bids must be positive and finite", but lets +inf through."""
    problem, _, decoder = _setup(1, False)
    bids = np.ones((1, problem.n_nodes))
    bids[0, -1] = np.inf
    with pytest.raises(ValueError, match="finite"):
        decoder.decode(bids, np.zeros((1, problem.n_conflicts)))


def test_huge_bids_overflowing_ranks() -> None:
    """Rank sums past the float range become +inf: ties broken by node index, still valid.

    numpy warns (RuntimeWarning: overflow in accumulate) on the way; the answer is valid.
    """
    problem, cliques, decoder = _setup(4, False)
    assert np.diff(problem.robot_start).max() >= 2
    bids = np.full((1, problem.n_nodes), 1.5e308)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        out = decoder.decode(bids, np.zeros((1, problem.n_conflicts)))
    assert check(problem, cliques, out).ok.all()


def test_decode_batch_shape_mismatch_raises() -> None:
    problem, _, decoder = _setup(1, False)
    with pytest.raises(ValueError):
        decoder.decode(np.ones((2, problem.n_nodes)), np.zeros((3, problem.n_conflicts)))


def test_assignments_take_and_single() -> None:
    batch = Assignments(np.eye(3, dtype=bool), np.zeros((3, 3), dtype=bool))
    assert batch.take(1).a_first.tolist() == [[False, True, False]]
    assert batch.take(np.array([0, 2])).n_samples == 2
    with pytest.raises(ValueError):
        Assignments(np.zeros(3, dtype=bool), np.zeros(3, dtype=bool))


def _hot_conflict(robots: int, nodes: int) -> Problem:
    """Conflict u-v inside robots x nodes maximal cliques {u, v, w}: every node w of the
    other robots conflicts with u and v (and not with its own robot's nodes)."""

    def node(nid: str, k: int) -> dict[str, object]:
        return {"id": nid, "enter": 2.0 * k, "exit": 2.0 * k + 1.0, "density": 2}

    ws = [[f"w{r}/{k}" for k in range(nodes)] for r in range(robots)]
    return problem_from_request(
        ScheduleRequest.model_validate(
            {
                "robots": [
                    {"id": "a", "nodes": [node("u", 0)]},
                    {"id": "b", "nodes": [node("v", 0)]},
                    *[
                        {"id": f"w{r}", "nodes": [node(w, k) for k, w in enumerate(ws[r])]}
                        for r in range(robots)
                    ],
                ],
                "conflicts": [
                    {"a": "u", "b": "v"},
                    *[{"a": x, "b": w} for row in ws for w in row for x in ("u", "v")],
                ],
            }
        )
    )


def test_a_conflict_in_thousands_of_cliques_costs_memory_in_proportion() -> None:
    """The decoder's clique lists and the checker's counts grow with the incidences, not
    with conflicts x the most cliques one conflict is in (a padded table: 144 MB here)."""
    import tracemalloc

    problem = _hot_conflict(30, 100)  # 3,000 cliques {u, v, w}: u-v is in all of them
    cliques = find_cliques(problem)
    assert cliques.budget.size == 3000 and cliques.binding().all()
    tracemalloc.start()
    decoder = Decoder(problem, cliques)
    out = decoder.decode_ranks(problem.node_enter[None], np.zeros((1, problem.n_conflicts)))
    ok = check(problem, cliques, out).ok
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert ok.tolist() == [True]
    assert peak < 8 * 1024 * 1024  # 9,000 incidences: well under a megabyte of lists
    # Density 2 allows 2 following conflicts per clique: u-v takes one in all of them.
    counts = cliques.following_counts(out.following)[0]
    assert counts.max() <= 2


def _greedy_types(problem: Problem, cliques: Cliques, scores: np.ndarray) -> np.ndarray:
    """Reference for Decoder.types, one sample, plainly: every conflict by descending
    score (ties: lower index; fixed following-type first), following-type when it may be
    (not in a zero-budget clique, type not fixed exclusive, a score) and every clique
    holding it has budget left."""
    m = problem.n_conflicts
    key = np.where(problem.fixed_type == 1, np.inf, scores)
    holding: list[list[int]] = [[] for _ in range(m)]
    for q in range(cliques.budget.size):
        for e in cliques.edge[cliques.start[q] : cliques.start[q + 1]]:
            holding[e].append(q)
    left = cliques.budget.copy()
    out = np.zeros(m, dtype=bool)
    for e in sorted(range(m), key=lambda e: (-key[e] if not np.isnan(key[e]) else 0.0, e)):
        if np.isnan(key[e]) or problem.fixed_type[e] == 0:
            continue
        if all(left[q] > 0 for q in holding[e]):
            out[e] = True
            for q in holding[e]:
                left[q] -= 1
    return out


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), density=st.sampled_from([2.0, 4.0]))
def test_types_fill_budgets_greedily_by_score(seed: int, density: float) -> None:
    """Decoder.types sorts only the conflicts that can be candidates: the same choice as
    the plain greedy over all of them, NaN scores never chosen."""
    problem = problem_from_request(
        ScheduleRequest.model_validate(stitched_problem(seed, 25, density))
    )
    cliques = find_cliques(problem)
    rng = np.random.default_rng(seed)
    scores = rng.random((3, problem.n_conflicts))
    scores[2, rng.random(problem.n_conflicts) < 0.3] = np.nan
    scores[1] = np.round(scores[1], 1)  # ties
    got = Decoder(problem, cliques).types(scores)
    for s in range(3):
        assert got[s].tolist() == _greedy_types(problem, cliques, scores[s]).tolist(), s


@settings(max_examples=60, deadline=None)
@given(
    times=st.lists(st.floats(0.0, 50.0), min_size=4, max_size=4),
    a_first=st.booleans(),
)
def test_following_gain_is_the_wait_following_spares(times: list[float], a_first: bool) -> None:
    """Two robots sharing one node (density 2): the evaluator's average completion with
    the conflict exclusive minus with it following, times two robots, is the gain."""
    (ea, xa), (eb, xb) = sorted(times[:2]), sorted(times[2:])
    req = {
        "robots": [
            {
                "id": r,
                "nodes": [{"id": f"{r}/0", "enter": e, "exit": x + 1.0, "density": 2}],
                "goal_time": 60.0,
            }
            for r, e, x in (("a", ea, xa), ("b", eb, xb))
        ],
        "conflicts": [{"a": "a/0", "b": "b/0"}],
    }
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    evaluator = Evaluator(problem)
    first = np.array([[a_first]])  # (1, 1)
    exclusive, following = (
        evaluator.evaluate(Assignments(first, np.array([[kind]]))).costs["avg_completion"][0]
        for kind in (False, True)
    )
    gain = following_gain(problem, first)
    assert gain.shape == (1, 1) and gain[0, 0] >= 0.0
    assert 2.0 * (exclusive - following) == pytest.approx(gain[0, 0], abs=1e-9)
