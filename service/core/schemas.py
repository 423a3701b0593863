"""Wire models of the v1 schedule contract (request and response).

These pydantic models check everything that can be checked field by field
(types, ranges, unknown fields); rules that span several fields (ids, node
order, pair times inside their node, cliques) are checked when the request is
turned into a :class:`service.core.problem.Problem`.
"""

from __future__ import annotations

from typing import Annotated, Literal, NotRequired, get_args

from pydantic import BaseModel, ConfigDict, Field, with_config
from typing_extensions import TypedDict

__all__ = [
    "MAX_COUNT",
    "MAX_TIME",
    "MAX_TIME_LIMIT_S",
    "OBJECTIVES",
    "SOLVER_NAMES",
    "Objective",
    "SolverName",
    "NodeIn",
    "RobotIn",
    "ConflictIn",
    "DensityLimitIn",
    "OptionsIn",
    "PreviousConflictIn",
    "RobotProgressIn",
    "ProgressIn",
    "ScheduleRequest",
    "AssignmentOut",
    "NodeTimesOut",
    "RobotScheduleOut",
    "SolverInfoOut",
    "ChecksOut",
    "CostsOut",
    "WaitAfterTime",
    "WaitPointTime",
    "DependencyTime",
    "ScheduleResponse",
]

# Times above this are rejected: ~31.7 years in seconds. It keeps integer-scaled
# times of the exact solver far from int64 overflow while allowing any real time scale.
MAX_TIME = 1e9
# The longest solve a request may ask for (options.time_limit_s), in seconds.
MAX_TIME_LIMIT_S = 300.0
# The largest density or max_robots: far above any fleet the size caps admit (5000 robots),
# so it never binds a real problem, and its budget rho (rho + 1) / 2 stays far inside int64.
MAX_COUNT = 1_000_000

Objective = Literal["avg_completion", "max_completion", "sync_completion", "avg_delay"]
OBJECTIVES: tuple[Objective, ...] = (
    "avg_completion",
    "max_completion",
    "sync_completion",
    "avg_delay",
)
SolverName = Literal[
    "auto",
    "exact",
    "fcfs",
    "gnn_vae",
    "gnn_vae_refined",
    "gnn_vae_exact",
    "random",
    "tabu",
    "priority_tabu",
    "lns",
    "reinsert",
    "cmaes",
    "bbts",
]
SOLVER_NAMES: tuple[SolverName, ...] = get_args(SolverName)

Time = Annotated[float, Field(strict=True, ge=0.0, le=MAX_TIME, allow_inf_nan=False)]
Count = Annotated[int, Field(strict=True, ge=1, le=MAX_COUNT)]
MAX_ID_LENGTH = 200
Id = Annotated[str, Field(min_length=1, max_length=MAX_ID_LENGTH)]


class _Strict(BaseModel):
    """Base of request models: unknown fields are errors, not silently ignored."""

    model_config = ConfigDict(extra="forbid")


class NodeIn(_Strict):
    """One merged interfering interval of a robot's path."""

    id: Id
    enter: Time
    exit: Time
    density: Count = 1


class RobotIn(_Strict):
    """A robot with its nodes in path order and an optional goal time."""

    id: Id
    nodes: list[NodeIn] = Field(min_length=1)
    goal_time: Time | None = None


# Conflicts and density limits are TypedDicts, not models: a 250-robot request holds
# ~22,000 conflicts and ~11,600 limits, and pydantic-core validates them into plain dicts
# where it built a model for each: the whole request (wh_two_way/250/0, 3.8 MB) 124-126 ms
# -> 65-71 ms (session 61, least of 15). Read them by key; optional keys may be absent.
@with_config(ConfigDict(extra="forbid"))
class ConflictIn(TypedDict):
    """An interfering pair of nodes of two robots, with the pair's own section times.

    ``first`` fixes the direction in advance (that side passes first, e.g. a robot
    parked inside the other's route, or a decision already realized); the type
    stays free. Absent or None leaves the direction to the solver; an absent time is
    its node's.
    """

    a: Id
    b: Id
    a_enter: NotRequired[Time | None]
    a_exit: NotRequired[Time | None]
    b_enter: NotRequired[Time | None]
    b_exit: NotRequired[Time | None]
    first: NotRequired[Literal["a", "b"] | None]


@with_config(ConfigDict(extra="forbid"))
class DensityLimitIn(TypedDict):
    """An explicit clique of nodes in which at most ``max_robots`` robots may crowd."""

    nodes: Annotated[list[Id], Field(min_length=2)]
    max_robots: Count


class OptionsIn(_Strict):
    """How to solve: which solver, how long, which seed, how many samples."""

    solver: SolverName = "auto"
    time_limit_s: float | None = Field(default=None, gt=0.0, le=MAX_TIME_LIMIT_S, strict=True)
    seed: int = Field(default=0, ge=0, le=2**31 - 1, strict=True)
    samples: int | None = Field(default=None, ge=1, le=1000, strict=True)


class PreviousConflictIn(_Strict):
    """One decision of the answer being executed (an ``assignment`` entry of that answer)."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)

    from_: Id = Field(alias="from")
    to: Id
    type: Literal["exclusive", "following"]


class RobotProgressIn(_Strict):
    """How far one robot got: every time point planned at or before ``passed_until`` is
    passed, and from now on it runs at least ``delay`` seconds behind its planned times."""

    passed_until: Time = 0.0
    delay: Time = 0.0


class ProgressIn(_Strict):
    """The fleet's state at ``time`` (same clock as the planned times); robots not listed
    have not started."""

    time: Time
    robots: dict[Id, RobotProgressIn] = Field(default_factory=dict)


class ScheduleRequest(_Strict):
    """Body of ``POST /v1/schedules``: a coordination skeleton graph to schedule.

    With ``progress`` (and optionally ``previous``, the assignment being executed) it is a
    re-schedule from ``progress.time`` on: decisions already realized stay fixed, the rest
    may change (docs/contract.md, Re-scheduling).
    """

    objective: Objective = "avg_completion"
    robots: list[RobotIn] = Field(min_length=1)
    conflicts: list[ConflictIn] = Field(default_factory=list)
    density_limits: list[DensityLimitIn] = Field(default_factory=list)
    options: OptionsIn = Field(default_factory=OptionsIn)
    previous: list[PreviousConflictIn] | None = None
    progress: ProgressIn | None = None


# The decision for one conflict: who passes first (``from``), and how. A TypedDict (the
# key ``from`` is a keyword, hence the functional form): a 250-robot answer has ~20,000
# of them, validated in pydantic-core in 6 ms where models took 56 ms.
AssignmentOut = TypedDict(
    "AssignmentOut",
    {"from": str, "to": str, "type": Literal["exclusive", "following"]},
)


class NodeTimesOut(BaseModel):
    """A node's updated (least) enter and exit times."""

    id: str
    enter: float
    exit: float


class RobotScheduleOut(BaseModel):
    """One robot's updated completion time, final delay and node times."""

    robot: str
    completion: float
    delay: float
    nodes: list[NodeTimesOut]


class SolverInfoOut(BaseModel):
    """Which solver answered, whether it proved optimality, and how long it took."""

    name: str
    optimal: bool
    runtime_s: float
    model: str | None = None
    samples: int | None = None
    fallback_from: str | None = None
    detail: str | None = None


class ChecksOut(BaseModel):
    """Results of the independent constraint checker on the returned assignment."""

    acyclic: bool
    density: bool
    forced: bool = True  # every fixed direction (a conflict's ``first``) is honoured


class CostsOut(BaseModel):
    """All four objectives evaluated on the returned assignment."""

    avg_completion: float
    max_completion: float
    sync_completion: float
    avg_delay: float


# Dependency plans are plain dicts (TypedDict): thousands of entries per answer are
# validated in pydantic-core when the response is assembled.
@with_config(ConfigDict(extra="forbid"))
class WaitAfterTime(TypedDict):
    """Robot ``robot`` must have passed its time point planned at ``time``."""

    robot: Id
    time: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]


@with_config(ConfigDict(extra="forbid"))
class WaitPointTime(TypedDict):
    """A time point (planned at ``time``) where a robot may have to wait until every robot
    of ``after`` has passed its point."""

    time: Annotated[float, Field(ge=0.0, allow_inf_nan=False)]
    after: list[WaitAfterTime]


@with_config(ConfigDict(extra="forbid"))
class DependencyTime(TypedDict):
    """One robot's dependency plan, graph form: its wait points in path order."""

    robot: Id
    waits: list[WaitPointTime]


class ScheduleResponse(BaseModel):
    """Body of a successful ``POST /v1/schedules``."""

    objective: Objective
    cost: float
    costs: CostsOut
    assignment: list[AssignmentOut]
    schedule: list[RobotScheduleOut]
    solver: SolverInfoOut
    checks: ChecksOut
    dependencies: list[DependencyTime] = Field(default_factory=list)
