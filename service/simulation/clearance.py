"""The one clearance check: do executed trajectories keep every two footprints apart?

Independent of how trajectories were made (it reads only timed waypoints and
radii): for every two robots present at the same time and near each other
(broad phase: STRtree over trajectory bounding boxes), it merges their waypoint
times and, on each interval where both move linearly, finds the least centre
distance in closed form (numba). A robot counts as present from its first
waypoint's time to its last, both included (stricter than "gone at its goal").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
import shapely

__all__ = ["Clearance", "Trajectory", "check_clearance"]

# Overlap tolerance, metres: gaps above -TOLERANCE count as clear (floating-point rounding
# of positions interpolated from times of order 1e5 s).
TOLERANCE = 1e-6


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Timed waypoints of one disk robot; linear motion in between. Shapes: K waypoints."""

    t: np.ndarray  # (K,) non-decreasing
    xy: np.ndarray  # (K, 2)
    radius: float


@dataclass(frozen=True)
class Clearance:
    """Least gap (centre distance minus radii) over all pairs present together, and where."""

    min_gap: float | None  # None when no two robots are ever present together nearby
    pair: tuple[int, int] | None
    time: float | None
    overlaps: tuple[tuple[int, int, float, float], ...]  # (i, j, time, gap) with gap < -TOL

    @property
    def ok(self) -> bool:
        return not self.overlaps


@numba.njit(cache=True, nogil=True)
def _pair_min_gap(
    ta: np.ndarray, pa: np.ndarray, tb: np.ndarray, pb: np.ndarray, radii: float
) -> tuple[float, float]:
    """Least centre distance minus ``radii`` of two waypoint lists over their common time,
    and when. (inf, nan) if they are never present together. Scalar arithmetic only: the
    kernel runs for every nearby pair of every answer."""
    t0, t1 = max(ta[0], tb[0]), min(ta[-1], tb[-1])
    if t0 > t1:
        return np.inf, np.nan
    ia = max(np.searchsorted(ta, t0, side="right") - 1, 0)
    ib = max(np.searchsorted(tb, t0, side="right") - 1, 0)
    best, when, t = np.inf, np.nan, t0
    while True:
        na = ta[ia + 1] if ia + 1 < ta.size else np.inf
        nb = tb[ib + 1] if ib + 1 < tb.size else np.inf
        u = min(na, nb, t1)
        ax0, ay0 = _at(ta, pa, ia, t)
        ax1, ay1 = _at(ta, pa, ia, u)
        bx0, by0 = _at(tb, pb, ib, t)
        bx1, by1 = _at(tb, pb, ib, u)
        dx, dy = ax0 - bx0, ay0 - by0  # relative position, linear from (dx, dy) at t ...
        ex, ey = ax1 - bx1 - dx, ay1 - by1 - dy  # ... by (ex, ey) until u
        denom = ex * ex + ey * ey
        f = 0.0 if denom <= 0.0 else min(1.0, max(0.0, -(dx * ex + dy * ey) / denom))
        gap = np.sqrt((dx + f * ex) ** 2 + (dy + f * ey) ** 2) - radii
        if gap < best:
            best, when = gap, t + f * (u - t)
        if u >= t1:
            return best, when
        if na <= u:
            ia += 1
        if nb <= u:
            ib += 1
        t = u


@numba.njit(cache=True, nogil=True)
def _at(ts: np.ndarray, ps: np.ndarray, k: int, t: float) -> tuple[float, float]:
    """Position (x, y) at time t on the waypoint interval k (clamped to its ends)."""
    if k + 1 >= ts.size or ts[k + 1] <= ts[k]:
        return ps[k, 0], ps[k, 1]
    f = min(1.0, max(0.0, (t - ts[k]) / (ts[k + 1] - ts[k])))
    return ps[k, 0] + f * (ps[k + 1, 0] - ps[k, 0]), ps[k, 1] + f * (ps[k + 1, 1] - ps[k, 1])


def check_clearance(trajectories: Sequence[Trajectory]) -> Clearance:
    """Check every two trajectories for overlapping footprints while both are present."""
    if len(trajectories) < 2:
        return Clearance(None, None, None, ())
    lo = np.array([tr.xy.min(axis=0) - tr.radius for tr in trajectories])  # (R, 2)
    hi = np.array([tr.xy.max(axis=0) + tr.radius for tr in trajectories])
    boxes = shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])
    a, b = shapely.STRtree(boxes).query(boxes)
    keep = a < b
    a, b = a[keep], b[keep]
    start = np.concatenate([[0], np.cumsum([tr.t.size for tr in trajectories])])  # (R+1,)
    radius = np.array([tr.radius for tr in trajectories])
    gaps, whens = _pairs_min_gap(
        np.concatenate([tr.t for tr in trajectories]),
        np.concatenate([tr.xy for tr in trajectories]),
        start,
        radius,
        a,
        b,
    )
    present = np.isfinite(gaps)
    if not present.any():
        return Clearance(None, None, None, ())
    k = int(np.argmin(np.where(present, gaps, np.inf)))
    bad = np.flatnonzero(present & (gaps < -TOLERANCE))
    overlaps = tuple((int(a[m]), int(b[m]), float(whens[m]), float(gaps[m])) for m in bad.tolist())
    return Clearance(float(gaps[k]), (int(a[k]), int(b[k])), float(whens[k]), overlaps)


@numba.njit(cache=True, nogil=True)
def _pairs_min_gap(
    t: np.ndarray,  # (K,) all waypoint times, robot by robot
    xy: np.ndarray,  # (K, 2)
    start: np.ndarray,  # (R+1,) int, robot r's waypoints are start[r]:start[r+1]
    radius: np.ndarray,  # (R,)
    a: np.ndarray,  # (C,) int, pairs to check
    b: np.ndarray,  # (C,) int
) -> tuple[np.ndarray, np.ndarray]:  # (C,) least gap (inf if never together), when
    gaps = np.empty(a.size)
    whens = np.empty(a.size)
    for c in range(a.size):
        i, j = a[c], b[c]
        gaps[c], whens[c] = _pair_min_gap(
            t[start[i] : start[i + 1]],
            xy[start[i] : start[i + 1]],
            t[start[j] : start[j + 1]],
            xy[start[j] : start[j + 1]],
            radius[i] + radius[j],
        )
    return gaps, whens
