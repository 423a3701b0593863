"""Pure numpy helpers the three pictures share: polylines by arc length, trajectories by time.

Nothing here draws; every function takes plain arrays so that it can be tested on
exact cases. Polylines are ``(n, 2)`` arrays of ``[x, y]`` (metres); trajectories
are ``(n, 3)`` arrays of timed waypoints ``[t, x, y]`` with non-decreasing ``t``
and linear motion between consecutive waypoints.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "POSITION_TOLERANCE_M",
    "cumulative_lengths",
    "point_at_length",
    "sub_polyline",
    "positions_at",
    "wait_intervals",
]

# Two waypoints closer than this are the same position (a wait): JSON round trips of
# the service's float64 coordinates move them by far less than a micrometre.
POSITION_TOLERANCE_M = 1e-6


def cumulative_lengths(path: np.ndarray) -> np.ndarray:
    """Arc length at each vertex of a polyline, starting at 0.

    Shapes: ``path (n, 2)`` -> ``(n,)``.
    """
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    return np.concatenate(([0.0], np.cumsum(steps)))


def point_at_length(path: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """Points at arc lengths ``s`` along a polyline (clipped to its ends).

    Shapes: ``path (n, 2)``, ``s (k,)`` -> ``(k, 2)``; a scalar ``s`` gives ``(2,)``.
    """
    lengths = cumulative_lengths(path)
    return np.stack((np.interp(s, lengths, path[:, 0]), np.interp(s, lengths, path[:, 1])), axis=-1)


def sub_polyline(path: np.ndarray, s_start: float, s_end: float) -> np.ndarray:
    """The part of a polyline between arc lengths ``s_start`` and ``s_end``.

    Keeps the vertices strictly inside the interval so that the piece follows the
    path's corners; both ends are clipped to the path. Used to draw where a
    coordination-graph node lies on its robot's path.

    Shapes: ``path (n, 2)`` -> ``(m, 2)`` with ``m >= 2``.
    """
    lengths = cumulative_lengths(path)
    s_start, s_end = np.clip(sorted((s_start, s_end)), 0.0, lengths[-1])
    inside = (lengths > s_start) & (lengths < s_end)
    ends = point_at_length(path, np.array([s_start, s_end]))
    return np.vstack((ends[:1], path[inside], ends[1:]))


def positions_at(points: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of a robot at ``times``, and whether it is present then.

    A robot is present from its first waypoint's time to its last one's; outside
    that span its position is that of the nearest end (and ``present`` is False).

    Shapes: ``points (n, 3)``, ``times (k,)`` -> positions ``(k, 2)``, present ``(k,)``.
    """
    t = points[:, 0]
    xy = np.stack((np.interp(times, t, points[:, 1]), np.interp(times, t, points[:, 2])), axis=-1)
    return xy, (times >= t[0]) & (times <= t[-1])


def wait_intervals(
    points: np.ndarray, completion: float | None = None
) -> list[tuple[float, float]]:
    """Time intervals in which a robot stands still before it has finished.

    A wait is a run of consecutive waypoints at the same position with increasing
    time; touching runs are merged. Standing at the goal after ``completion``
    (default: the last waypoint's time) is not a wait, so intervals are clipped
    to it.

    Shapes: ``points (n, 3)`` -> list of ``(start, end)`` with ``start < end``.
    """
    end = points[-1, 0] if completion is None else completion
    still = np.linalg.norm(np.diff(points[:, 1:], axis=0), axis=1) <= POSITION_TOLERANCE_M
    intervals: list[tuple[float, float]] = []
    for k in np.flatnonzero(still):
        start, stop = float(points[k, 0]), float(min(points[k + 1, 0], end))
        if stop <= start:
            continue
        if intervals and intervals[-1][1] == start:
            start = intervals.pop()[0]
        intervals.append((start, stop))
    return intervals
