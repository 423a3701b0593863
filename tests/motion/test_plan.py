"""The paths form end to end: every answer of every solver executes without collision.

The acceptance property of issue 10 is checked from the wire answer alone
(:func:`tests.motion.worlds.assert_motion_valid`: the sampled reference clearance,
start, end, order along the path, speed), on random fleets for several solvers and
on hand-made fleets for each situation the issue names. On all-exclusive plans the
executed completions must equal what the dispatcher's evaluator computes for the
same assignment of the graph (executor and evaluator agree).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from service.core.path_schemas import PathsRequest, PathsScheduleResponse
from service.core.problem import ProblemError
from service.geometry.graph import GeometrySettings, build_graph
from service.geometry.paths import RobotPath
from service.motion.dependencies import Decision, dependency_plan
from service.motion.plan import _decided
from service.motion.replan import decision
from service.motion.trajectories import trajectories
from service.simulation.clearance import check_clearance
from service.simulation.disturbances import Rate
from service.simulation.executor import Run, execute
from service.solvers.dispatch import DispatchPolicy, dispatch, dispatch_problem
from tests.motion.reference_clearance import position, reference_clearance
from tests.motion.scenarios import SCENARIOS, Fleet
from tests.motion.worlds import (
    OVERLAP_TOL,
    assert_motion_valid,
    evaluated,
    fleets,
    graph_of,
    paths_of,
    plan,
    request,
    robot,
    wire_trajectories,
)

PROPERTY_SOLVERS = ["exact", "fcfs", "tabu", "random", "bbts", "cmaes"]


def _completions(out: PathsScheduleResponse) -> dict[str, float]:
    return {s.robot: s.completion for s in out.schedule}


def _assert_parked_refusal_justified(req: PathsRequest, err: ProblemError) -> None:
    """The refusal names at least two robots, each parked within reach of another's route."""
    named = [r for r in req.robots if f"'{r.id}'" in str(err)]
    assert len(named) >= 2, str(err)
    margin = GeometrySettings().margin
    paths = {p.id: p for p in paths_of(req)}
    for r in named:
        start = paths[r.id].points[0]
        reach = [
            _distance_to_path(start, paths[o.id]) < r.radius + o.radius + margin + 1e-9
            for o in named
            if o.id != r.id
        ]
        assert any(reach), f"{r.id} is named but parked in nobody's way: {err}"


def _distance_to_path(q: np.ndarray, path: RobotPath) -> float:
    """Least distance from point q to a polyline."""
    p0, p1 = path.points[:-1], path.points[1:]
    d = p1 - p0
    f = np.clip(np.einsum("nd,nd->n", q - p0, d) / np.einsum("nd,nd->n", d, d), 0.0, 1.0)
    return float(np.linalg.norm(p0 + f[:, None] * d - q, axis=1).min())


def _assert_exclusive_matches(out: PathsScheduleResponse, *, equal: bool) -> None:
    """All-exclusive plan against the evaluator's completions of the same assignment.

    Never later: the executor waits for what the evaluator waits for, or less (a robot
    is released when the other *reaches* its point, and a conflict whose routes meet
    twice waits at each meeting). ``equal``: exactly what the evaluator says (one
    meeting per conflict), and so are the costs when no robot is isolated.
    """
    assert all(a["type"] == "exclusive" for a in out.assignment)
    expected, costs = evaluated(out)
    got = _completions(out)
    for rid, value in expected.items():
        assert got[rid] <= value + 1e-6, rid
        if equal:
            assert got[rid] == pytest.approx(value, abs=1e-6), rid
    if equal and len(expected) == len(got):  # no isolated robots: the costs are the graph's
        assert out.costs.model_dump() == pytest.approx(costs, abs=1e-6)


# ---- the acceptance property on random fleets ------------------------------------------


@pytest.mark.parametrize("solver", PROPERTY_SOLVERS)
@settings(
    max_examples=15,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.large_base_example],
)
@given(
    robots=fleets(side=12.0),
    time_limit=st.sampled_from([0.2, 0.3, 0.5]),
    seed=st.integers(0, 99),
)
def test_every_answer_moves_without_collision(
    solver: str, robots: Fleet, time_limit: float, seed: int
) -> None:
    req = request(robots, solver=solver, time_limit_s=time_limit, seed=seed)
    try:
        out = plan(req)
    except ProblemError as err:
        event("refused: robots parked in each other's way")
        _assert_parked_refusal_justified(req, err)
        return
    event(f"planned, following: {any(a['type'] == 'following' for a in out.assignment)}")
    assert_motion_valid(req, out)
    if out.graph is not None and all(a["type"] == "exclusive" for a in out.assignment):
        _assert_exclusive_matches(out, equal=False)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(robots=fleets(side=10.0), solver=st.sampled_from(["fcfs", "tabu", "exact"]))
def test_the_checked_answer_decides_as_its_rendered_response(robots: Fleet, solver: str) -> None:
    """A paths-form answer reads the dispatcher's checked answer without rendering it: the
    same directions and types as the graph-form response it would have rendered."""
    req = request(robots, solver=solver, time_limit_s=0.2)
    try:
        graph = build_graph(paths_of(req), GeometrySettings())
    except ProblemError:
        return
    problem = graph.problem()
    if problem is None:
        return
    checked = dispatch_problem(problem, req, DispatchPolicy())
    fast, rendered = _decided(checked), decision(graph, checked.response())
    assert np.array_equal(fast.a_first, rendered.a_first)
    assert np.array_equal(fast.following, rendered.following)


def _execute(req: PathsRequest, a_first: np.ndarray, following: np.ndarray) -> tuple[Run, list]:
    """Execute a decision of the request's graph directly (no solver): run, trajectories."""
    graph = build_graph(paths_of(req), GeometrySettings())
    run = execute(graph.paths, dependency_plan(graph, Decision(a_first, following)))
    return run, trajectories(graph.paths, run)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(robots=fleets(max_robots=6, side=10.0), seed=st.integers(0, 999), data=st.data())
def test_any_acyclic_directions_with_any_types_execute_safely(
    robots: Fleet, seed: int, data: st.DataObject
) -> None:
    """Following is a staircase over the boxes, safe whatever the geometry: random valid
    directions (the random solver's) with random types, density rules ignored, never
    deadlock and never overlap."""
    req = request(robots, solver="random", time_limit_s=0.2, seed=seed)
    try:
        graph = build_graph(paths_of(req), GeometrySettings())
    except ProblemError:
        return
    wire = graph.to_request(req)
    if wire is None:
        return
    answer = dispatch(wire, DispatchPolicy())
    ids = graph.node_ids()
    a_first = np.array(
        [
            ids[a] == out["from"]
            for out, a in zip(answer.assignment, graph.conf_node[:, 0], strict=True)
        ]
    )
    following = np.array(
        data.draw(st.lists(st.booleans(), min_size=a_first.size, max_size=a_first.size)), dtype=bool
    )
    run, trajs = _execute(req, a_first, following)
    assert run.deadlocked == ()
    assert not reference_clearance(trajs).overlapping(-OVERLAP_TOL)


# ---- the situations of issue 10 ----------------------------------------------------------


@pytest.mark.parametrize("solver", ["exact", "fcfs"])
@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_scenario_moves_without_collision(name: str, solver: str) -> None:
    req = request(SCENARIOS[name](), solver=solver)
    out = plan(req)
    assert_motion_valid(req, out)
    if all(a["type"] == "exclusive" for a in out.assignment):
        _assert_exclusive_matches(out, equal=True)


def _shifted(fleet: Fleet, offset: float) -> Fleet:
    """The fleet with every planned time later by ``offset`` seconds."""
    out = []
    for r in fleet:
        r = dict(r)
        if "times" in r:
            r["times"] = [t + offset for t in r["times"]]
        else:
            r["start_time"] = r.get("start_time", 0.0) + offset
        out.append(r)
    return out


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_scenario_far_from_time_zero(name: str) -> None:
    """Times of order 1e6 s (a fleet's clock since its start): rounding stays far below
    the margin, and exclusive plans still equal the evaluator."""
    req = request(_shifted(SCENARIOS[name](), 1e6), solver="fcfs")
    out = plan(req)
    assert_motion_valid(req, out)
    if all(a["type"] == "exclusive" for a in out.assignment):
        _assert_exclusive_matches(out, equal=True)


def _xs(req: PathsRequest, out: PathsScheduleResponse, times: np.ndarray) -> np.ndarray:
    """(R, T) x coordinate of every robot at ``times`` (NaN where it is not present)."""
    rows = []
    for tr in wire_trajectories(req, out):
        x = position(tr, times)[:, 0]
        rows.append(np.where((times >= tr.t[0]) & (times <= tr.t[-1]), x, np.nan))
    return np.array(rows)


def test_a_faster_follower_stays_behind() -> None:
    req = request(SCENARIOS["faster_follower"]())
    out = plan(req)
    assert [a["type"] for a in out.assignment] == ["following"]
    done = _completions(out)
    assert done["lead"] == 40.0  # the leader is never held up
    assert done["fast"] > done["lead"]  # the follower cannot pass it
    times = np.arange(0.0, done["fast"], 0.01)
    lead, fast = _xs(req, out, times)
    both = ~np.isnan(lead) & ~np.isnan(fast)
    assert np.all(lead[both] - fast[both] >= 0.8 - 1e-6)


def test_a_follower_stops_behind_a_leader_stopped_by_a_crossing_robot() -> None:
    """Force the corridor pair to follow (the solver would not, density rules): while
    'cross' is parked across the corridor, 'lead' stops and 'follow' stops behind it."""
    req = request(SCENARIOS["leader_stopped"]())
    graph = build_graph(paths_of(req), GeometrySettings())
    pairs = [tuple(graph.node_robot[n].tolist()) for n in graph.conf_node]
    assert sorted(pairs) == [(0, 1), (0, 2), (1, 2)]
    a_first = np.array([p != (0, 2) and p != (1, 2) for p in pairs])  # cross first, then lead
    following = np.array([p == (0, 1) for p in pairs])
    run, trajs = _execute(req, a_first, following)
    assert run.deadlocked == ()
    assert not reference_clearance(trajs).overlapping(-OVERLAP_TOL)
    lead, follow, cross = trajs
    # The leader waits for 'cross' (which leaves its start at t=12) inside the corridor,
    # and the follower is held inside the corridor too (it started at x=-3).
    assert np.any(np.diff(lead.t)[np.all(np.diff(lead.xy, axis=0) == 0, axis=1)] > 1.0)
    t_cross = float(cross.t[0])
    assert t_cross == 12.0
    still = np.all(np.diff(follow.xy, axis=0) == 0, axis=1) & (np.diff(follow.t) > 1.0)
    assert np.any(still & (follow.xy[:-1, 0] > 0.0)), "the follower stops inside the corridor"
    assert follow.t[-1] < 38.0, "following beats waiting for the whole corridor"


def test_a_robot_parked_at_its_start_goes_first() -> None:
    """'parked' stands 0.3 m beside 'drive''s route until t=6; 'drive' reaches its section
    at x ~ 4.2 and may pass only once 'parked' is 0.55 m up its way (t=6.55)."""
    req = request(SCENARIOS["parked_start"]())
    out = plan(req)
    graph = graph_of(out)
    assert graph is not None and graph.conflicts[0].get("first") == "b"
    assert out.assignment[0]["from"] == "parked/0"
    done = _completions(out)
    assert done["parked"] == pytest.approx(13.7)  # never waits
    reach = 0.85
    x_free = 5.0 - np.sqrt(reach**2 - 0.3**2)  # 'drive' must stop before here
    t_release = 6.0 + (reach - 0.3)  # 'parked' clear of 'drive''s route
    least = t_release + (10.0 - x_free)
    assert least - 1e-6 <= done["drive"] <= least + 0.25 + 1e-6  # + the resolution


def test_head_on_traffic_waits_outside_the_corridor() -> None:
    req = request(SCENARIOS["head_on"]())
    out = plan(req)
    assert [a["type"] for a in out.assignment] == ["exclusive"]
    done = _completions(out)
    times = np.arange(0.0, max(done.values()), 0.01)
    east, west = _xs(req, out, times)
    inside = (east > 1.0) & (east < 9.0) & (west > 1.0) & (west < 9.0)
    assert not inside.any(), "both robots in the one-lane corridor at once"


def test_a_queue_keeps_its_order() -> None:
    req = request(SCENARIOS["queue"]())
    out = plan(req)
    done = _completions(out)
    assert [done[f"q{k}"] for k in range(4)] == sorted(done[f"q{k}"] for k in range(4))
    times = np.arange(0.0, max(done.values()), 0.01)
    xs = _xs(req, out, times)
    for k in range(3):
        both = ~np.isnan(xs[k]) & ~np.isnan(xs[k + 1])
        assert np.all(xs[k][both] - xs[k + 1][both] >= 0.8 - 1e-6), f"q{k + 1} reached q{k}"


def test_robots_parked_in_each_others_way_are_refused() -> None:
    req = request([robot("east-1", [[0, 0], [10, 0]]), robot("west-2", [[10, 0], [0, 0]])])
    with pytest.raises(ProblemError) as err:
        plan(req)
    _assert_parked_refusal_justified(req, err.value)


def test_isolated_robots_get_their_planned_motion() -> None:
    fleet = [*SCENARIOS["three_way"](), robot("far", [[50, 50], [55, 50]], start_time=2.0)]
    req = request(fleet)
    out = plan(req)
    assert_motion_valid(req, out)
    graph = graph_of(out)
    assert graph is not None and "far" not in {r.id for r in graph.robots}
    far = wire_trajectories(req, out)[-1]
    np.testing.assert_allclose(far.t, [2.0, 7.0])
    np.testing.assert_allclose(far.xy, [[50, 50], [55, 50]])
    entry = next(s for s in out.schedule if s.robot == "far")
    assert entry.completion == 7.0 and entry.delay == 0.0 and entry.nodes == []


def test_no_interference_at_all() -> None:
    req = request([robot("a", [[0, 0], [1, 0]]), robot("b", [[0, 5], [1, 5]], speed=0.5)])
    out = plan(req)
    assert_motion_valid(req, out)
    assert out.graph is None and out.assignment == [] and out.solver.name == "none"
    assert _completions(out) == {"a": 1.0, "b": 2.0}


def _decision_of(req: PathsRequest, out: PathsScheduleResponse) -> Decision:
    """The answer's assignment as a decision on the request's graph (conflict order)."""
    graph = build_graph(paths_of(req), GeometrySettings())
    ids = graph.node_ids()
    a_first = np.array(
        [ids[a] == x["from"] for x, a in zip(out.assignment, graph.conf_node[:, 0], strict=True)],
        dtype=bool,
    )
    following = np.array([x["type"] == "following" for x in out.assignment], dtype=bool)
    return Decision(a_first, following)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(robots=fleets(max_robots=6, side=10.0), data=st.data())
def test_plans_stay_safe_when_robots_run_late(robots: Fleet, data: st.DataObject) -> None:
    """The answer's dependency plan executed with late starts, stops and slow-downs: no
    deadlock, no overlap (the dependencies, not the timing, keep robots apart)."""
    req = request(robots, solver="fcfs")
    try:
        out = plan(req)
    except ProblemError:
        return
    graph = build_graph(paths_of(req), GeometrySettings())
    piece = st.tuples(st.floats(0.0, 20.0), st.floats(0.1, 6.0), st.sampled_from([0.0, 0.3, 0.7]))
    rates = [Rate.of(data.draw(st.lists(piece, max_size=3))) for _ in robots]
    run = execute(graph.paths, dependency_plan(graph, _decision_of(req, out)), rates)
    assert run.deadlocked == ()
    trajs = trajectories(graph.paths, run)
    assert not reference_clearance(trajs).overlapping(-OVERLAP_TOL)
    assert check_clearance(trajs).ok
    late = np.array([s.completion for s in out.schedule])
    assert np.all(run.completion >= late - 1e-9), "a disturbance never makes a robot earlier"
