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

import heapq
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from service.geometry.paths import RobotPath
from service.simulation.disturbances import Rate

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
    (``rates``) belong to the world and stay.
    """

    def __init__(
        self, paths: Sequence[RobotPath], plan: DependencyPlan, rates: Sequence[Rate] | None = None
    ):
        # State lives in Python lists: the event loop reads single entries, where numpy
        # scalar indexing measured several times slower.
        self.paths = paths
        self.rates = list(rates) if rates is not None else [Rate()] * len(paths)
        n = len(paths)
        self.now = -np.inf  # wall time the run has been advanced to
        self.finish_clock = [p.finish_time for p in paths]
        self.clock = [p.start_time for p in paths]  # progress clock at self.wall
        self.wall = list(self.clock)
        self.moving = [False] * n
        self.started = [False] * n
        self.done = [False] * n
        self.version = [0] * n
        self.target = list(self.clock)  # progress clock of each moving robot's next event
        self.records: list[list[tuple[float, float]]] = [[] for _ in range(n)]
        self.completion = [float("nan")] * n
        self.events: list[tuple[float, int, int, int, float]] = []
        self.seq = 0
        self._load(plan)
        for r, path in enumerate(paths):
            self._push(path.start_time, r, -1, path.start_time)

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
        run.now, run.events = state.time, []
        for r, path in enumerate(paths):
            run.started[r], run.done[r] = bool(state.started[r]), bool(state.done[r])
            if state.done[r]:  # one waypoint at its arrival: gone from then on
                run.clock[r], run.completion[r] = path.finish_time, float(state.completion[r])
                run.wall[r] = run.completion[r]
                run._record(r)
            elif state.started[r]:
                run.clock[r], run.wall[r] = float(state.clock[r]), state.time
                run._record(r)
            else:
                run.wall[r] = max(path.start_time, state.time)
                run._push(run.wall[r], r, -1, path.start_time)
        run._load(plan)
        for r in range(len(paths)):
            if run.started[r]:
                run._reach(r)
        for r in range(len(paths)):
            if run.started[r] and not run.done[r]:
                run._schedule(r)
        return run

    def _load(self, plan: DependencyPlan) -> int:
        """Index ``plan``'s constraints; drop those whose waiter is past its wait point or
        done (moot). Returns how many were dropped."""
        n = len(self.paths)
        wait_clock = on_clock(self.paths, plan.waiter, plan.wait_s)  # (D,)
        until_clock = on_clock(self.paths, plan.waitee, plan.until_s)  # (D,)
        clock, done = np.array(self.clock), np.array(self.done, dtype=bool)  # (R,) each
        live = (wait_clock >= clock[plan.waiter]) & ~done[plan.waiter]  # (D,)
        waitee = plan.waitee[live]  # (D',)
        wait_clock, until_clock = wait_clock[live], until_clock[live]
        self.satisfied = [False] * waitee.size
        self.waiter = plan.waiter[live].tolist()
        # Per waiter, a heap of (wait clock, constraint); its limit is the least unsatisfied.
        self.blocking: list[list[tuple[float, int]]] = [[] for _ in range(n)]
        for c, (w, wc) in enumerate(zip(self.waiter, wait_clock.tolist(), strict=True)):
            self.blocking[w].append((wc, c))
        for heap in self.blocking:
            heapq.heapify(heap)
        # Per waitee, its release thresholds as progress-clock values, sorted.
        order = np.lexsort((until_clock, waitee))
        self.release_order = order.tolist()
        self.release_clock = until_clock[order].tolist()
        self.release_start = np.searchsorted(waitee[order], np.arange(n + 1)).tolist()
        self.next_release = self.release_start[:-1]
        return int(plan.size - waitee.size)

    @property
    def finished(self) -> bool:
        """Nothing more can happen: every robot is done or waits for ever (deadlock)."""
        return not self.events

    def advance(self, until: float) -> State:
        """Run every event up to wall time ``until`` (included) and return the state then."""
        while self.events and self.events[0][0] <= until:
            self._pop()
        self.now = until
        return State(
            until,
            np.array([self._clock_at(r, until) for r in range(len(self.paths))]),
            np.array(self.started, dtype=bool),
            np.array(self.done, dtype=bool),
            np.array(self.completion),
        )

    def replace_plan(self, plan: DependencyPlan) -> int:
        """From the time of the last :meth:`advance` on, robots obey ``plan`` instead.

        Constraints whose waiter is already past its wait point are moot and dropped;
        those whose waitee has already reached its point are satisfied. Returns the
        number of moot constraints.
        """
        present = [r for r in range(len(self.paths)) if self.started[r] and not self.done[r]]
        for r in present:  # bring clocks up to now; pending events are rescheduled below
            self._catch_up(r, self.now)
        moot = self._load(plan)
        for r in range(len(self.paths)):
            if self.started[r]:
                self._reach(r)
        for r in present:
            self._schedule(r)
        return moot

    def finish(self) -> Run:
        """Run to the end and return what happened."""
        while self.events:
            self._pop()
        return self._result()

    def _pop(self) -> None:
        wall, _, r, version, clock = heapq.heappop(self.events)
        if version == -1:
            self._start(r)
        elif version == self.version[r]:
            self._arrive(r, wall, clock)

    def _push(self, wall: float, r: int, version: int, clock: float) -> None:
        heapq.heappush(self.events, (wall, self.seq, r, version, clock))
        self.seq += 1

    def _limit_clock(self, r: int) -> float:
        """Progress clock of robot r's nearest blocking wait point (its finish if none)."""
        heap = self.blocking[r]
        while heap and self.satisfied[heap[0][1]]:
            heapq.heappop(heap)
        return heap[0][0] if heap else self.finish_clock[r]

    def _schedule(self, r: int) -> None:
        """Robot r moves from (wall, clock): push its next event, or stop it at its limit."""
        limit = self._limit_clock(r)
        if limit <= self.clock[r]:
            if self.moving[r]:
                self.moving[r] = False
                self.version[r] += 1  # a new plan may stop it before its pending event
                self._record(r)
            return
        if not self.moving[r]:
            self.moving[r] = True
            self._record(r)
        target = min(limit, self.finish_clock[r])
        k = self.next_release[r]
        if k < self.release_start[r + 1]:
            target = min(target, self.release_clock[k])
        self.version[r] += 1
        self.target[r] = target
        gain = target - self.clock[r]
        self._push(self.rates[r].advance(self.wall[r], gain), r, int(self.version[r]), target)

    def _start(self, r: int) -> None:
        """Robot r appears at its first point at its start time."""
        self.started[r] = True
        self._record(r)
        self._release(r)
        self._schedule(r)

    def _arrive(self, r: int, wall: float, clock: float) -> None:
        """Robot r reached progress ``clock`` at ``wall``: release, finish or go on."""
        self.wall[r], self.clock[r] = wall, clock
        if clock >= self.finish_clock[r]:
            self.done[r], self.moving[r] = True, False
            self.completion[r] = wall
            self._record(r)
        self._release(r)
        if not self.done[r]:
            self._schedule(r)

    def _reach(self, r: int) -> set[int]:
        """Satisfy the constraints robot r has now reached; return their waiters."""
        k, end = self.next_release[r], self.release_start[r + 1]
        waiters: set[int] = set()
        while k < end and (self.done[r] or self.release_clock[k] <= self.clock[r]):
            c = self.release_order[k]
            self.satisfied[c] = True
            waiters.add(self.waiter[c])
            k += 1
        self.next_release[r] = k
        return waiters

    def _release(self, r: int) -> None:
        """Satisfy the constraints robot r has now reached and update their waiters."""
        for w in sorted(self._reach(r)):
            self._wake(w, self.wall[r])

    def _clock_at(self, r: int, wall: float) -> float:
        """Robot r's progress clock at ``wall`` (never past its pending event: rounding of
        advance/progress)."""
        if not self.moving[r]:
            return self.clock[r]
        return min(self.clock[r] + self.rates[r].progress(self.wall[r], wall), self.target[r])

    def _catch_up(self, r: int, wall: float) -> None:
        """Bring robot r's clock up to ``wall``."""
        self.clock[r] = self._clock_at(r, wall)
        self.wall[r] = wall

    def _wake(self, w: int, wall: float) -> None:
        """Robot w's limit may have moved on at ``wall``: bring it up to date and reschedule."""
        if not self.started[w] or self.done[w]:
            return
        self._catch_up(w, wall)
        self._schedule(w)

    def _record(self, r: int) -> None:
        self.records[r].append((float(self.wall[r]), float(self.clock[r])))

    def _result(self) -> Run:
        walls, clocks = [], []
        for r, path in enumerate(self.paths):
            wall, clock = _expand(self.records[r], path, self.rates[r])
            walls.append(wall)
            clocks.append(clock)
        stuck = tuple(r for r, done in enumerate(self.done) if not done)
        return Run(walls, clocks, np.array(self.completion), stuck)


def on_clock(paths: Sequence[RobotPath], robot: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(D,) planned progress clock of each robot[d] at arc length s[d]."""
    out = np.empty(s.size)
    order = np.argsort(robot, kind="stable")
    bounds = np.searchsorted(robot[order], np.arange(len(paths) + 1))
    for r, path in enumerate(paths):
        rows = order[bounds[r] : bounds[r + 1]]
        out[rows] = path.time_at(s[rows])
    return out


def _expand(
    records: list[tuple[float, float]], path: RobotPath, rate: Rate
) -> tuple[np.ndarray, np.ndarray]:
    """Waypoints (wall, clock) between which motion is linear in the plane.

    Between two records a robot either stood still (equal clocks) or moved; inside
    a move, path vertices (speed or heading changes) and rate changes are added.
    """
    walls: list[float] = []
    clocks: list[float] = []
    for (w0, c0), (w1, c1) in zip(records[:-1], records[1:], strict=True):
        walls.append(w0)
        clocks.append(c0)
        if c1 <= c0:
            continue
        inner_clock = path.times[(path.times > c0) & (path.times < c1)]
        inner_wall = [rate.advance(w0, c - c0) for c in inner_clock]
        bp = rate.breakpoints(w0, w1)
        walls.extend(inner_wall + bp.tolist())
        clocks.extend(inner_clock.tolist() + [c0 + rate.progress(w0, b) for b in bp])
    if records:
        walls.append(records[-1][0])
        clocks.append(records[-1][1])
    wall, clock = np.asarray(walls), np.asarray(clocks)
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
