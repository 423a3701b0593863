"""The coordination graph of paths: nodes, conflicts, densities, fixed orders, the wire graph.

Densities are checked by what they allow under the contract (the reference's
density groups): a conflict may be following-type on its own only where the two
robots drive a section the same way, never where they cross or meet head-on.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from pydantic import ValidationError

from service.core.cliques import find_cliques
from service.core.path_schemas import MAX_ROBOT_ID_LENGTH, PathsRequest
from service.core.problem import ProblemError, problem_from_request
from service.core.schemas import MAX_ID_LENGTH, ScheduleRequest
from service.geometry import interference
from service.geometry.graph import CoordinationGraph, GeometrySettings, build_graph
from service.geometry.paths import RobotPath
from service.motion.plan import coordination_graph
from service.scenarios.kinds import KINDS, generate
from tests.motion.worlds import distance_to_path, fleets, paths_of, request, robot
from tests.reference import density_groups, density_ok, reference_problem

SETTINGS = GeometrySettings()


def _graph(robots: list[dict[str, Any]]) -> tuple[PathsRequest, CoordinationGraph]:
    """The request of ``robots`` and its graph."""
    req = request(robots)
    return req, build_graph(paths_of(req), SETTINGS)


def assert_graph_sound(req: PathsRequest, graph: CoordinationGraph) -> ScheduleRequest | None:
    """Structural invariants of a derived graph; returns its (accepted) wire form."""
    robot_of, span = graph.node_robot, graph.node_span
    assert np.all(np.diff(robot_of) >= 0), "nodes grouped by robot"
    assert np.all(span[:, 0] < span[:, 1])
    same = robot_of[1:] == robot_of[:-1]
    assert np.all(span[1:, 0][same] > span[:-1, 1][same]), "strictly separated, in path order"
    lengths = np.array([p.length for p in graph.paths])
    assert np.all(span[:, 0] >= 0) and np.all(span[:, 1] <= lengths[robot_of] + 1e-9)
    pairs = [tuple(p) for p in graph.conf_node.tolist()]
    assert len(set(pairs)) == len(pairs), "one conflict per node pair"
    assert np.all(robot_of[graph.conf_node[:, 0]] < robot_of[graph.conf_node[:, 1]])
    # Every box lies inside its conflict's union box, which lies inside both nodes.
    assert graph.box_start[0] == 0 and graph.box_start[-1] == graph.boxes.size
    assert np.all(np.diff(graph.box_start) > 0)
    for m in range(graph.n_conflicts):
        a, b = graph.conf_node[m]
        x0, x1, y0, y1 = graph.conf_span[m]
        lo, hi = graph.box_start[m], graph.box_start[m + 1]
        boxes = graph.boxes
        assert np.all(boxes.i[lo:hi] == robot_of[a]) and np.all(boxes.j[lo:hi] == robot_of[b])
        assert boxes.x0[lo:hi].min() == x0 and boxes.x1[lo:hi].max() == x1
        assert boxes.y0[lo:hi].min() == y0 and boxes.y1[lo:hi].max() == y1
        assert span[a, 0] <= x0 < x1 <= span[a, 1]
        assert span[b, 0] <= y0 < y1 <= span[b, 1]
        assert graph.forced[m] == _expected_first(graph, m), "a parked robot passes first"
    assert np.all(graph.node_density >= 1)
    wire = graph.to_request(req)
    if wire is None:
        assert robot_of.size == 0
        return None
    alone = following_alone_allowed(wire)
    assert alone == graph.conf_may_follow.tolist()
    for m, allowed in enumerate(alone):
        cos = np.concatenate(_box_cosines(graph, m))
        if allowed:  # crossings and head-on sections are exclusive
            assert np.any(cos > np.cos(np.radians(30))), f"crossing conflict {m} may follow"
            assert not np.any(cos < -np.cos(np.radians(30))), f"head-on conflict {m} may follow"
    # The density rules forbid following there and nowhere else: all the others at once.
    ref = reference_problem(wire.model_dump(mode="json", exclude_none=True))
    assert density_ok(density_groups(ref), alone)
    # No maximal clique can bind, so none is listed (none counts against the service's
    # clique work bound: a paths request is never refused with 413 for its cliques).
    cliques = find_cliques(problem_from_request(wire))
    assert cliques.budget.size == len(wire.density_limits) == int(np.sum(~np.array(alone)))
    assert_wire_is_the_graph(graph, wire)
    problem_from_request(wire)  # the contract's cross-field rules accept it
    ScheduleRequest.model_validate(wire.model_dump(mode="json"))  # and so does the wire
    assert [r.id for r in wire.robots] == [graph.paths[r].id for r in graph.robots_in_graph()]
    assert sorted(graph.isolated_robots() + [r.id for r in wire.robots]) == sorted(
        p.id for p in graph.paths
    )
    return wire


def assert_wire_is_the_graph(graph: CoordinationGraph, wire: ScheduleRequest) -> None:
    """The wire graph, built in bulk, says what the graph says, element by element: node
    and section times are the planned times of their arc lengths (``time_at`` one by one)."""
    ids, paths = graph.node_ids(), graph.paths
    nodes = [(r.id, n) for r in wire.robots for n in r.nodes]
    assert [n.id for _, n in nodes] == ids
    for v, (rid, node) in enumerate(nodes):
        path = paths[int(graph.node_robot[v])]
        assert rid == path.id
        assert [node.enter, node.exit] == path.time_at(graph.node_span[v]).tolist()
        assert node.density == graph.node_density[v]
    assert [r.goal_time for r in wire.robots] == [
        paths[r].finish_time for r in graph.robots_in_graph().tolist()
    ]
    assert len(wire.conflicts) == graph.n_conflicts
    for m, c in enumerate(wire.conflicts):
        a, b = graph.conf_node[m].tolist()
        i, j = graph.node_robot[[a, b]].tolist()
        x0, x1, y0, y1 = graph.conf_span[m]
        assert (c["a"], c["b"]) == (ids[a], ids[b])
        assert [c["a_enter"], c["a_exit"]] == paths[i].time_at([x0, x1]).tolist()
        assert [c["b_enter"], c["b_exit"]] == paths[j].time_at([y0, y1]).tolist()
        assert c.get("first") == {1: "a", -1: "b", 0: None}[int(graph.forced[m])]
    assert [d["nodes"] for d in wire.density_limits] == [
        [ids[a], ids[b]] for a, b in graph.exclusive_pairs().tolist()
    ]


def _expected_first(graph: CoordinationGraph, m: int) -> int:
    """+1 / -1 when side a / b of conflict m is parked (the section starts at its first
    point, which lies within reach of the other's stretch of the section), 0 when neither
    (both is refused before)."""
    i, j = graph.node_robot[graph.conf_node[m]].tolist()
    a, b = graph.paths[i], graph.paths[j]
    x0, x1, y0, y1 = graph.conf_span[m].tolist()
    reach = a.radius + b.radius + SETTINGS.margin
    a_parked = x0 <= 0.0 and distance_to_path(a.points[0], b, y0, y1) < reach
    b_parked = y0 <= 0.0
    if b_parked:  # b's arc lengths are exact: its first point is within reach of a's section
        assert distance_to_path(b.points[0], a, x0, x1) < reach + 1e-9
    assert not (a_parked and b_parked)
    return int(a_parked) - int(b_parked)


def following_alone_allowed(wire: ScheduleRequest) -> list[bool]:
    """Per conflict: do the contract's density rules let it alone be following-type?"""
    ref = reference_problem(wire.model_dump(mode="json", exclude_none=True))
    groups = density_groups(ref)
    return [
        density_ok(groups, [k == m for k in range(ref.n_conflicts)]) for m in range(ref.n_conflicts)
    ]


def _heading(path: RobotPath, s: np.ndarray) -> np.ndarray:
    """(K, 2) unit direction of travel of the segments holding arc lengths ``s`` (K,)."""
    k = np.clip(np.searchsorted(path.arc, s, side="right") - 1, 0, path.arc.size - 2)
    d = path.points[k + 1] - path.points[k]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _box_cosines(graph: CoordinationGraph, m: int) -> list[np.ndarray]:
    """Per box of conflict m, the cosines between i's heading on its piece and j's on each
    path segment that j's stretch runs along (a stretch may turn at j's vertices: the
    narrow phase merges a piece's stretches on consecutive segments into one box)."""
    lo, hi = graph.box_start[m], graph.box_start[m + 1]
    b = graph.boxes
    i, j = graph.node_robot[graph.conf_node[m]].tolist()
    ui = _heading(graph.paths[i], (b.x0[lo:hi] + b.x1[lo:hi]) / 2)  # (K, 2)
    arc = graph.paths[j].arc
    cosines = []
    for u, y0, y1 in zip(ui, b.y0[lo:hi], b.y1[lo:hi], strict=True):
        inner = arc[(arc > y0 + 1e-9) & (arc < y1 - 1e-9)]  # j's vertices inside the stretch
        cuts = np.concatenate([[y0], inner, [y1]])
        uj = _heading(graph.paths[j], (cuts[:-1] + cuts[1:]) / 2)  # (S, 2)
        cosines.append(uj @ u)
    return cosines


@settings(max_examples=40, deadline=None, derandomize=True)
@given(robots=fleets())
def test_random_fleets_give_sound_graphs_or_refuse_by_name(robots: list[dict[str, Any]]) -> None:
    req = request(robots)
    try:
        graph = build_graph(paths_of(req), SETTINGS)
    except ProblemError as err:
        assert "re-plan" in str(err)
        assert sum(f"'{r['id']}'" in str(err) for r in robots) >= 2
        return
    assert_graph_sound(req, graph)


def assert_problem_is_the_wire_problem(req: PathsRequest, graph: CoordinationGraph) -> None:
    """The problem built from the graph's arrays equals the one validated from its wire
    request, field by field."""
    direct = graph.problem()
    wire = graph.to_request(req)
    if wire is None:
        assert direct is None
        return
    assert direct is not None
    reference = problem_from_request(wire)
    for f in dataclasses.fields(reference):
        ours, theirs = getattr(direct, f.name), getattr(reference, f.name)
        if isinstance(theirs, np.ndarray):
            assert ours.dtype == theirs.dtype, f.name
            np.testing.assert_array_equal(ours, theirs, err_msg=f.name)
        elif f.name == "density_limits":
            assert [(d.nodes.tolist(), d.max_robots) for d in ours] == [
                (d.nodes.tolist(), d.max_robots) for d in theirs
            ]
        else:
            assert ours == theirs, f.name


@settings(max_examples=30, deadline=None, derandomize=True)
@given(robots=fleets())
def test_the_problem_from_arrays_is_the_wire_problem_on_random_fleets(
    robots: list[dict[str, Any]],
) -> None:
    req = request(robots)
    try:
        graph = build_graph(paths_of(req), SETTINGS)
    except ProblemError:
        return
    assert_problem_is_the_wire_problem(req, graph)


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_the_problem_from_arrays_is_the_wire_problem_on_scenario_worlds(kind: str) -> None:
    for seed in range(20):  # the first world of the kind that fixed paths do not refuse
        req = PathsRequest.model_validate(generate(kind, 20, seed).to_request())
        try:
            graph = build_graph(paths_of(req), SETTINGS)
        except ProblemError:
            continue
        assert graph.n_conflicts > 0
        assert_problem_is_the_wire_problem(req, graph)
        return
    pytest.fail(f"every {kind} world of 20 robots was refused")


def _graph_arrays(paths: list[RobotPath]) -> dict[str, np.ndarray]:
    graph = build_graph(paths, SETTINGS)
    return {
        "node_robot": graph.node_robot,
        "node_density": graph.node_density,
        "conf_node": graph.conf_node,
        "conf_may_follow": graph.conf_may_follow,
        "forced": graph.forced,
        "node_span": graph.node_span,
        "conf_span": graph.conf_span,
    }


def assert_coarse_pieces_give_the_fine_graph(paths: list[RobotPath]) -> None:
    """Shared stretches cut in coarse pieces leave nodes, conflicts, densities, fixed
    orders and pair sections as every piece at the resolution gives them (or the same
    refusal)."""
    try:
        coarse = _graph_arrays(paths)
    except ProblemError as err:
        with pytest.MonkeyPatch.context() as m, pytest.raises(ProblemError) as fine_err:
            m.setattr(interference, "COARSE_PIECE_M", 0.0)
            _graph_arrays(paths)
        assert str(fine_err.value) == str(err)
        return
    with pytest.MonkeyPatch.context() as m:
        m.setattr(interference, "COARSE_PIECE_M", 0.0)  # one piece per resolution step
        fine = _graph_arrays(paths)
    for name, value in fine.items():
        np.testing.assert_allclose(coarse[name], value, rtol=0, atol=1e-9, err_msg=name)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(robots=fleets())
def test_coarse_pieces_give_the_fine_graph_on_random_fleets(robots: list[dict[str, Any]]) -> None:
    assert_coarse_pieces_give_the_fine_graph(paths_of(request(robots)))


@pytest.mark.parametrize("kind", sorted(KINDS))
@pytest.mark.parametrize("seed", [0, 1])
def test_coarse_pieces_give_the_fine_graph_on_scenario_worlds(kind: str, seed: int) -> None:
    req = PathsRequest.model_validate(generate(kind, 40, seed).to_request())
    assert_coarse_pieces_give_the_fine_graph(paths_of(req))


@pytest.mark.parametrize("kind", sorted(KINDS))
@pytest.mark.parametrize("seed", [0, 1])
def test_scenario_worlds_give_sound_graphs(kind: str, seed: int) -> None:
    """The generator's worlds (many conflicts, timed and mixed fleets) give sound graphs
    whose wire form is exactly the graph (or are refused by name)."""
    req = PathsRequest.model_validate(generate(kind, 25, seed).to_request())
    try:
        graph = build_graph(paths_of(req), SETTINGS)
    except ProblemError as err:
        assert "re-plan" in str(err)
        return
    assert_graph_sound(req, graph)


def test_crossing_robots_form_one_exclusive_conflict() -> None:
    req, graph = _graph(
        [robot("h", [[0, 5], [10, 5]], start_time=1.0), robot("v", [[5, 0], [5, 10]], speed=2.0)]
    )
    wire = assert_graph_sound(req, graph)
    assert wire is not None
    assert graph.n_conflicts == 1 and graph.node_robot.tolist() == [0, 1]
    assert graph.node_density.tolist() == [2, 2] and graph.exclusive_pairs().tolist() == [[0, 1]]
    assert graph.forced.tolist() == [0]
    # Both sections are centred on the crossing and span at least the two radii + margin.
    (x0, x1), (y0, y1) = graph.node_span.tolist()
    assert x0 < 5 - 0.85 + 1e-9 and x1 > 5 + 0.85 - 1e-9 and (x0 + x1) / 2 == pytest.approx(5)
    assert y0 < 5 - 0.85 + 1e-9 and y1 > 5 + 0.85 - 1e-9 and (y0 + y1) / 2 == pytest.approx(5)
    # Times are the planned times there: h from t=1 at 1 m/s, v at 2 m/s from 0.
    node_h, node_v = wire.robots[0].nodes[0], wire.robots[1].nodes[0]
    assert (node_h.enter, node_h.exit) == pytest.approx((1 + x0, 1 + x1))
    assert (node_v.enter, node_v.exit) == pytest.approx((y0 / 2, y1 / 2))
    assert wire.robots[0].goal_time == 11.0 and wire.robots[1].goal_time == 5.0
    assert graph.node_ids() == ["h/0", "v/0"]
    assert graph.node_spans() == {"h/0": (x0, x1), "v/0": (y0, y1)}


# Lane b joins lane a 0.6 m beside it on a shallow (11 degree) approach: co-directional.
LANE_A = [[-1.0, 0.0], [10.0, 0.0]]
LANE_B = [[-20.0, 5.0], [2.0, 0.6], [10.0, 0.6]]


def test_following_only_for_co_directional_sections() -> None:
    """Two robots side by side the same way may follow; head-on or crossed, they may not."""
    req, same = _graph([robot("a", LANE_A), robot("b", LANE_B)])
    wire = assert_graph_sound(req, same)
    assert wire is not None and following_alone_allowed(wire) == [True]
    assert np.all(same.node_density >= 2) and same.forced.tolist() == [0]
    req, opposite = _graph([robot("a", LANE_A), robot("b", LANE_B[::-1])])
    wire = assert_graph_sound(req, opposite)
    assert wire is not None and following_alone_allowed(wire) == [False]
    assert opposite.node_density.tolist() == [2, 2] and opposite.exclusive_pairs().tolist() == [
        [0, 1]
    ]
    req, mixed = _graph([robot("a", LANE_A), robot("b", LANE_B), robot("c", [[5, -5], [5, 5]])])
    wire = assert_graph_sound(req, mixed)
    assert wire is not None and mixed.n_conflicts == 3
    crossing = [m for m, c in enumerate(wire.conflicts) if c["b"].startswith("c/")]
    assert len(crossing) == 2
    allowed = following_alone_allowed(wire)
    assert not any(allowed[m] for m in crossing)


def test_a_start_near_but_outside_a_route_is_not_parked() -> None:
    """r0 starts 0.5 m from r1's route (reach 0.4875 m) but its first 0.25 m piece comes
    within reach: only r1 (which starts on r0's route) is parked, and r0 waits at its start.
    Found by the motion property test: both were reported parked (a false 422)."""
    robots = [
        robot("r0", [[1.0, 0.0], [0.0, 0.0]], radius=0.21875, times=[0.0, 1.0]),
        robot("r1", [[0.0, 0.0], [0.5, 0.0]], radius=0.21875, times=[0.0, 0.5]),
    ]
    req, graph = _graph(robots)
    wire = assert_graph_sound(req, graph)
    assert wire is not None and graph.forced.tolist() == [-1]
    assert graph.conf_span[0, 0] == 0.0  # r0's section does start at its first point


def test_a_start_at_the_corner_of_another_route_is_parked() -> None:
    """r1 turns at r0's first point: r0 is parked (fixed first) even where a box's stretch of
    r1 spans the corner (a chord between the stretch's ends misses r0's start)."""
    robots = [
        robot("r0", [[0.0, 0.0], [0.5, 0.0]], radius=0.25, times=[0.0, 0.5]),
        robot("r1", [[1.0, 1.0], [0.0, 0.0], [1.0, 0.0]], radius=0.5, speed=1.0),
    ]
    req, graph = _graph(robots)
    assert_graph_sound(req, graph)
    assert graph.forced.tolist() == [1]


def test_parked_robot_passes_first() -> None:
    """b starts on a's route (a drives through b's start point): b is fixed first."""
    req, graph = _graph(
        [robot("a", [[0, 0], [10, 0]]), robot("b", [[5, 0.3], [5, 8]], start_time=3.0)]
    )
    wire = assert_graph_sound(req, graph)
    assert wire is not None and graph.n_conflicts == 1
    assert graph.forced.tolist() == [-1]
    assert wire.conflicts[0].get("first") == "b"
    assert graph.conf_span[0, 2] == 0.0


@pytest.mark.parametrize("swap", [False, True])
def test_robots_parked_in_each_others_way_are_refused_by_name(swap: bool) -> None:
    """Facing each other in a one-lane aisle: neither can pass the other."""
    robots = [robot("east-1", [[0, 0], [10, 0]]), robot("west-2", [[10, 0], [0, 0]])]
    if swap:
        robots.reverse()
    with pytest.raises(ProblemError) as err:
        _graph(robots)
    assert "'east-1'" in str(err.value) and "'west-2'" in str(err.value)


def test_a_circle_of_parked_robots_is_refused_naming_all() -> None:
    """Three robots each parked on the next one's way out of a small triangle."""
    corners = np.array([[0.0, 0.0], [1.6, 0.0], [0.8, 1.4]])
    nxt = np.roll(corners, -1, axis=0)
    robots = [robot(f"r{k}", [corners[k], nxt[k], 8 * nxt[k] - 4 * corners[k]]) for k in range(3)]
    with pytest.raises(ProblemError) as err:
        _graph(robots)
    message = str(err.value)
    assert all(f"'r{k}'" in message for k in range(3)), message


def test_out_and_back_path_crossed_twice() -> None:
    """An aisle driven out and back, crossed near its middle: two nodes on the aisle robot,
    one on the crossing robot, and two conflicts."""
    req, graph = _graph(
        [robot("aisle", [[0, 0], [10, 0], [0, 0.05]]), robot("cross", [[4, -4], [4, 4]])]
    )
    assert_graph_sound(req, graph)
    aisle = graph.node_span[graph.node_robot == 0]
    assert aisle.shape == (2, 2)
    assert aisle[0, 1] < 10 < aisle[1, 0]
    assert graph.n_conflicts == 2
    assert (graph.node_robot == 1).sum() == 1


def test_isolated_robots_are_listed_and_get_no_node() -> None:
    req, graph = _graph(
        [
            robot("lonely", [[50, 50], [60, 50]]),
            robot("h", [[0, 5], [10, 5]]),
            robot("v", [[5, 0], [5, 10]]),
        ]
    )
    wire = assert_graph_sound(req, graph)
    assert graph.isolated_robots() == ["lonely"]
    assert 0 not in graph.node_robot.tolist()
    assert wire is not None and [r.id for r in wire.robots] == ["h", "v"]
    response = coordination_graph(req, SETTINGS)
    assert response.isolated_robots == ["lonely"]
    assert set(response.node_spans) == {"h/0", "v/0"}


def test_no_interference_gives_no_graph() -> None:
    req, graph = _graph([robot("a", [[0, 0], [1, 0]]), robot("b", [[0, 5], [1, 5]])])
    assert graph.to_request(req) is None
    assert graph.isolated_robots() == ["a", "b"]
    assert graph.n_conflicts == 0


def test_the_longest_robot_ids_still_name_valid_nodes() -> None:
    """Node ids are "<robot id>/<k>": a robot id of the paths form's longest length gives
    node ids within the graph form's limit; one character more is refused by name (422),
    never a graph the service cannot validate (it answered 503)."""
    longest = MAX_ROBOT_ID_LENGTH
    ids = ["h" * longest, "v" * longest]
    req, graph = _graph([robot(ids[0], [[0, 5], [10, 5]]), robot(ids[1], [[5, 0], [5, 10]])])
    wire = assert_graph_sound(req, graph)
    assert wire is not None and max(len(n) for n in graph.node_ids()) <= MAX_ID_LENGTH
    body = req.model_dump(exclude_none=True)
    body["robots"][1]["id"] = "v" * (longest + 1)
    with pytest.raises(ValidationError) as err:
        PathsRequest.model_validate(body)
    assert [e["loc"] for e in err.value.errors()] == [("robots", 1, "id")]
