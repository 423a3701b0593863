"""Wire models of the paths form: robots given by their paths, answered with trajectories.

A request of the paths form describes each robot by a polyline, a disk footprint
and its timing (a constant ``speed`` from ``start_time``, or one planned time per
path point). Field-by-field rules live here; the geometry package derives the
coordination graph, and the motion package turns the schedule back into motion.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    SerializerFunctionWrapHandler,
    field_serializer,
    field_validator,
    model_validator,
    with_config,
)
from typing_extensions import TypedDict

from service.core.schemas import (
    MAX_ID_LENGTH,
    MAX_TIME,
    AssignmentOut,
    ChecksOut,
    CostsOut,
    Objective,
    OptionsIn,
    PreviousConflictIn,
    RobotScheduleOut,
    ScheduleRequest,
    SolverInfoOut,
)

__all__ = [
    "MAX_COORDINATE",
    "MAX_RADIUS",
    "MAX_SPEED",
    "PathRobotIn",
    "PathRobotProgressIn",
    "PathsProgressIn",
    "PathsRequest",
    "TrajectoryOut",
    "TimingsOut",
    "MotionChecksOut",
    "Dependency",
    "WaitPoint",
    "WaitAfter",
    "DisturbanceIn",
    "TrajectoryIn",
    "SimulationRequest",
    "OverlapOut",
    "SimulationResponse",
    "PathsScheduleResponse",
    "CoordinationGraphResponse",
]

# Coordinates are metres; a floor larger than 2,000 km is a unit error, not a layout.
MAX_COORDINATE = 1e6
# A footprint wider than 1 km or faster than 1 km/s is a unit error too.
MAX_RADIUS = 1e3
MAX_SPEED = 1e3

# Strict: numbers must be JSON numbers (no "1.5" strings, no booleans), as in the graph form.
Coordinate = Annotated[
    float, Field(strict=True, ge=-MAX_COORDINATE, le=MAX_COORDINATE, allow_inf_nan=False)
]
Point = tuple[Coordinate, Coordinate]
Time = Annotated[float, Field(strict=True, ge=0.0, le=MAX_TIME, allow_inf_nan=False)]
Id = Annotated[str, Field(min_length=1, max_length=MAX_ID_LENGTH)]
# A robot's nodes in the derived graph are "<robot id>/<k>": its id leaves room for "/"
# and seven digits (k < the geometry's MAX_PIECES = 2e6 pieces of all paths), so that
# every node id fits the graph form's MAX_ID_LENGTH.
MAX_ROBOT_ID_LENGTH = MAX_ID_LENGTH - 8
RobotId = Annotated[str, Field(min_length=1, max_length=MAX_ROBOT_ID_LENGTH)]


class PathRobotIn(BaseModel):
    """One robot of the paths form: its path, disk footprint and planned timing."""

    model_config = ConfigDict(extra="forbid")

    id: RobotId
    path: list[Point] = Field(min_length=2)
    radius: float = Field(gt=0.0, le=MAX_RADIUS, allow_inf_nan=False, strict=True)
    speed: float | None = Field(
        default=None, gt=0.0, le=MAX_SPEED, allow_inf_nan=False, strict=True
    )
    start_time: Time | None = None
    times: list[Time] | None = None

    @property
    def begin(self) -> float:
        """Planned start time: ``times[0]``, else ``start_time`` (default 0)."""
        return self.times[0] if self.times else self.start_time or 0.0

    @field_validator("path")
    @classmethod
    def _distinct_consecutive(cls, path: list[Point]) -> list[Point]:
        """Consecutive points must differ: a zero-length segment has no heading."""
        for k in range(1, len(path)):
            if path[k] == path[k - 1]:
                raise ValueError(f"path points {k - 1} and {k} are equal: {list(path[k])}")
        return path

    @field_validator("times")
    @classmethod
    def _increasing(cls, times: list[float] | None) -> list[float] | None:
        """Planned times must strictly increase (every segment takes positive time)."""
        if times is not None:
            for k in range(1, len(times)):
                if not times[k] > times[k - 1]:
                    raise ValueError(
                        f"times must strictly increase: times[{k}] = {times[k]} <= "
                        f"times[{k - 1}] = {times[k - 1]}"
                    )
        return times

    @model_validator(mode="after")
    def _one_timing(self) -> PathRobotIn:
        """Exactly one timing: ``speed`` (with ``start_time``) or ``times`` (one per point)."""
        if self.times is None:
            if self.speed is None:
                raise ValueError("give 'speed' (with optional 'start_time') or 'times'")
            arrival = (self.start_time or 0.0) + path_length(self.path) / self.speed
            if not arrival <= MAX_TIME:
                raise ValueError(f"'speed': the robot would arrive at {arrival} s > {MAX_TIME}")
            return self
        if self.speed is not None:
            raise ValueError("'speed' and 'times' are exclusive: give one of them")
        if self.start_time is not None:
            raise ValueError("'start_time' comes with 'speed'; with 'times' it is times[0]")
        if len(self.times) != len(self.path):
            raise ValueError(
                f"'times' has {len(self.times)} entries; 'path' has {len(self.path)} points"
            )
        return self


def path_length(path: list[Point]) -> float:
    """Total Euclidean length of a polyline, metres."""
    return sum(math.dist(p, q) for p, q in zip(path[:-1], path[1:], strict=True))


class PathRobotProgressIn(BaseModel):
    """Where one robot is: arc length ``s`` (metres along its path) reached at the time."""

    model_config = ConfigDict(extra="forbid")

    s: float = Field(ge=0.0, le=1e9, allow_inf_nan=False, strict=True)


class PathsProgressIn(BaseModel):
    """The fleet at ``time`` (the paths' clock); robots not listed have not started."""

    model_config = ConfigDict(extra="forbid")

    time: Time
    robots: dict[Id, PathRobotProgressIn] = Field(default_factory=dict)


class PathsRequest(BaseModel):
    """Body of the paths form of ``POST /v1/schedules`` and ``POST /v1/coordination-graphs``.

    With ``progress`` (and optionally ``previous``: the assignment of the answer being
    executed) it is a re-schedule from ``progress.time`` on (docs/paths.md).
    """

    model_config = ConfigDict(extra="forbid")

    objective: Objective = "avg_completion"
    robots: list[PathRobotIn] = Field(min_length=1)
    options: OptionsIn = Field(default_factory=OptionsIn)
    previous: list[PreviousConflictIn] | None = None
    progress: PathsProgressIn | None = None

    @model_validator(mode="after")
    def _unique_ids(self) -> PathsRequest:
        """Robot ids name trajectories and nodes, so they must be unique."""
        seen: set[str] = set()
        for robot in self.robots:
            if robot.id in seen:
                raise ValueError(f"duplicate robot id '{robot.id}'")
            seen.add(robot.id)
        return self


def request_form(body: object) -> Literal["paths", "graph"]:
    """Which form a request body uses: ``paths`` when its first robot has a ``path`` (raw),
    or when it is already a :class:`PathsRequest` (validated from its JSON bytes, see
    :mod:`service.api.body`)."""
    if isinstance(body, PathsRequest):
        return "paths"
    if isinstance(body, dict):
        robots = body.get("robots")
        if isinstance(robots, list) and robots and isinstance(robots[0], dict):
            return "paths" if "path" in robots[0] else "graph"
    return "graph"


class TrajectoryOut(BaseModel):
    """Timed waypoints ``[t, x, y]`` of one robot; motion is linear between consecutive ones."""

    robot: str
    points: list[tuple[float, float, float]]


class MotionChecksOut(ChecksOut):
    """The graph checks plus the independent clearance check of the executed trajectories."""

    collision_free: bool
    min_clearance_m: float | None = Field(
        description="Least gap between two present footprints (centre distance minus both "
        "radii) over the whole run; null when no two robots are ever present together."
    )


# The dependency plan is typed as TypedDicts rather than models: a 250-robot plan has
# ~10^4-10^5 entries, and building them as models measured seconds; dicts are built in
# microseconds and validated in pydantic-core when the response is assembled.
@with_config(ConfigDict(extra="forbid"))
class WaitAfter(TypedDict):
    """Robot ``robot`` must have reached arc length ``s`` (metres) on its path."""

    robot: Id
    s: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


@with_config(ConfigDict(extra="forbid"))
class WaitPoint(TypedDict):
    """A point (arc length ``s``, metres) where a robot may have to wait until every robot
    of ``after`` has reached its point."""

    s: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
    after: list[WaitAfter]


@with_config(ConfigDict(extra="forbid"))
class Dependency(TypedDict):
    """One robot's dependency plan: its wait points in path order (executable without clocks)."""

    robot: Id
    waits: list[WaitPoint]


class TimingsOut(BaseModel):
    """Where the time of a paths-form answer went, seconds."""

    graph_s: float = Field(description="Paths to coordination graph (geometry).")
    solve_s: float = Field(description="The graph's solve, checks and evaluation (dispatch).")
    motion_s: float = Field(description="Dependency plan, execution and clearance check.")


# No return annotation on purpose: pydantic would take it for the field's JSON Schema,
# which must stay the graph-form request's.
def _graph_as_built(
    self: BaseModel,
    graph: ScheduleRequest | dict[str, Any] | None,
    handler: SerializerFunctionWrapHandler,
):  # type: ignore[no-untyped-def]
    """Serialize ``graph`` as built: the service fills it with the graph-form request's
    plain JSON body (from the graph's arrays, valid by construction; tests validate it
    and post it back), since validating 23,000 conflicts into models cost 0.06 s of a
    250-robot answer for nothing. A validated body is written as the model."""
    return graph if isinstance(graph, dict) else handler(graph)


class PathsScheduleResponse(BaseModel):
    """Body of a successful paths-form ``POST /v1/schedules``.

    ``schedule``, ``cost`` and ``costs`` describe the returned trajectories: what
    will happen when they are executed.
    """

    objective: Objective
    cost: float
    costs: CostsOut
    assignment: list[AssignmentOut]
    schedule: list[RobotScheduleOut]
    solver: SolverInfoOut
    checks: MotionChecksOut
    graph: ScheduleRequest | None
    node_spans: dict[str, tuple[float, float]]
    trajectories: list[TrajectoryOut]
    dependencies: list[Dependency]
    timings: TimingsOut

    serialize_graph = field_serializer("graph", mode="wrap")(_graph_as_built)


class CoordinationGraphResponse(BaseModel):
    """Body of ``POST /v1/coordination-graphs``: the derived graph and where its nodes lie."""

    graph: ScheduleRequest | None
    node_spans: dict[str, tuple[float, float]]
    isolated_robots: list[str]

    serialize_graph = field_serializer("graph", mode="wrap")(_graph_as_built)


class DisturbanceIn(BaseModel):
    """From ``start`` for ``duration`` seconds, robot ``robot`` moves at ``factor`` of its speed.

    ``factor`` 0 (the default) is a stop; a stop from the robot's start time is a late start.
    """

    model_config = ConfigDict(extra="forbid")

    robot: Id
    start: Time
    duration: float = Field(gt=0.0, le=MAX_TIME, allow_inf_nan=False)
    factor: float = Field(default=0.0, ge=0.0, lt=1.0, allow_inf_nan=False)


class TrajectoryIn(BaseModel):
    """Timed waypoints ``[t, x, y]`` of one robot to play back (times non-decreasing)."""

    model_config = ConfigDict(extra="forbid")

    robot: Id
    points: list[tuple[Time, Coordinate, Coordinate]] = Field(min_length=1)

    @field_validator("points")
    @classmethod
    def _ordered(cls, points: list[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
        """Waypoint times may repeat (an instant) but never go back."""
        for k in range(1, len(points)):
            if points[k][0] < points[k - 1][0]:
                raise ValueError(f"points[{k}] has time {points[k][0]} < points[{k - 1}]'s")
        return points


class SimulationRequest(BaseModel):
    """Body of ``POST /v1/simulations``: play back trajectories, or execute a dependency plan.

    Exactly one of ``trajectories`` (playback) and ``dependencies`` (execution, with
    optional ``disturbances``) is given, for the robots of ``robots``.
    """

    model_config = ConfigDict(extra="forbid")

    robots: list[PathRobotIn] = Field(min_length=1)
    trajectories: list[TrajectoryIn] | None = None
    dependencies: list[Dependency] | None = None
    disturbances: list[DisturbanceIn] = Field(default_factory=list)

    @model_validator(mode="after")
    def _one_mode(self) -> SimulationRequest:
        """Playback or execution, not both; disturbances only disturb an execution."""
        if (self.trajectories is None) == (self.dependencies is None):
            raise ValueError("give exactly one of 'trajectories' and 'dependencies'")
        if self.trajectories is not None and self.disturbances:
            raise ValueError("'disturbances' apply to 'dependencies' (an execution), not playback")
        return self


class OverlapOut(BaseModel):
    """Two footprints overlapping: the deepest moment of one pair."""

    robots: tuple[str, str]
    time: float
    gap_m: float


class SimulationResponse(BaseModel):
    """What the run did: clearance, overlaps, deadlocks, completion times, trajectories."""

    collision_free: bool
    min_clearance_m: float | None
    overlaps: list[OverlapOut]
    deadlocked: list[str]
    completion: dict[str, float | None]
    trajectories: list[TrajectoryOut]
