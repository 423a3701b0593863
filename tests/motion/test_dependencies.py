"""Dependency plans: the staircase reduction, and plans that keep every pair out of its boxes.

The safety argument of the paths form is that, for a conflict decided "i first",
robot j can never be inside a box ``(x0, x1) x (y0, y1)`` of the pair: while i has
not reached ``x1``, j's limit is at most ``y0``. That is checked here directly on the
constraints, for every box, both directions and both types, on random fleets.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

from service.core.problem import ProblemError
from service.geometry.graph import CoordinationGraph, GeometrySettings, build_graph
from service.motion.dependencies import Decision, dependency_plan, staircase
from service.simulation.executor import DependencyPlan
from tests.motion.worlds import fleets, paths_of, request, robot


def _limit(until: np.ndarray, wait: np.ndarray, u: float) -> float:
    """Where a waiter must stop while the waitee is at ``u``: the least wait whose
    until lies beyond u (inf when none)."""
    ahead = until > u
    return float(wait[ahead].min()) if ahead.any() else np.inf


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    pairs=st.lists(st.tuples(st.floats(0.0, 10.0), st.floats(0.0, 10.0)), min_size=1, max_size=12)
)
# Equal untils: (0, 1) is implied by (0, 0); it was kept (fixed: ties sort the least last).
@example(pairs=[(0.0, 0.0), (0.0, 1.0)])
def test_staircase_keeps_the_same_limits_with_fewest_steps(
    pairs: list[tuple[float, float]],
) -> None:
    until, wait = (np.array(c) for c in zip(*pairs, strict=True))
    u2, w2 = staircase(until, wait)
    assert np.all(np.diff(u2) > 0) and np.all(np.diff(w2) > 0), "one constraint per step"
    probes = np.concatenate([until, until - 1e-9, until + 1e-9, [-1.0, 11.0]])
    for u in probes.tolist():
        assert _limit(u2, w2, u) == _limit(until, wait, u)


def _constraints(
    graph: CoordinationGraph, plan: DependencyPlan, m: int, a_first: bool
) -> tuple[np.ndarray, np.ndarray]:
    """(until, wait) of conflict m's constraints: the second robot waits inside its node
    for the first to reach a point of its node (conflicts are node pairs, so that is m's)."""
    node_a, node_b = graph.conf_node[m]
    first, second = (node_a, node_b) if a_first else (node_b, node_a)
    (f0, f1), (s0, s1) = graph.node_span[first], graph.node_span[second]
    mine = (
        (plan.waiter == graph.node_robot[second])
        & (plan.waitee == graph.node_robot[first])
        & (plan.wait_s >= s0)
        & (plan.wait_s <= s1)
        & (plan.until_s >= f0)
        & (plan.until_s <= f1)
    )
    return plan.until_s[mine], plan.wait_s[mine]


def assert_boxes_guarded(graph: CoordinationGraph, decision: Decision) -> None:
    """For every box of every conflict, the second robot's limit keeps it out of the box
    until the first has left it; exclusive plans never wait beyond the union section."""
    plan = dependency_plan(graph, decision)
    b = graph.boxes
    for m in range(graph.n_conflicts):
        until, wait = _constraints(graph, plan, m, bool(decision.a_first[m]))
        assert until.size > 0, f"conflict {m} has no constraint"
        for k in range(graph.box_start[m], graph.box_start[m + 1]):
            if decision.a_first[m]:
                leave, enter = b.x1[k], b.y0[k]
            else:
                leave, enter = b.y1[k], b.x0[k]
            assert _limit(until, wait, leave - 1e-9) <= enter + 1e-12, f"box {k} unguarded"
        if not decision.following[m]:
            x0, x1, y0, y1 = graph.conf_span[m]
            lo, hi = (y0, x1) if decision.a_first[m] else (x0, y1)
            assert np.all(wait >= lo - 1e-12) and np.all(until <= hi + 1e-12)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(robots=fleets(max_robots=5, side=8.0), data=st.data())
def test_every_box_is_guarded_for_any_decision(
    robots: list[dict[str, Any]], data: st.DataObject
) -> None:
    try:
        graph = build_graph(paths_of(request(robots)), GeometrySettings())
    except ProblemError:
        return
    m = graph.n_conflicts
    flags = st.lists(st.booleans(), min_size=m, max_size=m)
    decision = Decision(np.array(data.draw(flags), bool), np.array(data.draw(flags), bool))
    assert_boxes_guarded(graph, decision)
    assert_boxes_guarded(graph, decision.exclusive())


def test_no_conflict_gives_an_empty_plan() -> None:
    robots = [robot("a", [[0, 0], [1, 0]]), robot("b", [[0, 5], [1, 5]])]
    graph = build_graph(paths_of(request(robots)), GeometrySettings())
    empty = np.zeros(0, dtype=bool)
    assert dependency_plan(graph, Decision(empty, empty)).size == 0
