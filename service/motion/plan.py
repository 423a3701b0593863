"""The paths form end to end: paths -> graph -> schedule -> executed, checked trajectories.

:func:`plan_paths` is what ``POST /v1/schedules`` runs for a paths-form body:
derive the coordination graph (geometry), solve it with the dispatcher (any
solver, checked by the one constraint checker), turn the assignment into a
dependency plan, execute it (simulation), and check the trajectories with the
one clearance check. A plan that fails the clearance check or deadlocks is
never returned: the same directions are tried with every conflict exclusive
(safe by construction), and if even that failed the request fails loudly.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.core.path_schemas import (
    CoordinationGraphResponse,
    Dependency,
    MotionChecksOut,
    PathsRequest,
    PathsScheduleResponse,
    TimingsOut,
    TrajectoryOut,
)
from service.core.problem import ProblemError
from service.core.schemas import (
    AssignmentOut,
    CostsOut,
    NodeTimesOut,
    ProgressIn,
    RobotScheduleOut,
    ScheduleRequest,
    SolverInfoOut,
)
from service.core.threads import shared_pool
from service.geometry.graph import CoordinationGraph, GeometrySettings, build_graph
from service.geometry.paths import RobotPath
from service.motion.dependencies import Decision, dependency_plan, without_implied
from service.motion.progress import progress_at, state_of
from service.motion.reserve import MotionReserve, work_units
from service.motion.trajectories import departure_times, realized_costs, trajectories
from service.scenarios.world import World
from service.simulation.clearance import Clearance, Trajectory, check_clearance
from service.simulation.executor import (
    DependencyPlan,
    Execution,
    Run,
    State,
    execute,
    on_clock,
)
from service.simulation.simulate import plan_to_wire
from service.solvers.dispatch import (
    CHECK_RESERVE_S,
    Checked,
    DispatchPolicy,
    InvalidAnswerError,
    dispatch_problem,
)

__all__ = [
    "MOTION_RESERVE",
    "PathsAnswer",
    "coordination_graph",
    "derived_request",
    "plan_paths",
    "world_request",
]

log = logging.getLogger(__name__)

# The time kept after the solve for execution, the clearance check and the answer, learned
# from this process's answers (service/motion/reserve.py); at least MIN_SOLVE_S to solve.
MOTION_RESERVE = MotionReserve()
MIN_SOLVE_S = 0.05


@dataclass(frozen=True, eq=False)
class PathsAnswer:
    """A paths-form answer and its JSON body (by alias, as the route sends it).

    Encoded here, not by the route, so that the motion reserve learns the whole time an
    answer takes after its solve: a 250-robot answer is 4-7 MB of JSON, 0.03-0.06 s to
    encode.
    """

    response: PathsScheduleResponse
    content: bytes
    encode_s: float  # seconds spent encoding ``content``


@dataclass(frozen=True, eq=False)
class _Executed:
    """A decision that executed without deadlock and passed the clearance check."""

    decision: Decision
    plan: DependencyPlan  # the constraints ahead (of a re-schedule's state), none implied
    plan_wire: list[Dependency]  # the same plan in the wire format
    run: Run
    trajectories: list[Trajectory]
    clearance: Clearance


@dataclass(frozen=True, eq=False)
class _Described:
    """What the answer says of the graph and of the solver's decision, whatever its
    execution (built on a kernel thread while the plan is executed)."""

    decision: Decision
    graph_wire: dict[str, Any] | None  # the graph's JSON body (see PathsScheduleResponse)
    time_points: list[np.ndarray]  # per robot (P_r,): :func:`_time_points`
    assignment: list[AssignmentOut]  # ``decision`` in the wire format


def derive(request: PathsRequest, geometry: GeometrySettings) -> CoordinationGraph:
    """The coordination graph of a paths-form request.

    Raises:
        ProblemError: fixed paths leave no collision-free order.
    """
    return build_graph(RobotPath.all_from_wire(request.robots), geometry)


def world_request(world: World, objective: str = "avg_completion") -> ScheduleRequest | None:
    """The graph-form request the service derives from ``world``'s paths for ``objective``
    (None: no two robots interfere).

    Raises:
        ProblemError: the service refuses the paths (422).
    """
    paths = PathsRequest.model_validate(world.to_request(objective))
    return derive(paths, GeometrySettings()).to_request(paths)


def derived_request(world: World) -> ScheduleRequest | None:
    """The graph-form request of ``world``, as the service derives it; None when the
    service would refuse the world (422) or no two of its robots interfere. (Never 413:
    a derived graph's density cliques are its exclusive-only conflicts' own limits, which
    the clique work bound does not count; see service/geometry/graph.py.)"""
    try:
        return world_request(world)
    except ProblemError:
        return None


def coordination_graph(
    request: PathsRequest, geometry: GeometrySettings
) -> CoordinationGraphResponse:
    """What ``POST /v1/coordination-graphs`` answers: the graph and its node spans."""
    graph = derive(request, geometry)
    return CoordinationGraphResponse.model_construct(
        graph=graph.to_wire(request),  # its JSON body (see CoordinationGraphResponse)
        node_spans=graph.node_spans(),
        isolated_robots=graph.isolated_robots(),
    )


def plan_paths(
    request: PathsRequest,
    policy: DispatchPolicy,
    geometry: GeometrySettings,
    *,
    deadline: float | None = None,
    reserve: MotionReserve = MOTION_RESERVE,
) -> PathsAnswer:
    """Schedule ``request`` and return trajectories that never collide, with the
    answer's JSON body.

    Args:
        deadline: ``time.monotonic()`` by which the answer is due (the request's arrival
            plus its time limit); default: the time limit from now. The solve gets what
            is left of it after the geometry, less what ``reserve`` keeps for motion
            (execution, the clearance check, the answer and its encoding), which then
            learns what motion took.

    Raises:
        ProblemError: bad geometry (fixed paths leave no collision-free order).
        TooComplex: the paths interfere in more places than the work bound allows.
        InvalidAnswerError: not even the all-exclusive plan executed cleanly (a bug).
    """
    start = time.perf_counter()
    if deadline is None:
        deadline = time.monotonic() + (request.options.time_limit_s or policy.default_time_limit_s)
    graph = derive(request, geometry)
    state = None if request.progress is None else state_of(graph.paths, request.progress)
    problem = graph.problem()
    progress = None if state is None or problem is None else progress_at(graph, state)
    graph_done = time.perf_counter()
    answer: Checked | None = None
    units = 0 if problem is None else work_units(problem)
    if problem is not None:
        solve_due = max(deadline - reserve.seconds(units), time.monotonic() + MIN_SOLVE_S)
        answer = dispatch_problem(
            problem,
            request,
            policy,
            deadline=solve_due,
            previous=request.previous,
            progress=progress,
            reserve_s=CHECK_RESERVE_S,  # its graph-form response is not rendered
        )
    solve_done = time.perf_counter()
    # What the answer says of the graph (Python, holding the GIL) is built on a kernel
    # thread while the plan is executed and checked (numba kernels, most without it).
    decision = _decided(answer)
    described = shared_pool().submit(_describe, request, graph, progress, decision)
    executed = _execute_safely(graph, decision, state)
    response = _render(
        request, graph, described.result(), answer, executed, solve_done - graph_done, state
    )
    # Motion: everything after the solve, building this answer included (its encoding,
    # which must come after, is not, but the reserve learns it too).
    motion_done = time.perf_counter()
    response.timings = TimingsOut(
        graph_s=graph_done - start,
        solve_s=solve_done - graph_done,
        motion_s=motion_done - solve_done,
    )
    content = response.model_dump_json(by_alias=True).encode()
    encode_s = time.perf_counter() - motion_done
    reserve.observe(units, response.timings.motion_s + encode_s)
    return PathsAnswer(response, content, encode_s)


def _decided(answer: Checked | None) -> Decision:
    """The checked answer's assignment as arrays (the derived problem keeps the graph's
    conflict order, side a first where the graph's first node passes first)."""
    if answer is None:
        return Decision(np.zeros(0, dtype=bool), np.zeros(0, dtype=bool))
    return Decision(answer.output.assignment.a_first[0], answer.output.assignment.following[0])


def _execute_safely(graph: CoordinationGraph, decision: Decision, state: State | None) -> _Executed:
    """Execute ``decision`` (from ``state`` on, for a re-schedule), or its all-exclusive
    version, whichever first runs clean."""
    for candidate in (decision, decision.exclusive()):
        # The constraints still ahead, without those others imply: what is run and sent.
        ahead = _ahead(graph.paths, dependency_plan(graph, candidate), state)
        plan = without_implied(ahead, len(graph.paths))
        plan_wire = shared_pool().submit(plan_to_wire, graph.paths, plan)  # while it runs
        if state is None:
            run = execute(graph.paths, plan)
        else:
            run = Execution.resume(graph.paths, plan, state).finish()
        if run.deadlocked:
            log.error("plan deadlocked (robots %s); trying all-exclusive", run.deadlocked[:10])
            continue
        trajs = trajectories(graph.paths, run)
        clearance = check_clearance(trajs)
        if clearance.ok:
            return _Executed(candidate, plan, plan_wire.result(), run, trajs, clearance)
        log.error(
            "plan failed the clearance check %s; trying all-exclusive", clearance.overlaps[:3]
        )
    raise InvalidAnswerError("no executable collision-free plan for a valid assignment")


def _describe(
    request: PathsRequest,
    graph: CoordinationGraph,
    progress: ProgressIn | None,
    decision: Decision,
) -> _Described:
    """The parts of the answer that its execution does not change."""
    return _Described(
        decision,
        graph.to_wire(request, request.previous, progress),
        _time_points(graph),
        _assignment(graph, decision),
    )


def _render(
    request: PathsRequest,
    graph: CoordinationGraph,
    described: _Described,
    answer: Checked | None,
    executed: _Executed,
    solve_s: float,
    state: State | None,
) -> PathsScheduleResponse:
    """The wire answer: the graph answer's fields, re-described by the executed motion
    (from ``state`` on, for a re-schedule: the dependencies left to obey)."""
    paths, run = graph.paths, executed.run
    ids = graph.node_ids()
    planned = described.time_points
    node_bounds = np.searchsorted(graph.node_robot, np.arange(len(paths) + 1)).tolist()
    realized, schedule = [], []
    for r, path in enumerate(paths):
        lo, hi = node_bounds[r], node_bounds[r + 1]  # robot r's nodes, in path order
        n_points = planned[r].size
        # (P + 2n,) one lookup for the time points and the node ends
        span_times = path.time_at(graph.node_span[lo:hi].T.ravel())
        left = _departures(run, r, np.concatenate([planned[r], span_times]), state)
        realized.append(left[:n_points])
        enter, exit_ = left[n_points : n_points + hi - lo], left[n_points + hi - lo :]
        schedule.append(
            RobotScheduleOut.model_construct(
                robot=path.id,
                completion=float(run.completion[r]),
                delay=float(run.completion[r] - path.finish_time),
                nodes=[
                    NodeTimesOut.model_construct(id=ids[v], enter=a, exit=b)
                    for v, a, b in zip(range(lo, hi), enter.tolist(), exit_.tolist(), strict=True)
                ],
            )
        )
    costs = realized_costs(run.completion, planned, realized)
    # Constructed without re-validation: every field comes from checked arrays and the
    # request's ids (tests validate rendered answers against the models).
    return PathsScheduleResponse.model_construct(
        objective=request.objective,
        cost=costs[request.objective],
        costs=CostsOut(**costs),
        assignment=described.assignment
        if executed.decision is described.decision
        else _assignment(graph, executed.decision),
        schedule=schedule,
        solver=_solver_info(answer, executed, solve_s),
        checks=MotionChecksOut(
            acyclic=True if answer is None else answer.checks.acyclic,
            density=True if answer is None else answer.checks.density,
            forced=True if answer is None else answer.checks.forced,
            collision_free=executed.clearance.ok,
            min_clearance_m=executed.clearance.min_gap,
        ),
        graph=described.graph_wire,
        node_spans=graph.node_spans(),
        trajectories=[
            TrajectoryOut.model_construct(
                robot=path.id,
                points=list(map(tuple, np.column_stack([tr.t, tr.xy]).tolist())),  # (t, x, y)
            )
            for path, tr in zip(paths, executed.trajectories, strict=True)
        ],
        dependencies=executed.plan_wire,
        timings=TimingsOut(graph_s=0.0, solve_s=solve_s, motion_s=0.0),  # set by the caller
    )


def _departures(run: Run, r: int, planned: np.ndarray, state: State | None) -> np.ndarray:
    """(P,) when robot r leaves each planned time point (P,): read off the run, except
    points a re-schedule's robot had passed before ``state.time``, which are estimated
    like the residual problem does (planned time plus the robot's delay then)."""
    out = departure_times(run.wall[r], run.clock[r], planned)
    if state is None or not state.started[r]:
        return out
    late = (
        state.time - state.clock[r] if not state.done[r] else state.completion[r] - state.clock[r]
    )
    return np.where(planned < state.clock[r], planned + late, out)


def _ahead(paths: list[RobotPath], plan: DependencyPlan, state: State | None) -> DependencyPlan:
    """The constraints of ``plan`` still to obey from ``state`` on (all without a state):
    a robot already past its wait point, or done, no longer waits there."""
    if state is None:
        return plan
    wait_clock = on_clock(paths, plan.waiter, plan.wait_s)  # (D,)
    # A robot not started stands at its start clock, before every wait point of its own.
    keep = ~state.done[plan.waiter] & (wait_clock >= state.clock[plan.waiter])
    return DependencyPlan(
        plan.waiter[keep], plan.wait_s[keep], plan.waitee[keep], plan.until_s[keep]
    )


def _time_points(graph: CoordinationGraph) -> list[np.ndarray]:
    """Per robot (P_r,) its planned time points (contract): node and pair ends, goal."""
    robot = graph.node_robot[graph.conf_node]  # (M, 2)
    owner = np.concatenate(
        [np.arange(len(graph.paths)), np.repeat(graph.node_robot, 2), np.repeat(robot.ravel(), 2)]
    )
    arc = np.concatenate(
        [
            [p.length for p in graph.paths],
            graph.node_span.ravel(),
            graph.conf_span.ravel(),  # x0 x1 on side a, y0 y1 on side b
        ]
    )
    order = np.argsort(owner, kind="stable")
    bounds = np.searchsorted(owner[order], np.arange(len(graph.paths) + 1))
    return [
        np.unique(p.time_at(arc[order[bounds[r] : bounds[r + 1]]]))
        for r, p in enumerate(graph.paths)
    ]


def _assignment(graph: CoordinationGraph, decision: Decision) -> list[AssignmentOut]:
    """The executed decision in the wire format, in the graph's conflict order."""
    ids = graph.node_ids()
    a, b = graph.conf_node[:, 0], graph.conf_node[:, 1]  # (M,) each
    first = np.where(decision.a_first, a, b).tolist()
    second = np.where(decision.a_first, b, a).tolist()
    kinds = ["following" if f else "exclusive" for f in decision.following.tolist()]
    return [
        {"from": ids[u], "to": ids[v], "type": k}
        for u, v, k in zip(first, second, kinds, strict=True)
    ]


def _solver_info(answer: Checked | None, executed: _Executed, runtime_s: float) -> SolverInfoOut:
    """The graph solver's info (its runtime: the whole dispatch), noting when the plan had
    to be executed all-exclusive."""
    if answer is None:
        return SolverInfoOut(
            name="none", optimal=True, runtime_s=runtime_s, detail="no two robots interfere"
        )
    info = answer.info.model_copy(update={"runtime_s": runtime_s})
    if bool(np.any(executed.decision.following != _decided(answer).following)):
        info = info.model_copy(
            update={"optimal": False, "detail": "executed with every conflict exclusive"}
        )
    return info
