"""Disturbances of a run: late starts, stops and slow-downs, as a progress rate per robot.

A robot executing a plan follows its planned motion on its own *progress clock*:
moving, its clock advances at rate 1 (it drives at its planned speed); blocked
by a dependency, it stands still and the clock stops. A disturbance changes the
rate over a stretch of wall time: 0 for a stop, ``factor`` < 1 for a slow-down.
A late start is a stop from the planned start time. Rates never exceed 1, so a
disturbed robot is never faster than planned.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Disturbance", "Rate"]


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
        if self.constant:
            return t1 - t0
        lo = np.clip(self.edges[:-1], t0, t1)
        hi = np.clip(self.edges[1:], t0, t1)
        inside = hi - lo  # (K,) wall seconds spent in each piece
        return float((t1 - t0) - inside.sum() + (inside * self.value).sum())

    def advance(self, t0: float, gain: float) -> float:
        """The wall time at which a robot moving from t0 has gained ``gain`` progress seconds."""
        if self.constant or gain <= 0.0:
            return t0 + max(gain, 0.0)
        t, left = t0, gain
        for k in range(self.value.size):
            a, b = self.edges[k], self.edges[k + 1]
            if b <= t:
                continue
            if t < a:  # rate 1 before this piece
                if a - t >= left:
                    return t + left
                left -= a - t
                t = a
            if self.value[k] > 0.0:
                if (b - t) * self.value[k] >= left:
                    return t + left / self.value[k]
                left -= (b - t) * self.value[k]
            t = b
        return t + left

    def breakpoints(self, t0: float, t1: float) -> np.ndarray:
        """Wall times strictly inside (t0, t1) where the rate changes."""
        return self.edges[(self.edges > t0) & (self.edges < t1)]
