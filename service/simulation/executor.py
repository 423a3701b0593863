"""The kinematic executor: robots drive their paths and wait where their dependencies say.

A :class:`DependencyPlan` is a list of constraints "robot ``waiter`` may not pass
arc length ``wait_s`` until robot ``waitee`` has reached arc length ``until_s``"
(a robot that has finished has reached every point). Each robot drives its path
at its planned speed, from its start time (where it is present, standing at its
first point), as far as its unsatisfied constraints allow, and waits exactly at
the nearest blocking ``wait_s``. Disturbances (:mod:`.disturbances`) slow or stop
robots. The run is event-driven and exact (no time step): events are a robot
reaching a wait point, a release threshold or its goal.

Executing a plan built from an acyclic schedule never deadlocks (docs/paths.md);
should it happen anyway, the run reports the robots that never finished.

A run can be paused at a wall time (:meth:`Execution.advance` returns each
robot's :class:`State`) and continued under another plan
(:meth:`Execution.replace_plan`): what re-scheduling while robots move needs.
Constraints of the new plan whose waiter is already past its wait point are moot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba.typed import List

from service.geometry.paths import RobotPath
from service.simulation.disturbances import Rate
from service.simulation.event_loop import (
    RECORD,
    Loop,
    catch_up,
    clocks_at,
    push_starts,
    reach_all,
    run_until,
    schedule_all,
    waypoints,
)

__all__ = ["DependencyPlan", "Execution", "Run", "State", "execute", "on_clock"]


@dataclass(frozen=True, eq=False)
class DependencyPlan:
    """Constraints: ``waiter`` may not pass ``wait_s`` until ``waitee`` has reached ``until_s``.

    Shapes: D constraints, arc lengths in metres on each robot's own path.
    """

    waiter: np.ndarray  # (D,) int
    wait_s: np.ndarray  # (D,) float
    waitee: np.ndarray  # (D,) int
    until_s: np.ndarray  # (D,) float

    @classmethod
    def empty(cls) -> DependencyPlan:
        return cls(*(np.zeros(0, dtype=t) for t in (np.int64, float, np.int64, float)))

    @property
    def size(self) -> int:
        return int(self.waiter.size)


@dataclass(frozen=True, eq=False)
class Run:
    """What happened. Per robot r: waypoints (wall time, arc length), motion in between
    follows the planned speed profile scaled by the progress rate."""

    wall: list[np.ndarray]  # R arrays (K_r,) wall times, non-decreasing
    clock: list[np.ndarray]  # R arrays (K_r,) progress clock (planned time) at those walls
    completion: np.ndarray  # (R,) wall time at the last point; NaN if it never got there
    deadlocked: tuple[int, ...]  # robots that never finished

    def arcs(self, paths: Sequence[RobotPath]) -> list[np.ndarray]:
        """(K_r,) arc length at every waypoint of every robot."""
        return [p.arc_at(c) for p, c in zip(paths, self.clock, strict=True)]


@dataclass(frozen=True, eq=False)
class State:
    """Where every robot stands at wall time ``time`` of a paused run. Shapes: R robots.

    ``clock`` is each robot's progress clock, the planned time of where it is (its
    start time before it starts, its finish time once done).
    """

    time: float
    clock: np.ndarray  # (R,) float
    started: np.ndarray  # (R,) bool, its start time has come (present on the floor)
    done: np.ndarray  # (R,) bool, at its last point
    completion: np.ndarray  # (R,) wall time at the last point; NaN while not done

    def arcs(self, paths: Sequence[RobotPath]) -> np.ndarray:
        """(R,) arc length where each robot stands."""
        return np.array([p.arc_at(c) for p, c in zip(paths, self.clock.tolist(), strict=True)])


class Execution:
    """One run that can be paused at a wall time and continued under another plan.

    ``execute(paths, plan, rates)`` is ``Execution(paths, plan, rates).finish()``.
    Re-scheduling pauses the run (:meth:`advance`), reads the :class:`State`, and
    continues from that state with a new plan (:meth:`replace_plan`); disturbances
    (``rates``) belong to the world and stay. The event loop itself is compiled
    (:mod:`.event_loop`); this class loads plans into it and reads results out.
    """

    def __init__(
        self, paths: Sequence[RobotPath], plan: DependencyPlan, rates: Sequence[Rate] | None = None
    ):
        self.paths = paths
        rates = list(rates) if rates is not None else [Rate()] * len(paths)
        self.now = -np.inf  # wall time the run has been advanced to
        start = np.array([p.start_time for p in paths], dtype=np.float64)  # (R,)
        pieces = np.array([rate.value.size for rate in rates], dtype=np.int64)  # (R,)
        none = DependencyPlan.empty()  # placeholders until the plan is loaded
        self.loop = Loop(
            clock=start.copy(),
            wall=start.copy(),
            target=start.copy(),
            finish_clock=np.array([p.finish_time for p in paths], dtype=np.float64),
            completion=np.full(len(paths), np.nan),
            moving=np.zeros(len(paths), dtype=bool),
            started=np.zeros(len(paths), dtype=bool),
            done=np.zeros(len(paths), dtype=bool),
            rate_start=np.concatenate([[0], np.cumsum(pieces + 1)]),
            rate_edge=np.concatenate([r.edges for r in rates]),
            rate_value=np.concatenate([np.append(r.value, 1.0) for r in rates]),
            **_constraints(len(paths), none.waiter, none.wait_s, none.waitee, none.until_s),
            event_wall=np.zeros(len(paths)),
            event_clock=np.zeros(len(paths)),
            event_start=np.zeros(len(paths), dtype=bool),
            event_seq=np.zeros(len(paths), dtype=np.int64),
            seq=np.zeros(1, dtype=np.int64),
            heap=np.zeros(len(paths), dtype=np.int64),
            heap_size=np.zeros(1, dtype=np.int64),
            heap_pos=np.full(len(paths), -1, dtype=np.int64),
            records=List.empty_list(RECORD),
        )
        self._load(plan)
        push_starts(self.loop, np.arange(len(paths)), start, start)

    @classmethod
    def resume(
        cls,
        paths: Sequence[RobotPath],
        plan: DependencyPlan,
        state: State,
        rates: Sequence[Rate] | None = None,
    ) -> Execution:
        """A run from ``state`` on (robots where a fleet reports them at ``state.time``),
        under ``plan``: a re-scheduled answer executed from now.

        Started robots stand at their clocks at ``state.time`` (constraints whose waiter
        is already past its wait point are moot); done robots keep their completion; the
        others appear at their first point at their start time, or now if that has passed.
        """
        run = cls(paths, DependencyPlan.empty(), rates)
        run.now = state.time
        loop = run.loop
        loop.heap_size[0], loop.heap_pos[:] = 0, -1  # no starts: robots are where they are
        loop.started[:], loop.done[:] = state.started, state.done
        present = state.started | state.done  # (R,)
        for r in np.flatnonzero(present).tolist():
            if state.done[r]:  # one waypoint at its arrival: gone from then on
                loop.clock[r], loop.wall[r] = loop.finish_clock[r], state.completion[r]
                loop.completion[r] = state.completion[r]
            else:
                loop.clock[r], loop.wall[r] = state.clock[r], state.time
            loop.records.append((r, loop.wall[r], loop.clock[r]))
        waiting = np.flatnonzero(~present)  # (W,) appear at their start, or now
        loop.wall[waiting] = np.maximum(loop.clock[waiting], state.time)
        push_starts(loop, waiting, loop.wall[waiting], loop.clock[waiting])
        run._load(plan)
        reach_all(run.loop)
        schedule_all(run.loop, np.flatnonzero(loop.started & ~loop.done))
        return run

    def _load(self, plan: DependencyPlan) -> int:
        """Index ``plan``'s constraints; drop those whose waiter is past its wait point or
        done (moot). Returns how many were dropped."""
        loop = self.loop
        wait_clock = on_clock(self.paths, plan.waiter, plan.wait_s)  # (D,)
        until_clock = on_clock(self.paths, plan.waitee, plan.until_s)  # (D,)
        live = (wait_clock >= loop.clock[plan.waiter]) & ~loop.done[plan.waiter]  # (D,)
        self.loop = loop._replace(
            **_constraints(
                len(self.paths),
                plan.waiter[live],
                wait_clock[live],
                plan.waitee[live],
                until_clock[live],
            )
        )
        return int(plan.size - np.count_nonzero(live))

    @property
    def finished(self) -> bool:
        """Nothing more can happen: every robot is done or waits for ever (deadlock)."""
        return self.loop.heap_size[0] == 0

    def advance(self, until: float) -> State:
        """Run every event up to wall time ``until`` (included) and return the state then."""
        run_until(self.loop, until)
        self.now = until
        return State(
            until,
            clocks_at(self.loop, until),
            self.loop.started.copy(),
            self.loop.done.copy(),
            self.loop.completion.copy(),
        )

    def replace_plan(self, plan: DependencyPlan) -> int:
        """From the time of the last :meth:`advance` on, robots obey ``plan`` instead.

        Constraints whose waiter is already past its wait point are moot and dropped;
        those whose waitee has already reached its point are satisfied. Returns the
        number of moot constraints.
        """
        present = np.flatnonzero(self.loop.started & ~self.loop.done)  # (P,)
        catch_up(self.loop, present, self.now)  # pending events are rescheduled below
        moot = self._load(plan)
        reach_all(self.loop)
        schedule_all(self.loop, present)
        return moot

    def finish(self) -> Run:
        """Run to the end and return what happened."""
        run_until(self.loop, np.inf)
        times_start = np.concatenate([[0], np.cumsum([p.times.size for p in self.paths])])
        robot, wall, clock = waypoints(
            self.loop, np.concatenate([p.times for p in self.paths]), times_start
        )  # (K,) each, grouped by robot
        bounds = np.searchsorted(robot, np.arange(len(self.paths) + 1)).tolist()
        walls, clocks = [], []
        for r in range(len(self.paths)):
            w, c = _linear_pieces(wall[bounds[r] : bounds[r + 1]], clock[bounds[r] : bounds[r + 1]])
            walls.append(w)
            clocks.append(c)
        stuck = tuple(np.flatnonzero(~self.loop.done).tolist())
        return Run(walls, clocks, self.loop.completion.copy(), stuck)


def _constraints(
    n: int, waiter: np.ndarray, wait_clock: np.ndarray, waitee: np.ndarray, until_clock: np.ndarray
) -> dict[str, np.ndarray]:
    """The :class:`Loop` fields of constraints (D,) (progress clocks), none satisfied yet:
    by waiter and wait clock (ties by index), and by waitee and threshold."""
    block = np.lexsort((np.arange(waiter.size), wait_clock, waiter))  # (D,)
    release = np.lexsort((until_clock, waitee))  # (D,)
    block_start = np.searchsorted(waiter[block], np.arange(n + 1))
    release_start = np.searchsorted(waitee[release], np.arange(n + 1))
    return {
        "waiter": waiter,
        "satisfied": np.zeros(waiter.size, dtype=bool),
        "block_start": block_start,
        "block_next": block_start[:-1].copy(),
        "block_clock": wait_clock[block],
        "block_constraint": block,
        "release_start": release_start,
        "next_release": release_start[:-1].copy(),
        "release_clock": until_clock[release],
        "release_constraint": release,
    }


def on_clock(paths: Sequence[RobotPath], robot: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(D,) planned progress clock of each robot[d] at arc length s[d]."""
    out = np.empty(s.size)
    order = np.argsort(robot, kind="stable")
    bounds = np.searchsorted(robot[order], np.arange(len(paths) + 1))
    for r, path in enumerate(paths):
        rows = order[bounds[r] : bounds[r + 1]]
        out[rows] = path.time_at(s[rows])
    return out


def _linear_pieces(wall: np.ndarray, clock: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints (K,) of :func:`~.event_loop.waypoints` in time order, duplicates dropped."""
    order = np.lexsort((clock, wall))
    # A clock computed at a rate edge (c0 + progress) can round one ulp below the one
    # before it; a robot never drives back, so the clock is made non-decreasing.
    wall, clock = wall[order], np.maximum.accumulate(clock[order])
    keep = np.ones(wall.size, dtype=bool)
    keep[1:] = (np.diff(wall) > 0) | (np.diff(clock) > 0)
    return wall[keep], clock[keep]


def execute(
    paths: Sequence[RobotPath], plan: DependencyPlan, rates: Sequence[Rate] | None = None
) -> Run:
    """Run ``plan`` on ``paths`` (optionally disturbed by one :class:`Rate` per robot)."""
    return Execution(paths, plan, rates).finish()
