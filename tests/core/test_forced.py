"""Fixed directions (a conflict's ``first``): validation, checker, decoder and move searches.

Random fixed directions come from :func:`tests.reference.fix_directions` (read off a
random order agreeing with every path, so they never form a cycle); the
reference enumeration honours them, so "valid" below always includes them.
"""

from __future__ import annotations

import copy
import itertools
import warnings
from functools import cache
from graphlib import TopologicalSorter
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder, bids_from_ranks
from service.core.orientation import OrientationGraph
from service.core.problem import Problem, ProblemError, problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from tests.reference import (
    feasible_assignments,
    fix_directions,
    honours_fixed,
    is_acyclic,
    reference_problem,
    tiny_request,
    trap_request,
)

# r0: n0, n1;  r1: m0, m1;  r2: q0.  c0 n1 -- m0, c1 n0 -- m1, c2 n0 -- m0, c3 n0 -- q0.
TWO_ROBOTS: dict[str, Any] = {
    "robots": [
        {
            "id": rid,
            "nodes": [
                {"id": f"{prefix}{k}", "enter": 2.0 * k, "exit": 2.0 * k + 1.0}
                for k in range(count)
            ],
        }
        for rid, prefix, count in (("r0", "n", 2), ("r1", "m", 2), ("r2", "q", 1))
    ],
    "conflicts": [
        {"a": "n1", "b": "m0"},
        {"a": "n0", "b": "m1"},
        {"a": "n0", "b": "m0"},
        {"a": "n0", "b": "q0"},
    ],
}


def _build(req: dict[str, Any]) -> Problem:
    return problem_from_request(ScheduleRequest.model_validate(req))


def _with_first(req: dict[str, Any], **first: str) -> dict[str, Any]:
    """A copy of ``req`` with ``first`` set on conflicts ``c<k>``."""
    out = copy.deepcopy(req)
    for key, side in first.items():
        out["conflicts"][int(key[1:])]["first"] = side
    return out


@cache
def _setup(seed: int, tiny: bool) -> tuple[dict[str, Any], Problem, Cliques, Decoder]:
    req = fix_directions(tiny_request(seed) if tiny else small_problem(seed), seed)
    problem = _build(req)
    cliques = find_cliques(problem)
    return req, problem, cliques, Decoder(problem, cliques)


# --- the problem model --------------------------------------------------------------------


def test_forced_array_and_arcs() -> None:
    p = _build(_with_first(TWO_ROBOTS, c0="b", c2="a"))
    assert p.forced.dtype == np.int8
    assert p.forced.tolist() == [-1, 0, 1, 0]
    conflicts, first, second = p.forced_arcs
    assert conflicts.tolist() == [0, 2]
    assert [p.node_ids[v] for v in first] == ["m0", "n0"]
    assert [p.node_ids[v] for v in second] == ["n1", "m0"]
    assert p.has_forced


def test_no_fixed_direction_is_all_zero() -> None:
    p = _build(TWO_ROBOTS)
    assert p.forced.tolist() == [0, 0, 0, 0] and not p.has_forced
    assert p.forced_arcs[0].size == 0


@pytest.mark.parametrize(
    ("first", "on_cycle"),
    [
        ({"c0": "a", "c1": "b"}, [0, 1]),  # n0 -> n1 -> m0 -> m1 -> n0
        ({"c0": "a", "c2": "b"}, [0, 2]),  # n0 -> n1 -> m0 -> n0
        ({"c0": "a", "c1": "b", "c2": "a", "c3": "a"}, [0, 1, 2]),  # c3 to r2 is no part of it
        ({"c0": "a", "c1": "a"}, []),  # n0 -> n1 -> m0 -> m1 and n0 -> m1
        ({"c0": "b", "c1": "b", "c2": "b", "c3": "b"}, []),  # r1, then r0 after r2
    ],
)
def test_cycles_of_fixed_directions_are_named(first: dict[str, str], on_cycle: list[int]) -> None:
    """Rejected exactly when the reference finds a cycle in path order plus the fixed arcs,
    naming every fixed conflict on a cycle (and no other) with all of them in its message."""
    req = _with_first(TWO_ROBOTS, **first)
    fixed_only = {**req, "conflicts": [c for c in req["conflicts"] if "first" in c]}
    ref = reference_problem(fixed_only)
    assert is_acyclic(ref, [conf.first == "a" for conf in ref.conflicts]) == (not on_cycle)
    if not on_cycle:
        assert _build(req).has_forced
        return
    with pytest.raises(ProblemError) as info:
        _build(req)
    assert [e.loc for e in info.value.errors] == [
        ("body", "conflicts", k, "first") for k in on_cycle
    ]
    for k, error in zip(on_cycle, info.value.errors, strict=True):
        c = req["conflicts"][k]
        assert "fixed directions form a circular wait" in error.msg
        assert f"conflicts {on_cycle}" in error.msg
        assert f"'{c['a']}' and '{c['b']}', first '{c['first']}'" in error.msg


def test_three_robot_cycle_of_fixed_directions() -> None:
    """The trap's a -> b -> c -> a fixed: a cycle through three robots, all three named."""
    req = trap_request()
    for c in req["conflicts"]:
        c["first"] = "a"
    with pytest.raises(ProblemError, match="circular wait") as info:
        _build(req)
    assert sorted(e.loc[2] for e in info.value.errors) == [0, 1, 2]


# --- the checker --------------------------------------------------------------------------


def test_checker_reports_fixed_directions() -> None:
    p = _build(_with_first(TWO_ROBOTS, c0="b"))
    batch = Assignments(np.array([[False] * 4, [True] * 4]), np.zeros((2, 4), dtype=bool))
    result = check(p, find_cliques(p), batch)
    assert result.acyclic.tolist() == [True, True]
    assert result.forced.tolist() == [True, False]
    assert result.ok.tolist() == [True, False]


def test_checker_without_fixed_directions_always_passes_them() -> None:
    p = _build(TWO_ROBOTS)
    batch = Assignments(np.ones((2, 4), dtype=bool), np.zeros((2, 4), dtype=bool))
    assert check(p, find_cliques(p), batch).forced.tolist() == [True, True]


# --- the decoder --------------------------------------------------------------------------

BIDS = st.one_of(
    st.floats(min_value=0.0, max_value=1e300, exclude_min=True),
    st.sampled_from([5e-324, 1e-9, 1.0, 2.0, 1e9, 1e300]),
)


@settings(max_examples=120, deadline=None)
@given(data=st.data(), seed=st.integers(0, 400), tiny=st.booleans(), samples=st.integers(1, 3))
def test_any_bids_decode_to_valid_assignments_honouring_fixed_directions(
    data: st.DataObject, seed: int, tiny: bool, samples: int
) -> None:
    _, problem, cliques, decoder = _setup(seed, tiny)
    size = problem.n_nodes * samples
    bids = np.array(data.draw(st.lists(BIDS, min_size=size, max_size=size)))
    bids = bids.reshape(samples, problem.n_nodes)
    scores = np.random.default_rng(seed).random((samples, problem.n_conflicts))
    out = decoder.decode(bids, scores)
    result = check(problem, cliques, out)
    assert result.acyclic.all() and result.density.all() and result.forced.all()


@pytest.mark.parametrize("seed", range(20))
def test_repair_raises_ranks_along_fixed_arcs_only_as_needed(seed: int) -> None:
    _, problem, _, decoder = _setup(seed, False)
    rng = np.random.default_rng(seed)
    ranks = decoder.ranks(rng.random((4, problem.n_nodes)) + 1e-3)  # (4, V)
    out = decoder.repair(ranks)
    _, first, second = problem.forced_arcs
    assert np.all(out >= ranks)
    assert np.all(out[:, first] < out[:, second])
    same = problem.node_robot[1:] == problem.node_robot[:-1]
    assert np.all(np.diff(out, axis=1)[:, same] >= 0)  # still non-decreasing along paths
    assert np.all(decoder.repair(out) == out)  # ranks that honour them are kept


def test_repair_is_the_identity_without_fixed_directions() -> None:
    problem = _build(small_problem(3))
    decoder = Decoder(problem, find_cliques(problem))
    ranks = np.arange(2.0 * problem.n_nodes).reshape(2, -1)
    np.testing.assert_array_equal(decoder.repair(ranks), ranks)


@pytest.mark.parametrize("seed", range(30))
def test_every_valid_direction_of_a_tiny_problem_is_still_reachable(seed: int) -> None:
    """Topological ranks of an acyclic direction honouring the fixed ones decode to it."""
    req, problem, _, decoder = _setup(seed, True)
    ref = reference_problem(req)
    m = problem.n_conflicts
    choices = [
        d
        for d in itertools.product((False, True), repeat=m)
        if is_acyclic(ref, d) and honours_fixed(ref, d)
    ]
    assert choices
    ranks = np.stack([_topological_ranks(problem, np.array(d, dtype=bool)) for d in choices])
    out = decoder.decode(bids_from_ranks(problem, ranks), np.zeros((len(choices), m)))
    np.testing.assert_array_equal(out.a_first, np.array(choices, dtype=bool).reshape(-1, m))


def test_overflowing_ranks_still_honour_fixed_directions() -> None:
    for seed in range(10):
        _, problem, cliques, decoder = _setup(seed, False)
        bids = np.full((2, problem.n_nodes), 1.5e308)
        bids[1, ::2] = 1.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            out = decoder.decode(bids, np.zeros((2, problem.n_conflicts)))
        assert check(problem, cliques, out).ok.all()


def _topological_ranks(problem: Problem, a_first: np.ndarray) -> np.ndarray:
    """(V,) 1 + position of every node in a topological order of the node graph."""
    preds: dict[int, set[int]] = {v: set() for v in range(problem.n_nodes)}
    for v in np.flatnonzero(problem.node_robot[1:] == problem.node_robot[:-1]).tolist():
        preds[v + 1].add(v)
    first, second = Assignments.single(a_first, a_first).from_to(problem)
    for u, v in zip(first.tolist(), second.tolist(), strict=True):
        preds[v].add(u)
    ranks = np.empty(problem.n_nodes)
    for position, v in enumerate(TopologicalSorter(preds).static_order()):
        ranks[v] = position + 1
    return ranks


# --- move searches ------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(30))
def test_enumeration_is_exactly_the_valid_set_honouring_fixed_directions(seed: int) -> None:
    req, problem, cliques, _ = _setup(seed, True)
    graph = OrientationGraph(problem, cliques)
    m = problem.n_conflicts
    rng = np.random.default_rng(seed)
    search = graph.enumerate(rng.permutation(m), rng.random(m) < 0.5, follow_first=bool(seed % 2))
    leaves = search.next(100_000)
    assert search.done
    keys = [
        (tuple(leaves.a_first[s].tolist()), tuple(leaves.following[s].tolist()))
        for s in range(leaves.n_samples)
    ]
    assert len(set(keys)) == len(keys)
    assert set(keys) == {
        (c.a_first, c.following) for c in feasible_assignments(reference_problem(req))
    }


@pytest.mark.parametrize("seed", range(6))
def test_a_fixed_direction_is_never_a_feasible_move(seed: int) -> None:
    req = fix_directions(stitched_problem(seed, 15, 3.0) if seed % 2 else tiny_request(seed), seed)
    problem = _build(req)
    cliques = find_cliques(problem)
    graph = OrientationGraph(problem, cliques)
    m = problem.n_conflicts
    decoded = Decoder(problem, cliques).decode(
        np.random.default_rng(seed).random((3, problem.n_nodes)) + 1e-3, np.zeros((3, m))
    )
    conflict = np.arange(m)
    for s in range(decoded.n_samples):
        a_first, following = decoded.a_first[s], decoded.following[s]
        neighbours = Assignments(np.tile(a_first, (2 * m, 1)), np.tile(following, (2 * m, 1)))
        neighbours.a_first[conflict, conflict] ^= True
        neighbours.following[m + conflict, conflict] ^= True
        expected = check(problem, cliques, neighbours).ok
        assert graph.feasible(a_first, following, np.arange(2 * m)).tolist() == expected.tolist()
        assert not graph.feasible(a_first, following, problem.forced_arcs[0]).any()
