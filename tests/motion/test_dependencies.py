"""Dependency plans: the staircase reduction, and plans that keep every pair out of its boxes.

The safety argument of the paths form is that, for a conflict decided "i first",
robot j can never be inside a box ``(x0, x1) x (y0, y1)`` of the pair: while i has
not reached ``x1``, j's limit is at most ``y0``. That is checked here directly on the
constraints, for every box, both directions and both types, on random fleets.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from service.core.problem import ProblemError
from service.geometry.graph import CoordinationGraph, GeometrySettings, build_graph
from service.geometry.paths import RobotPath
from service.motion import dependencies
from service.motion.dependencies import (
    IMPLIED_TOL_M,
    Decision,
    dependency_plan,
    staircase,
    without_implied,
)
from service.motion.trajectories import departure_times
from service.simulation.disturbances import Rate
from service.simulation.executor import DependencyPlan, Run, execute, on_clock
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


def _graph_and_decision(
    robots: list[dict[str, Any]], data: st.DataObject
) -> tuple[CoordinationGraph, Decision] | None:
    """The fleet's graph and a random decision of its conflicts (None: paths refused)."""
    try:
        graph = build_graph(paths_of(request(robots)), GeometrySettings())
    except ProblemError:
        return None
    flags = st.lists(st.booleans(), min_size=graph.n_conflicts, max_size=graph.n_conflicts)
    return graph, Decision(np.array(data.draw(flags), bool), np.array(data.draw(flags), bool))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(robots=fleets(max_robots=5, side=8.0), data=st.data())
def test_every_box_is_guarded_for_any_decision(
    robots: list[dict[str, Any]], data: st.DataObject
) -> None:
    drawn = _graph_and_decision(robots, data)
    if drawn is None:
        return
    graph, decision = drawn
    assert_boxes_guarded(graph, decision)
    assert_boxes_guarded(graph, decision.exclusive())


@settings(max_examples=20, deadline=None, derandomize=True)
@given(robots=fleets(max_robots=5, side=8.0), data=st.data(), parts=st.integers(2, 5))
def test_a_plan_made_in_parts_is_the_plan_made_whole(
    robots: list[dict[str, Any]], data: st.DataObject, parts: int
) -> None:
    """Conflicts planned in parts on threads give the same constraints in the same order
    (parts may be empty)."""
    drawn = _graph_and_decision(robots, data)
    if drawn is None:
        return
    graph, decision = drawn
    whole = dependency_plan(graph, decision)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(dependencies, "parts_for", lambda work, least: parts)
        cut = dependency_plan(graph, decision)
    for field in ("waiter", "wait_s", "waitee", "until_s"):
        np.testing.assert_array_equal(getattr(cut, field), getattr(whole, field), err_msg=field)


def test_no_conflict_gives_an_empty_plan() -> None:
    robots = [robot("a", [[0, 0], [1, 0]]), robot("b", [[0, 5], [1, 5]])]
    graph = build_graph(paths_of(request(robots)), GeometrySettings())
    empty = np.zeros(0, dtype=bool)
    assert dependency_plan(graph, Decision(empty, empty)).size == 0


def _plan(*rows: tuple[int, float, int, float]) -> DependencyPlan:
    """A plan of (waiter, wait_s, waitee, until_s) rows."""
    waiter, wait, waitee, until = (np.array(c) for c in zip(*rows, strict=True))
    return DependencyPlan(waiter.astype(np.int64), wait, waitee.astype(np.int64), until)


def _rows(plan: DependencyPlan) -> set[tuple[int, float, int, float]]:
    return set(
        zip(
            plan.waiter.tolist(),
            plan.wait_s.tolist(),
            plan.waitee.tolist(),
            plan.until_s.tolist(),
            strict=True,
        )
    )


def test_a_constraint_implied_through_a_third_robot_goes() -> None:
    """0 waits at 1 for 1 to reach 3; 1 waits at 2 for 2 to reach 5: when 0 passes 1,
    robot 1 is past 2, so 2 is at 5 or beyond, and "0 waits at 1.5 for 2 to reach 4"
    says nothing more."""
    chain = [(0, 1.0, 1, 3.0), (1, 2.0, 2, 5.0)]
    assert _rows(without_implied(_plan(*chain, (0, 1.5, 2, 4.0)), 3)) == set(chain)
    # Not implied: 2 must go farther, 0 waits earlier, or 1 is only at its wait point.
    for extra in [(0, 1.5, 2, 5.5), (0, 0.5, 2, 4.0)]:
        assert _rows(without_implied(_plan(*chain, extra), 3)) == {*chain, extra}
    at_wait = [(0, 1.0, 1, 2.0), (1, 2.0, 2, 5.0), (0, 1.5, 2, 4.0)]
    assert _rows(without_implied(_plan(*at_wait), 3)) == set(at_wait)
    nearly = [(0, 1.0, 1, 2.0 + IMPLIED_TOL_M / 2), (1, 2.0, 2, 5.0), (0, 1.5, 2, 4.0)]
    assert _rows(without_implied(_plan(*nearly), 3)) == set(nearly)


def _implied_by_brute_force(rows: list[tuple[int, float, int, float]]) -> set[int]:
    """Indices of the rows that two others imply through a third robot, by definition:
    robots in turn, fewest rows first (ties by index), a chain's second link among what
    its robot kept if that robot came before, else among all its rows."""
    robots = sorted({r[0] for r in rows} | {r[2] for r in rows})
    order = sorted(robots, key=lambda r: (sum(row[0] == r for row in rows), r))
    links = {r: [row for row in rows if row[0] == r] for r in robots}  # second links of r
    dropped: set[int] = set()
    for i in order:
        mine = [c for c, row in enumerate(rows) if row[0] == i]
        for c in mine:
            _, w, j, u = rows[c]
            if any(
                w1 <= w and k != j and w2 + IMPLIED_TOL_M < u1 and j2 == j and u2 >= u
                for _, w1, k, u1 in links[i]
                for _, w2, j2, u2 in links[k]
            ):
                dropped.add(c)
        links[i] = [rows[c] for c in mine if c not in dropped]
    return dropped


arc = st.one_of(st.integers(0, 8).map(lambda v: v / 2), st.floats(0.0, 4.0))  # ties, and not
constraint_rows = st.lists(
    st.tuples(st.integers(0, 3), arc, st.integers(0, 3), arc).filter(lambda r: r[0] != r[2]),
    min_size=1,
    max_size=14,
    unique=True,
)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(rows=constraint_rows)
# Where the order matters: robot 1 (two rows) comes before robot 0 (three) and drops its
# wait for 3 (implied through 2); robot 0's wait for 3 would be implied through robot 1's
# dropped row only, so it stays.
@example(
    rows=[
        (1, 1.0, 2, 3.0),
        (2, 2.0, 3, 5.0),
        (1, 1.5, 3, 4.0),
        (0, 1.0, 1, 2.0),
        (0, 1.5, 3, 4.0),
        (0, 0.5, 2, 0.1),
    ]
)
def test_exactly_the_constraints_implied_through_a_third_robot_go(
    rows: list[tuple[int, float, int, float]],
) -> None:
    """On any plan (arc lengths often on a grid, so that ties occur), the kept constraints are
    those not implied by two others as the definition reads them (any plan: this test is
    of the definition alone; that the run stays the same is the next test's)."""
    implied = _implied_by_brute_force(rows)
    kept = without_implied(_plan(*rows), 4)
    assert _rows(kept) == {r for c, r in enumerate(rows) if c not in implied}


def _same_run(a: Run, b: Run) -> bool:
    return (
        a.deadlocked == b.deadlocked
        and np.allclose(a.completion, b.completion, rtol=0, atol=1e-9, equal_nan=True)
        and all(
            np.allclose(np.interp(t, wa, ca), np.interp(t, wb, cb), rtol=0, atol=1e-9)
            for wa, ca, wb, cb in zip(a.wall, a.clock, b.wall, b.clock, strict=True)
            for t in [np.union1d(wa, wb)]
        )
    )


def _aisle(speeds: list[float], starts: list[float]) -> list[dict[str, Any]]:
    """Robots along one aisle, all one way, each from its own place and time."""
    return [
        robot(f"r{k}", [[1.0 * k, 0.0], [12.0 + 1.0 * k, 0.0]], speed=v, start_time=t)
        for k, (v, t) in enumerate(zip(speeds, starts, strict=True))
    ]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    robots=st.one_of(
        fleets(max_robots=6, side=6.0),
        st.integers(3, 6).flatmap(
            lambda n: st.builds(
                _aisle,
                st.lists(st.floats(0.3, 2.0), min_size=n, max_size=n),
                st.lists(st.floats(0.0, 4.0), min_size=n, max_size=n),
            )
        ),
    ),
    data=st.data(),
)
def test_a_plan_without_implied_constraints_runs_the_same(
    robots: list[dict[str, Any]], data: st.DataObject
) -> None:
    """Any decision whose plan never deadlocks (as no acyclic schedule's does) runs the
    same without the constraints its others imply, and obeys them all however late its
    robots run."""
    drawn = _graph_and_decision(robots, data)
    if drawn is None:
        return
    graph, decision = drawn
    plan = dependency_plan(graph, decision)
    run = execute(graph.paths, plan)
    if run.deadlocked:
        return
    kept = without_implied(plan, len(graph.paths))
    assert _rows(kept) <= _rows(plan)
    assert _same_run(execute(graph.paths, kept), run)
    stop = st.tuples(st.floats(0.0, 20.0), st.floats(0.1, 5.0), st.sampled_from([0.0, 0.3]))
    rates = [Rate.of(data.draw(st.lists(stop, max_size=2))) for _ in graph.paths]
    late = execute(graph.paths, kept, rates)
    if not late.deadlocked:
        assert_obeyed(graph.paths, late, plan)


def assert_obeyed(paths: list[RobotPath], run: Run, plan: DependencyPlan) -> None:
    """In ``run``, no robot left a wait point of ``plan`` before its waitee got there."""
    wait_clock = on_clock(paths, plan.waiter, plan.wait_s)  # (D,)
    until_clock = on_clock(paths, plan.waitee, plan.until_s)  # (D,)
    for d in range(plan.size):
        i, j = int(plan.waiter[d]), int(plan.waitee[d])
        left = departure_times(run.wall[i], run.clock[i], wait_clock[d : d + 1])[0]
        wall, clock = run.wall[j], run.clock[j]
        first = int(np.searchsorted(clock, until_clock[d]))  # first waypoint there or past
        reached = wall[0]
        if first > 0:  # between two waypoints: where j's clock crosses the point
            c0, c1, w0, w1 = clock[first - 1], clock[first], wall[first - 1], wall[first]
            reached = w0 + (until_clock[d] - c0) / (c1 - c0) * (w1 - w0)
        assert left >= reached - 1e-9, f"constraint {d} broken"


def test_an_aisle_waits_only_for_the_robot_in_front() -> None:
    """Six robots in a row, each following the one ahead: each keeps its constraints on
    the robot in front only, and the run is the same."""
    graph = build_graph(paths_of(request(_aisle([1.0] * 6, [0.0] * 6))), GeometrySettings())
    ahead = graph.node_robot[graph.conf_node[:, 1]] > graph.node_robot[graph.conf_node[:, 0]]
    plan = dependency_plan(graph, Decision(~ahead, np.ones(graph.n_conflicts, bool)))
    kept = without_implied(plan, len(graph.paths))
    assert set((kept.waitee - kept.waiter).tolist()) == {1}
    assert kept.size < plan.size
    assert _same_run(execute(graph.paths, kept), execute(graph.paths, plan))
