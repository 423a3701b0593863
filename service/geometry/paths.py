"""A robot's path as arrays: polyline, arc length, planned times, footprint.

Everything downstream (interference, dependency plans, execution, clearance)
works in arc length ``s`` along the path; ``time_at``/``position_at`` map it to
the planned clock and to the plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from service.core.path_schemas import PathRobotIn

__all__ = ["RobotPath"]


@dataclass(frozen=True, eq=False)
class RobotPath:
    """One robot's polyline with its planned timing. Shapes: N path points."""

    id: str
    points: np.ndarray  # (N, 2) float, metres
    arc: np.ndarray  # (N,) float, cumulative arc length, arc[0] = 0, strictly increasing
    times: np.ndarray  # (N,) float, planned time at each point, strictly increasing
    radius: float

    @classmethod
    def from_wire(cls, robot: PathRobotIn) -> RobotPath:
        """Arrays of a validated wire robot (``speed``/``start_time`` or ``times``)."""
        points = np.asarray(robot.path, dtype=np.float64)  # (N, 2)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
        if robot.times is not None:
            times = np.asarray(robot.times, dtype=np.float64)
        else:
            assert robot.speed is not None  # the wire model guarantees one timing
            times = (robot.start_time or 0.0) + arc / robot.speed
        return cls(robot.id, points, arc, times, float(robot.radius))

    @property
    def length(self) -> float:
        return float(self.arc[-1])

    @property
    def start_time(self) -> float:
        return float(self.times[0])

    @property
    def finish_time(self) -> float:
        """Planned arrival at the last point: the completion without any delay."""
        return float(self.times[-1])

    def time_at(self, s: np.ndarray | float) -> np.ndarray:
        """Planned time at arc length(s) ``s`` (linear within each segment)."""
        return np.interp(s, self.arc, self.times)

    def arc_at(self, t: np.ndarray | float) -> np.ndarray:
        """Planned arc length at time(s) ``t`` (clamped to the path)."""
        return np.interp(t, self.times, self.arc)

    def position_at(self, s: np.ndarray | float) -> np.ndarray:
        """Points at arc length(s) ``s``. Shapes: s (K,) -> (K, 2); scalar -> (2,)."""
        x = np.interp(s, self.arc, self.points[:, 0])
        y = np.interp(s, self.arc, self.points[:, 1])
        return np.stack([x, y], axis=-1)

    def segment_speeds(self) -> np.ndarray:
        """(N-1,) planned speed of each segment, m/s: the speed the robot never exceeds."""
        return np.diff(self.arc) / np.diff(self.times)
