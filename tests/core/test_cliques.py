"""Density cliques and their budgets of following-type conflicts."""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core import cliques as module
from service.core.cliques import (
    CliqueBound,
    Cliques,
    TooManyCliques,
    _lexicographic_order,
    _maximal_cliques,
    budget_for,
    clique_budget,
    find_cliques,
)
from service.core.csr import csr, gather, select, transpose
from service.core.decompose import parts
from service.core.problem import Problem, problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import small_problem
from tests.reference import density_groups, reference_problem, side_by_side, tiny_request

DATA = Path(__file__).resolve().parents[1] / "data" / "conformance"
NO_LIMITS = np.array([-1, -1])
COMPLETE, OVER_INCIDENCES, OVER_CLIQUES = (
    module._COMPLETE,
    module._OVER_INCIDENCES,
    module._OVER_CLIQUES,
)


def _problem(req: dict[str, Any]) -> Problem:
    return problem_from_request(ScheduleRequest.model_validate(req))


def _groups(cl: Cliques) -> set[tuple[frozenset[int], int]]:
    """Each clique as (its conflicts, its budget)."""
    return {
        (frozenset(cl.edge[cl.start[q] : cl.start[q + 1]].tolist()), int(cl.budget[q]))
        for q in range(cl.budget.size)
    }


def _crowd(densities: list[int], pairs: list[tuple[int, int]], **extra: Any) -> dict[str, Any]:
    """One robot per density, each with one node [0, 10]; a conflict per pair."""
    return {
        "robots": [
            {"id": f"r{i}", "nodes": [{"id": f"v{i}", "enter": 0.0, "exit": 10.0, "density": d}]}
            for i, d in enumerate(densities)
        ],
        "conflicts": [{"a": f"v{i}", "b": f"v{j}"} for i, j in pairs],
        **extra,
    }


@pytest.mark.parametrize(("rho", "h"), [(1, 0), (2, 2), (3, 5), (4, 9)])
def test_budget(rho: int, h: int) -> None:
    # h = rho (rho + 1) / 2 - 1: 1 -> 0, 2 -> 3 - 1 = 2, 3 -> 6 - 1 = 5, 4 -> 10 - 1 = 9.
    assert budget_for(rho) == h


def test_triangle_is_one_clique_with_min_density() -> None:
    cl = find_cliques(_problem(_crowd([3, 2, 3], [(0, 1), (1, 2), (0, 2)])))
    # One maximal clique {v0, v1, v2} holding all three conflicts; rho = min(3, 2, 3) = 2.
    assert _groups(cl) == {(frozenset({0, 1, 2}), 2)}
    assert cl.size.tolist() == [3]
    assert cl.binding().tolist() == [True]  # 0 < 2 < 3
    assert cl.forbidden().tolist() == [False] * 3
    following = np.array([[True, True, False], [True, True, True]])
    assert cl.following_counts(following).tolist() == [[2], [3]]


def test_triangle_with_density_one_forbids_following() -> None:
    cl = find_cliques(_problem(_crowd([3, 1, 3], [(0, 1), (1, 2), (0, 2)])))
    assert _groups(cl) == {(frozenset({0, 1, 2}), 0)}
    assert cl.forbidden().tolist() == [True] * 3
    assert cl.binding().tolist() == [False]


def test_path_is_two_cliques() -> None:
    # v0 - v1 - v2 without v0 - v2: maximal cliques {v0, v1} and {v1, v2}; the first,
    # budget h(2) = 2 over one conflict, can never bind and is not listed.
    cl = find_cliques(_problem(_crowd([2, 3, 1], [(0, 1), (1, 2)])))
    assert _groups(cl) == {(frozenset({1}), 0)}
    assert cl.forbidden().tolist() == [False, True]
    assert not cl.binding().any()  # budget 0 is "forbidden", not binding


def test_four_clique() -> None:
    pairs = [(i, j) for i in range(4) for j in range(i + 1, 4)]
    cl = find_cliques(_problem(_crowd([3, 3, 3, 3], pairs)))
    assert _groups(cl) == {(frozenset(range(6)), 5)}  # 6 conflicts, h(3) = 5: binding
    assert cl.binding().tolist() == [True]


def test_explicit_limits_add_cliques() -> None:
    limits = [
        {"nodes": ["v0", "v1", "v2"], "max_robots": 1},  # h(1) = 0 over the whole triangle
        {"nodes": ["v2", "v0"], "max_robots": 2},  # h(2) = 2 over conflict 2 alone
    ]
    req = _crowd([3, 3, 3], [(0, 1), (1, 2), (0, 2)], density_limits=limits)
    cl = find_cliques(_problem(req))
    assert _groups(cl) == {  # not the maximal clique: rho = 3 members, h(3) = 5 >= 3
        (frozenset({0, 1, 2}), 0),  # first limit
        (frozenset({2}), 2),  # second limit
    }
    assert cl.forbidden().tolist() == [True] * 3


def test_no_conflicts_no_cliques() -> None:
    cl = find_cliques(_problem({"robots": _crowd([2, 2], [])["robots"]}))
    assert cl.budget.size == 0
    assert cl.following_counts(np.zeros((3, 0), dtype=bool)).shape == (3, 0)
    assert cl.forbidden().shape == (0,)


@pytest.mark.parametrize("seed", range(30))
def test_cliques_equal_brute_force(seed: int) -> None:
    req = tiny_request(seed) if seed % 2 else small_problem(seed)
    cl = find_cliques(_problem(req))
    # Every incidence once per clique, grouped by clique.
    assert cl.start[0] == 0 and cl.start[-1] == cl.edge.size
    assert np.all(cl.size >= 1)
    reference = set(density_groups(reference_problem(req)))
    ours = _groups(cl)
    # The groups whose budget is below their conflicts (the only ones that constrain) are
    # the contract's; a maximal clique that cannot bind may be left out.
    assert _constraining(ours) == _constraining(reference) and ours <= reference


def _constraining(groups: set[tuple[frozenset[int], int]]) -> set[tuple[frozenset[int], int]]:
    return {(conflicts, budget) for conflicts, budget in groups if budget < len(conflicts)}


@st.composite
def graphs(draw: st.DrawFn) -> tuple[int, list[tuple[int, int]]]:
    """A random simple graph: n vertices, each pair an edge with probability p."""
    n = draw(st.integers(2, 40))
    p = draw(st.sampled_from([0.05, 0.15, 0.3, 0.5]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    return n, [(i, j) for i in range(n) for j in range(i + 1, n) if rng.random() < p]


def _csr(n: int, edges: list[tuple[int, int]]) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([e[k] for k in (0, 1) for e in edges], dtype=np.int64)
    b = np.array([e[1 - k] for k in (0, 1) for e in edges], dtype=np.int64)
    order = np.lexsort((b, a))
    return np.searchsorted(a[order], np.arange(n + 1)), b[order]


@settings(max_examples=150, deadline=None, derandomize=True)
@given(graph=graphs(), dense=st.lists(st.integers(1, 6), min_size=40, max_size=40))
def test_maximal_cliques_equal_networkx(
    graph: tuple[int, list[tuple[int, int]]], dense: list[int]
) -> None:
    """Those of more members than their least density; with densities 1, all of them."""
    n, edges = graph
    for density in (np.ones(n, dtype=np.int64), np.array(dense[:n], dtype=np.int64)):
        members, ends, status = _maximal_cliques(*_csr(n, edges), density, NO_LIMITS)
        flat, bounds = members.tolist(), [0, *ends.tolist()]
        ours = [frozenset(flat[lo:hi]) for lo, hi in zip(bounds[:-1], bounds[1:], strict=True)]
        every = nx.find_cliques(nx.Graph(edges)) if edges else []
        reference = {frozenset(c) for c in every if len(c) > min(density[c])}
        assert status == COMPLETE and len(ours) == len(set(ours)) and set(ours) == reference


@settings(max_examples=40, deadline=None, derandomize=True)
@given(graph=graphs())
def test_the_bounds_stop_exactly_above_the_cliques_pairs_and_count(
    graph: tuple[int, list[tuple[int, int]]],
) -> None:
    n, edges = graph
    csr = _csr(n, edges)
    cliques = list(nx.find_cliques(nx.Graph(edges))) if edges else []
    pairs = sum(len(c) * (len(c) - 1) // 2 for c in cliques)

    def status(incidences: int, count: int) -> int:
        ones = np.ones(n, dtype=np.int64)
        return int(_maximal_cliques(*csr, ones, np.array([incidences, count]))[2])

    assert status(pairs, len(cliques)) == COMPLETE
    if cliques:
        assert status(pairs - 1, -1) == OVER_INCIDENCES
        assert status(-1, len(cliques) - 1) == OVER_CLIQUES


@settings(max_examples=100, deadline=None, derandomize=True)
@given(segments=st.lists(st.lists(st.integers(0, 4), max_size=5), max_size=60))
def test_segments_are_ordered_as_python_orders_lists(segments: list[list[int]]) -> None:
    values = np.array([v for seg in segments for v in seg], dtype=np.int64)
    bounds = np.cumsum([0, *map(len, segments)]).astype(np.int64)
    order = _lexicographic_order(values, bounds)
    assert order.tolist() == sorted(range(len(segments)), key=lambda q: segments[q])


@settings(max_examples=100, deadline=None, derandomize=True)
@given(
    segments=st.lists(st.lists(st.integers(0, 9), max_size=6), max_size=30),
    presorted=st.lists(st.booleans(), min_size=30, max_size=30),
)
def test_sort_segments_sorts_each_segment_in_place(
    segments: list[list[int]], presorted: list[bool]
) -> None:
    segments = [
        sorted(seg) if keep else seg for seg, keep in zip(segments, presorted, strict=False)
    ]
    values = np.array([v for seg in segments for v in seg], dtype=np.int64)
    bounds = np.cumsum([0, *map(len, segments)]).astype(np.int64)
    module._sort_segments(values, bounds)
    assert values.tolist() == [v for seg in segments for v in sorted(seg)]


def test_find_cliques_lists_cliques_and_their_conflicts_in_canonical_order() -> None:
    problem = _problem(small_problem(3))
    cl = find_cliques(problem)
    inside = [cl.edge[lo:hi] for lo, hi in zip(cl.start[:-1], cl.start[1:], strict=True)]
    groups = [
        sorted(set(problem.conf_a[q].tolist()) | set(problem.conf_b[q].tolist())) for q in inside
    ]
    assert not problem.density_limits and len(groups) > 3 and groups == sorted(groups)
    assert all(np.all(np.diff(q) > 0) for q in inside)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(keys=st.lists(st.integers(0, 6), max_size=80))
def test_csr_groups_values_by_key_stably(keys: list[int]) -> None:
    key = np.array(keys, dtype=np.int64)
    start, grouped = csr(key, np.arange(key.size) * 10, 7)
    counts = np.bincount(key, minlength=7)
    assert start.tolist() == np.concatenate([[0], np.cumsum(counts)]).tolist()
    assert grouped.tolist() == (np.argsort(key, kind="stable") * 10).tolist()


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    keys=st.lists(st.integers(0, 6), max_size=80),
    rows=st.lists(st.integers(0, 6), max_size=10),
)
def test_gather_reads_the_rows_of_the_keys_asked_for(keys: list[int], rows: list[int]) -> None:
    key = np.array(keys, dtype=np.int64)
    start, grouped = csr(key, np.arange(key.size) * 10, 7)
    values, owner = gather(start, grouped, np.array(rows, dtype=np.int64))
    expected = [(v, r) for r in rows for v in grouped[start[r] : start[r + 1]].tolist()]
    assert list(zip(values.tolist(), owner.tolist(), strict=True)) == expected


rows_of_values = st.lists(st.lists(st.integers(0, 6), max_size=8), max_size=12)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(rows=rows_of_values)
def test_transpose_lists_the_rows_of_each_value_in_row_order(rows: list[list[int]]) -> None:
    start = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int64)
    values = np.array([v for r in rows for v in r], dtype=np.int64)
    by_value, row_of = transpose(start, values, 7)
    expected = [[i for i, r in enumerate(rows) for v in r if v == value] for value in range(7)]
    assert [row_of[by_value[v] : by_value[v + 1]].tolist() for v in range(7)] == expected


@settings(max_examples=60, deadline=None, derandomize=True)
@given(rows=rows_of_values, keep=st.lists(st.booleans(), min_size=7, max_size=7))
def test_select_keeps_the_kept_values_of_each_row_in_order(
    rows: list[list[int]], keep: list[bool]
) -> None:
    start = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int64)
    values = np.array([v for r in rows for v in r], dtype=np.int64)
    kept_start, kept = select(start, values, np.array(keep))
    expected = [[v for v in r if keep[v]] for r in rows]
    assert [kept[kept_start[i] : kept_start[i + 1]].tolist() for i in range(len(rows))] == expected
    assert kept_start[-1] == kept.size


def test_conflict_cliques_are_the_cliques_holding_each_conflict() -> None:
    mixed = 0  # problems with binding and zero-budget cliques both
    for seed in range(36):
        cliques = find_cliques(_problem(tiny_request(seed)))
        binding = cliques.binding()
        mixed += bool(binding.any() and not binding.all())
        start, held = cliques.by_conflict
        b_start, b_held = cliques.binding_by_conflict
        inside = [set(cliques.edge[lo:hi].tolist()) for lo, hi in pairwise(cliques.start)]
        for c in range(cliques.n_conflicts):
            expected = [q for q, conflicts in enumerate(inside) if c in conflicts]
            assert held[start[c] : start[c + 1]].tolist() == expected
            assert b_held[b_start[c] : b_start[c + 1]].tolist() == [
                q for q in expected if binding[q]
            ]
    assert mixed >= 3


def test_find_cliques_names_the_bound_it_exceeds() -> None:
    # Complete tripartite, 3 nodes per robot: 27 maximal cliques of 3 conflicts each.
    problem = _problem(
        {
            "robots": [
                {
                    "id": f"r{i}",
                    "nodes": [
                        {"id": f"r{i}/{k}", "enter": 3.0 * k, "exit": 3.0 * k + 1, "density": 2}
                        for k in range(3)
                    ],
                }
                for i in range(3)
            ],
            "conflicts": [
                {"a": f"r{i}/{a}", "b": f"r{j}/{b}"}
                for i in range(3)
                for j in range(i + 1, 3)
                for a in range(3)
                for b in range(3)
            ],
        }
    )
    with clique_budget(CliqueBound(cliques=27, incidences=81)):
        assert find_cliques(problem).budget.size == 27
    with clique_budget(CliqueBound(cliques=26)), pytest.raises(TooManyCliques) as many:
        find_cliques(problem)
    assert many.value.setting == "max_cliques"
    assert "more than 26 maximal cliques (max_cliques)" in str(many.value)
    with clique_budget(CliqueBound(incidences=80)), pytest.raises(TooManyCliques) as held:
        find_cliques(problem)
    assert held.value.setting == "max_clique_incidences"
    assert "hold more than 80 conflicts in all (max_clique_incidences)" in str(held.value)
    assert find_cliques(problem).budget.size == 27  # unbounded outside the context


def _split_matches_each_part(problem: Problem) -> int:
    """Asserts that the whole problem's cliques split by component equal those found on each
    component alone; the number of components."""
    pieces = parts(problem)
    label = np.empty(problem.n_conflicts, dtype=np.int64)
    for k, piece in enumerate(pieces):
        label[piece.conflicts] = k
    for piece, got in zip(pieces, find_cliques(problem).split(label, len(pieces)), strict=True):
        alone = find_cliques(piece.problem)
        assert got.n_conflicts == alone.n_conflicts == piece.problem.n_conflicts
        for name in ("budget", "edge", "start"):
            assert np.array_equal(getattr(got, name), getattr(alone, name)), name
    return len(pieces)


@pytest.mark.parametrize("seed", range(30))
def test_cliques_split_by_component_equal_each_component_s_own(seed: int) -> None:
    req = side_by_side(seed)
    assert req is not None
    assert _split_matches_each_part(_problem(req)) >= 2


@pytest.mark.parametrize("name", ["wh_100", "wh_50"])
def test_cliques_split_on_warehouses_of_several_components(name: str) -> None:
    lines = (DATA / f"{name}.jsonl").read_text().splitlines()
    counts = [_split_matches_each_part(_problem(json.loads(line)["request"])) for line in lines]
    assert max(counts) >= 2


def test_cliques_split_into_parts_without_cliques() -> None:
    whole = Cliques(np.array([0]), np.array([0, 2]), np.array([0, 2]), 4)  # one clique
    first, second = whole.split(np.array([0, 1, 0, 1]), 2)
    assert np.array_equal(first.edge, [0, 1]) and first.n_conflicts == 2
    assert second.size.size == 0 and second.n_conflicts == 2 and np.array_equal(second.start, [0])
