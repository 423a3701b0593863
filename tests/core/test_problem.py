"""problem_from_request: the arrays of a hand example, and every cross-field rule."""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import service.core.problem as problem_module
from service.core.problem import DensityLimits, Problem, ProblemError, problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import stitched_problem
from tests.reference import tiny_request

# r0: n0 [0, 4], n1 [6, 9] (density 2), goal 12;  r1: m0 [1, 5] (density 3).
# c0: n0 (section [1, 3]) with m0 (default: the whole node [1, 5]);
# c1: m0 with n1, both default sections.
EXAMPLE: dict[str, Any] = {
    "robots": [
        {
            "id": "r0",
            "nodes": [
                {"id": "n0", "enter": 0.0, "exit": 4.0},
                {"id": "n1", "enter": 6.0, "exit": 9.0, "density": 2},
            ],
            "goal_time": 12.0,
        },
        {"id": "r1", "nodes": [{"id": "m0", "enter": 1.0, "exit": 5.0, "density": 3}]},
    ],
    "conflicts": [
        {"a": "n0", "b": "m0", "a_enter": 1.0, "a_exit": 3.0},
        {"a": "m0", "b": "n1"},
    ],
}


def _build(req: dict[str, Any]) -> Problem:
    return problem_from_request(ScheduleRequest.model_validate(req))


def test_hand_example_arrays() -> None:
    p = _build(EXAMPLE)
    assert p.robot_ids == ("r0", "r1")
    assert p.node_ids == ("n0", "n1", "m0")
    assert p.node_index == {"n0": 0, "n1": 1, "m0": 2}
    assert p.robot_start.tolist() == [0, 2, 3]
    assert p.node_robot.tolist() == [0, 0, 1]
    assert p.node_enter.tolist() == [0, 6, 1]
    assert p.node_exit.tolist() == [4, 9, 5]
    assert p.node_density.tolist() == [1, 2, 3]
    assert p.goal_time[0] == 12.0 and math.isnan(p.goal_time[1])
    assert p.conf_a.tolist() == [0, 2]
    assert p.conf_b.tolist() == [2, 1]
    # Default pair times are the node's own.
    assert p.pair_enter.tolist() == [[1, 1], [1, 6]]
    assert p.pair_exit.tolist() == [[3, 5], [5, 9]]
    # Time points: r0 = {0, 4, 6, 9} nodes + {1, 3} c0 section + {6, 9} c1 + goal 12;
    #              r1 = {1, 5} node, also both sections.
    #   index:      0  1  2  3  4  5   6 | 7  8
    assert p.tp_time.tolist() == [0, 1, 3, 4, 6, 9, 12, 1, 5]
    assert p.tp_start.tolist() == [0, 7, 9]
    assert p.tp_robot.tolist() == [0] * 7 + [1] * 2
    assert p.tp_pair_enter.tolist() == [[1, 7], [7, 4]]
    assert p.tp_pair_exit.tolist() == [[2, 8], [8, 5]]
    assert p.tp_node_enter.tolist() == [0, 4, 7]
    assert p.tp_node_exit.tolist() == [3, 5, 8]
    assert p.last_tp.tolist() == [6, 8]
    assert p.free_time().tolist() == [12, 5]
    # Events: the distinct pair-enter time points 1, 4 (r0) and 7 (r1).
    assert p.events.tolist() == [1, 4, 7]
    assert p.tp_event.tolist() == [3, 0, 0, 0, 1, 1, 1, 2, 2]  # 3 = E: before any event
    assert p.event_next.tolist() == [1, -1, -1]
    assert (p.n_robots, p.n_nodes, p.n_conflicts) == (2, 3, 2)


def test_goal_equal_to_last_exit_is_one_time_point() -> None:
    req = copy.deepcopy(EXAMPLE)
    req["robots"][0]["goal_time"] = 9.0
    p = _build(req)
    assert p.tp_time[: p.tp_start[1]].tolist() == [0, 1, 3, 4, 6, 9]


def test_no_conflicts() -> None:
    p = _build({"robots": EXAMPLE["robots"]})
    assert p.n_conflicts == 0
    assert p.pair_enter.shape == (0, 2) and p.tp_pair_enter.shape == (0, 2)
    assert p.events.size == 0
    assert p.tp_time.tolist() == [0, 4, 6, 9, 12, 1, 5]


Edit = Callable[[dict[str, Any]], None]


def _set(path: tuple[Any, ...], value: Any) -> Edit:
    def edit(req: dict[str, Any]) -> None:
        target = req
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return edit


def _append(key: str, value: Any) -> Edit:
    return lambda req: req.setdefault(key, []).append(value)


RULES: dict[str, tuple[Edit, tuple[Any, ...]]] = {
    "unknown node a": (_set(("conflicts", 0, "a"), "zz"), ("conflicts", 0, "a")),
    "unknown node b": (_set(("conflicts", 1, "b"), "zz"), ("conflicts", 1, "b")),
    "same-robot conflict": (_append("conflicts", {"a": "n0", "b": "n1"}), ("conflicts", 2)),
    "duplicate robot id": (_set(("robots", 1, "id"), "r0"), ("robots", 1, "id")),
    "duplicate node id": (
        _set(("robots", 1, "nodes", 0, "id"), "n0"),
        ("robots", 1, "nodes", 0, "id"),
    ),
    "duplicate conflict": (_append("conflicts", {"a": "n0", "b": "m0"}), ("conflicts", 2)),
    "duplicate conflict reversed": (_append("conflicts", {"a": "m0", "b": "n0"}), ("conflicts", 2)),
    "pair exit after node exit": (
        _set(("conflicts", 0, "a_exit"), 4.5),
        ("conflicts", 0, "a_exit"),
    ),
    "pair enter before node enter": (
        _set(("conflicts", 0, "b_enter"), 0.5),
        ("conflicts", 0, "b_enter"),
    ),
    "pair exit not after pair enter": (
        _set(("conflicts", 0, "a_exit"), 1.0),
        ("conflicts", 0, "a_exit"),
    ),
    "node exit not after enter": (
        _append("robots", {"id": "r2", "nodes": [{"id": "q0", "enter": 2.0, "exit": 1.0}]}),
        ("robots", 2, "nodes", 0, "exit"),
    ),
    "touching nodes": (
        _set(("robots", 0, "nodes", 1, "enter"), 4.0),
        ("robots", 0, "nodes", 1, "enter"),
    ),
    "overlapping nodes": (
        _set(("robots", 0, "nodes", 1, "enter"), 3.0),
        ("robots", 0, "nodes", 1, "enter"),
    ),
    "goal too early": (_set(("robots", 0, "goal_time"), 8.0), ("robots", 0, "goal_time")),
    "non-clique density limit": (
        _append("density_limits", {"nodes": ["n0", "m0", "n1"], "max_robots": 2}),
        ("density_limits", 0, "nodes"),
    ),
    "density limit with unknown node": (
        _append("density_limits", {"nodes": ["n0", "zz"], "max_robots": 2}),
        ("density_limits", 0, "nodes"),
    ),
    "density limit listing a node twice": (
        _append("density_limits", {"nodes": ["n0", "m0", "n0"], "max_robots": 2}),
        ("density_limits", 0, "nodes"),
    ),
}


@pytest.mark.parametrize("rule", list(RULES))
def test_cross_field_rule_names_the_field(rule: str) -> None:
    edit, loc = RULES[rule]
    req = copy.deepcopy(EXAMPLE)
    edit(req)
    with pytest.raises(ProblemError) as info:
        _build(req)
    assert [e.loc for e in info.value.errors] == [("body", *loc)]
    item = info.value.errors[0].as_dict()
    assert item["loc"] == ["body", *loc] and item["type"] == "value_error" and item["msg"]


def test_several_violations_are_reported_together() -> None:
    req = copy.deepcopy(EXAMPLE)
    req["conflicts"][0]["a_exit"] = 4.5
    req["conflicts"][1]["b_enter"] = 5.0
    req["robots"][0]["goal_time"] = 1.0  # reported only once conflicts are valid
    with pytest.raises(ProblemError) as info:
        _build(req)
    assert [e.loc for e in info.value.errors] == [
        ("body", "conflicts", 0, "a_exit"),
        ("body", "conflicts", 1, "b_enter"),
    ]


def test_valid_clique_density_limit_is_kept() -> None:
    req = copy.deepcopy(EXAMPLE)
    req["density_limits"] = [{"nodes": ["m0", "n0"], "max_robots": 1}]
    p = _build(req)
    assert len(p.density_limits) == 1
    assert p.density_limits[0].nodes.tolist() == [0, 2]  # sorted node indices
    assert p.density_limits[0].max_robots == 1


def test_faulty_density_limits_are_reported_in_order_and_the_others_kept() -> None:
    req = copy.deepcopy(EXAMPLE)
    req["density_limits"] = [
        {"nodes": ["m0", "n1"], "max_robots": 1},
        {"nodes": ["n0", "zz", "yy"], "max_robots": 2},
        {"nodes": ["m0", "n0"], "max_robots": 2},
        {"nodes": ["n1", "n1"], "max_robots": 1},
        {"nodes": ["n0", "n1"], "max_robots": 1},  # same robot: not in conflict
    ]
    with pytest.raises(ProblemError) as info:
        _build(req)
    assert [(e.loc[2], e.msg) for e in info.value.errors] == [
        (1, "unknown node id 'zz'"),
        (1, "unknown node id 'yy'"),
        (3, "a node is listed twice"),
        (4, "nodes are not a clique of the conflict graph: no conflict between 'n0' and 'n1'"),
    ]
    del req["density_limits"][1:2], req["density_limits"][2:]
    kept = _build(req).density_limits
    assert [(lim.nodes.tolist(), lim.max_robots) for lim in kept] == [([1, 2], 1), ([0, 2], 2)]


def test_times_are_exact_keys() -> None:
    # Times differing in the last bit stay distinct time points; equal ones merge.
    t = 1.0 + np.finfo(float).eps
    req = copy.deepcopy(EXAMPLE)
    req["conflicts"][1]["a_enter"] = t
    p = _build(req)
    assert p.tp_time[p.tp_start[1] : p.tp_start[2]].tolist() == [1.0, t, 5.0]
    assert p.tp_pair_enter.tolist() == [[1, 7], [8, 4]]


@pytest.mark.parametrize(
    "body",
    [tiny_request(seed) for seed in range(12)]
    + [stitched_problem(seed, 40, 3.0) for seed in range(3)]
    + [EXAMPLE],
)
def test_valid_conflicts_read_in_bulk_equal_the_walk(
    body: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The bulk reading of valid conflicts builds the problem the per-conflict walk does
    (the walk also checks faulty ones: every rule above goes through it)."""
    req = ScheduleRequest.model_validate(body)
    bulk = problem_from_request(req)
    monkeypatch.setattr(problem_module, "_valid_conflicts", lambda *args: None)
    walked = problem_from_request(req)
    for field in ("conf_a", "conf_b", "pair_enter", "pair_exit", "tp_pair_enter", "tp_time"):
        a, b = getattr(bulk, field), getattr(walked, field)
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), field
    assert bulk.pair_exit.shape[0] == len(req.conflicts)


@settings(max_examples=60, deadline=None)
@given(
    groups=st.lists(
        st.tuples(st.sets(st.integers(0, 30), min_size=2, max_size=5), st.integers(1, 4)),
        max_size=12,
    ),
    data=st.data(),
)
def test_density_limits_taken_keep_their_nodes_renumbered_and_sorted(
    groups: list[tuple[set[int], int]], data: st.DataObject
) -> None:
    """Limits in CSR arrays read back limit by limit; those taken keep their order, their
    budgets and their nodes under the new numbering (sorted, as the numbering increases)."""
    nodes = [sorted(g) for g, _ in groups]
    limits = DensityLimits(
        np.array([v for g in nodes for v in g], dtype=np.int64),
        np.concatenate([[0], np.cumsum([len(g) for g in nodes])]).astype(np.int64),
        np.array([m for _, m in groups], dtype=np.int64),
    )
    assert [(lim.nodes.tolist(), lim.max_robots) for lim in limits] == [
        (g, m) for g, (_, m) in zip(nodes, groups, strict=True)
    ]
    kept_nodes = np.array(data.draw(st.lists(st.booleans(), min_size=31, max_size=31)))
    renumber = np.where(kept_nodes, np.cumsum(kept_nodes) - 1, -1)  # (31,)
    keep = np.array([all(kept_nodes[v] for v in g) for g in nodes], dtype=bool)
    taken = limits.take(keep, renumber)
    assert [(lim.nodes.tolist(), lim.max_robots) for lim in taken] == [
        (renumber[g].tolist(), m) for g, (_, m), k in zip(nodes, groups, keep, strict=True) if k
    ]
    assert all(np.all(np.diff(lim.nodes) > 0) for lim in taken)


def test_density_limits_of_pairs_sort_each_pair() -> None:
    limits = DensityLimits.of_pairs(np.array([[3, 1], [0, 2]]), 1)
    assert [(lim.nodes.tolist(), lim.max_robots) for lim in limits] == [([1, 3], 1), ([0, 2], 1)]
    assert len(DensityLimits.of_pairs(np.zeros((0, 2), dtype=np.int64), 1)) == 0
    assert len(DensityLimits.empty()) == 0 and not DensityLimits.empty()
