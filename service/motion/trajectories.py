"""Executed runs as trajectories, and the schedule and costs they realize.

The schedule of a paths-form answer describes what the trajectories do: a time
point of robot i (planned time T at arc length s) is realized at the moment the
robot leaves s (after any wait there); completion is the arrival at its last
point. Costs follow the contract's definitions on those realized times.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from service.core.evaluate import costs_from_completion
from service.geometry.paths import RobotPath
from service.simulation.clearance import Trajectory
from service.simulation.executor import Run

__all__ = ["departure_times", "realized_costs", "trajectories"]


def trajectories(paths: Sequence[RobotPath], run: Run) -> list[Trajectory]:
    """One timed-waypoint trajectory per robot from an executed run."""
    return [
        Trajectory(wall, path.position_at(path.arc_at(clock)), path.radius)
        for path, wall, clock in zip(paths, run.wall, run.clock, strict=True)
    ]


def departure_times(wall: np.ndarray, clock: np.ndarray, planned: np.ndarray) -> np.ndarray:
    """Wall time at which a robot leaves each planned time point (after waiting there).

    Shapes: wall, clock (K,) waypoints with clock non-decreasing; planned (P,) -> (P,).
    """
    k = np.clip(np.searchsorted(clock, planned, side="right") - 1, 0, clock.size - 1)  # (P,)
    nxt = np.minimum(k + 1, clock.size - 1)
    span = clock[nxt] - clock[k]
    frac = np.where(span > 0, (planned - clock[k]) / np.where(span > 0, span, 1.0), 0.0)
    return wall[k] + np.clip(frac, 0.0, 1.0) * (wall[nxt] - wall[k])


def realized_costs(
    completion: np.ndarray, planned: Sequence[np.ndarray], realized: Sequence[np.ndarray]
) -> dict[str, float]:
    """All four objectives of realized times. Shapes: completion (R,); per robot (P_r,) times."""
    costs = {k: float(v[0]) for k, v in costs_from_completion(completion[None, :]).items()}
    delay = [float(np.mean(r - p)) for p, r in zip(planned, realized, strict=True)]
    costs["avg_delay"] = float(np.mean(delay))
    return costs
