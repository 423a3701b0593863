"""Disturbances of a run: late starts, stops and slow-downs, as a progress rate per robot.

A robot executing a plan follows its planned motion on its own *progress clock*:
moving, its clock advances at rate 1 (it drives at its planned speed); blocked
by a dependency, it stands still and the clock stops. A disturbance changes the
rate over a stretch of wall time: 0 for a stop, ``factor`` < 1 for a slow-down.
A late start is a stop from the planned start time. Rates never exceed 1, so a
disturbed robot is never faster than planned.

**Profiles** (:data:`PROFILES`) draw seeded disturbances for benchmarks. Each robot
is hit by each kind of disturbance independently with probability ``share``,
once; the duration is exponential with mean ``mean_s``; a stop or slow-down
begins at a wall time uniform over the robot's window (its start to its
undisturbed completion), a late start at its start time; a slow-down's factor is
uniform over ``factor``:

=========  ==================  ==================  =================================
profile    late start          stop                slow-down
=========  ==================  ==================  =================================
none       (none: the control)
light      10 %, mean 5 s      10 %, mean 5 s      10 %, mean 10 s, factor 0.5-0.9
heavy      30 %, mean 20 s     30 %, mean 20 s     30 %, mean 30 s, factor 0.2-0.6
=========  ==================  ==================  =================================

:func:`played_by_clock` is what a robot does that plays back a timed trajectory
by its clock when disturbed: it falls behind and never catches up.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numba
import numpy as np

from service.simulation.clearance import Trajectory

__all__ = [
    "PROFILES",
    "Disturbance",
    "Hazard",
    "Profile",
    "Rate",
    "Window",
    "advance",
    "played_by_clock",
    "progress",
    "rates_of",
]


@dataclass(frozen=True)
class Disturbance:
    """From wall time ``start`` for ``duration`` seconds, robot ``robot`` moves at ``factor``.

    ``factor`` 0 is a stop, 0 < factor < 1 a slow-down.
    """

    robot: str
    start: float
    duration: float
    factor: float = 0.0


@dataclass(frozen=True, eq=False)
class Rate:
    """A piecewise-constant progress rate over wall time (1 outside the pieces).

    Shapes: K pieces, ``edges`` (K+1,) sorted wall times, ``value`` (K,) the rate
    on ``[edges[k], edges[k+1])``.
    """

    edges: np.ndarray = field(default_factory=lambda: np.zeros(1))
    value: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @classmethod
    def of(cls, pieces: list[tuple[float, float, float]]) -> Rate:
        """From (start, duration, factor) pieces; overlaps take the smallest factor."""
        if not pieces:
            return cls()
        edges = np.unique([t for s, d, _ in pieces for t in (s, s + d)])
        value = np.ones(edges.size - 1)
        mids = (edges[:-1] + edges[1:]) / 2
        for start, duration, factor in pieces:
            inside = (mids >= start) & (mids < start + duration)
            value[inside] = np.minimum(value[inside], factor)
        return cls(edges, value)

    @property
    def constant(self) -> bool:
        return self.value.size == 0

    def progress(self, t0: float, t1: float) -> float:
        """Progress-clock seconds gained moving from wall time t0 to t1 >= t0."""
        return float(progress(self.edges, self.value, 0, self.value.size, t0, t1))

    def advance(self, t0: float, gain: float) -> float:
        """The wall time at which a robot moving from t0 has gained ``gain`` progress seconds."""
        return float(advance(self.edges, self.value, 0, self.value.size, t0, gain))

    def breakpoints(self, t0: float, t1: float) -> np.ndarray:
        """Wall times strictly inside (t0, t1) where the rate changes."""
        return self.edges[(self.edges > t0) & (self.edges < t1)]


@numba.njit(cache=True, nogil=True, inline="always")
def progress(
    edges: np.ndarray, value: np.ndarray, first: int, pieces: int, t0: float, t1: float
) -> float:
    """Progress-clock seconds gained from wall time t0 to t1 >= t0 at a piecewise rate:
    ``value[first + k]`` on ``[edges[first + k], edges[first + k + 1])`` for k < ``pieces``,
    1 outside (arrays that hold several rates: the executor's, one per robot)."""
    inside, weighted = 0.0, 0.0  # wall seconds spent in the pieces, and progress there
    for k in range(first, first + pieces):
        a = min(max(edges[k], t0), t1)
        b = min(max(edges[k + 1], t0), t1)
        inside += b - a
        weighted += (b - a) * value[k]
    return (t1 - t0) - inside + weighted


@numba.njit(cache=True, nogil=True, inline="always")
def advance(
    edges: np.ndarray, value: np.ndarray, first: int, pieces: int, t0: float, gain: float
) -> float:
    """The wall time at which a robot moving from t0 at the piecewise rate of
    :func:`progress` has gained ``gain`` progress seconds."""
    if gain <= 0.0:
        return t0
    t, left = t0, gain
    for k in range(first, first + pieces):
        a, b = edges[k], edges[k + 1]
        if b <= t:
            continue
        if t < a:  # rate 1 before this piece
            if a - t >= left:
                return t + left
            left -= a - t
            t = a
        if value[k] > 0.0:
            if (b - t) * value[k] >= left:
                return t + left / value[k]
            left -= (b - t) * value[k]
        t = b
    return t + left


def rates_of(ids: Sequence[str], disturbances: Sequence[Disturbance]) -> list[Rate]:
    """One progress rate per robot of ``ids`` (in that order) from ``disturbances``."""
    pieces: dict[str, list[tuple[float, float, float]]] = {rid: [] for rid in ids}
    for d in disturbances:
        pieces[d.robot].append((d.start, d.duration, d.factor))
    return [Rate.of(pieces[rid]) for rid in ids]


def played_by_clock(traj: Trajectory, rate: Rate) -> Trajectory:
    """``traj`` played back by a clock that runs at ``rate`` (a robot that follows its
    timed trajectory and is stopped or slowed: it falls behind and never catches up).

    At wall time t the robot is where ``traj`` is at its own time
    ``t0 + rate.progress(t0, t)``, t0 its first time; waits in ``traj`` are played
    back too. Shapes: K waypoints -> K + (rate changes during the playback).
    """
    t0 = float(traj.t[0])
    walls = np.array([rate.advance(t0, float(t) - t0) for t in traj.t])  # (K,)
    edges = rate.breakpoints(t0, float(walls[-1]))  # (E,) rate changes during the playback
    own = t0 + np.array([rate.progress(t0, float(b)) for b in edges])  # (E,) traj time then
    xy = np.column_stack([np.interp(own, traj.t, traj.xy[:, k]) for k in (0, 1)])  # (E, 2)
    wall = np.concatenate([walls, edges])
    order = np.argsort(wall, kind="stable")
    return Trajectory(wall[order], np.concatenate([traj.xy, xy])[order], traj.radius)


Window = tuple[str, float, float]  # robot id, wall times from which and until which it is hit


@dataclass(frozen=True)
class Hazard:
    """One kind of disturbance of a profile: each robot is hit with probability ``share``
    (independently, once), for an exponential duration of mean ``mean_s`` seconds, at a
    rate factor uniform over ``factor`` (0 is a stop)."""

    share: float
    mean_s: float
    factor: tuple[float, float] = (0.0, 0.0)

    def draw(
        self, rng: np.random.Generator, ids: Sequence[str], start: np.ndarray
    ) -> list[Disturbance]:
        """Disturbances of the robots hit, beginning at ``start`` (R,) wall times."""
        n = len(ids)
        hit = rng.random(n) < self.share  # (R,) every draw is made, hit or not: the stream
        duration = rng.exponential(self.mean_s, n)  # of one kind never depends on the others
        factor = rng.uniform(*self.factor, n)
        return [
            Disturbance(ids[r], float(start[r]), float(duration[r]), float(factor[r]))
            for r in np.flatnonzero(hit).tolist()
        ]


@dataclass(frozen=True)
class Profile:
    """Late starts, stops and slow-downs, each a :class:`Hazard` (table in the module doc)."""

    late_start: Hazard
    stop: Hazard
    slow_down: Hazard

    @property
    def quiet(self) -> bool:
        """It hits nobody: every draw is empty (one run tells all)."""
        return not any(h.share for h in (self.late_start, self.stop, self.slow_down))

    def draw(self, windows: Sequence[Window], seed: int) -> list[Disturbance]:
        """Seeded disturbances of the robots of ``windows``: late starts at each window's
        start, stops and slow-downs beginning uniformly inside it."""
        rng = np.random.default_rng(seed)
        ids = [w[0] for w in windows]
        begin = np.array([w[1] for w in windows], dtype=float)  # (R,)
        end = np.maximum(np.array([w[2] for w in windows], dtype=float), begin)  # (R,)
        out = self.late_start.draw(rng, ids, begin)
        out += self.stop.draw(rng, ids, rng.uniform(begin, end))
        out += self.slow_down.draw(rng, ids, rng.uniform(begin, end))
        return out


# Benchmark profiles (issue 12): "light" is a few seconds for about one robot in ten per
# kind (a person crossing, a slow turn), "heavy" tens of seconds for a third (a blocked
# aisle, a manual intervention). Chosen for the benchmark, not measured on a fleet.
# "none" is the control: what re-scheduling does without any disturbance.
PROFILES = {
    "none": Profile(Hazard(0.0, 1.0), Hazard(0.0, 1.0), Hazard(0.0, 1.0)),
    "light": Profile(Hazard(0.1, 5.0), Hazard(0.1, 5.0), Hazard(0.1, 10.0, (0.5, 0.9))),
    "heavy": Profile(Hazard(0.3, 20.0), Hazard(0.3, 20.0), Hazard(0.3, 30.0, (0.2, 0.6))),
}
