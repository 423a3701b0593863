"""A brute-force reference of the clearance check, for tests only.

It samples every trajectory on one fine time grid (plus every waypoint time of
every robot, so presence boundaries and corners are always sampled), places each
robot by plain linear interpolation (``np.interp``), and computes every pairwise
centre distance with numpy. A robot is present from its first waypoint time to
its last, both included. No closed form, no broad phase: it is what
:func:`service.simulation.clearance.check_clearance` is compared to.

Sampling can only *miss* the exact minimum: the sampled least gap is never below
the true one, and above it by at most ``relative speed x step / 2``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from service.simulation.clearance import Trajectory

__all__ = ["ReferenceClearance", "position", "reference_clearance"]

DEFAULT_STEP_S = 0.01


@dataclass(frozen=True)
class ReferenceClearance:
    """Sampled least gaps: per pair of robots present together, and over all pairs."""

    pair_gap: dict[tuple[int, int], float]  # (i, j) with i < j -> least sampled gap
    pair_time: dict[tuple[int, int], float]  # when that gap was sampled

    @property
    def min_gap(self) -> float | None:
        """Least gap over every pair present together (None when no pair ever is)."""
        return min(self.pair_gap.values()) if self.pair_gap else None

    def overlapping(self, below: float) -> set[tuple[int, int]]:
        """Pairs whose least sampled gap is below ``below`` metres."""
        return {pair for pair, gap in self.pair_gap.items() if gap < below}


def position(trajectory: Trajectory, t: np.ndarray | float) -> np.ndarray:
    """Centre at time(s) ``t`` by linear interpolation of the waypoints. (K,) -> (K, 2)."""
    t = np.asarray(t, dtype=np.float64)
    # Waits repeat a position at increasing times; a repeated *time* would be a jump,
    # which no trajectory of ours has, so np.interp's handling of it never matters.
    x = np.interp(t, trajectory.t, trajectory.xy[:, 0])
    y = np.interp(t, trajectory.t, trajectory.xy[:, 1])
    return np.stack([x, y], axis=-1)


def reference_clearance(
    trajectories: Sequence[Trajectory], step: float = DEFAULT_STEP_S
) -> ReferenceClearance:
    """Least sampled gap (centre distance minus both radii) of every pair present together."""
    if not trajectories:
        return ReferenceClearance({}, {})
    begin = min(float(tr.t[0]) for tr in trajectories)
    end = max(float(tr.t[-1]) for tr in trajectories)
    grid = np.arange(begin, end + step, step)
    times = np.unique(np.concatenate([grid, *(tr.t for tr in trajectories)]))  # (T,)
    centres = np.stack([position(tr, times) for tr in trajectories])  # (R, T, 2)
    present = np.stack([(times >= tr.t[0]) & (times <= tr.t[-1]) for tr in trajectories])
    gaps: dict[tuple[int, int], float] = {}
    when: dict[tuple[int, int], float] = {}
    for i in range(len(trajectories)):
        for j in range(i + 1, len(trajectories)):
            both = present[i] & present[j]  # (T,)
            if not both.any():
                continue
            dist = np.linalg.norm(centres[i, both] - centres[j, both], axis=1)
            gap = dist - trajectories[i].radius - trajectories[j].radius
            k = int(np.argmin(gap))
            gaps[(i, j)] = float(gap[k])
            when[(i, j)] = float(times[both][k])
    return ReferenceClearance(gaps, when)
