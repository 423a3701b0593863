"""The robots common to every world: radii, timing, ids, and clean paths.

Layouts (warehouse, floor) decide where robots drive; this module turns those
polylines into paths-form robot objects: radius, a constant ``speed`` with a
``start_time`` or per-point ``times`` (piecewise speeds), all from one seeded
numpy Generator.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from service.scenarios.world import ROUND_DIGITS

__all__ = [
    "FleetParams",
    "check_robot_count",
    "clean_path",
    "make_robots",
    "piecewise_times",
    "sample_radii",
]

# Interior points whose turn is below this cross product (m^2) lie on a straight
# line: dropping them leaves the same path with fewer points.
COLLINEAR_TOL = 1e-9
MIN_ROBOTS, MAX_ROBOTS = 2, 250


@dataclass(frozen=True)
class FleetParams:
    """How the fleet is drawn; every range is ``(low, high)`` sampled uniformly."""

    radius: float = 0.4  # metres, every robot unless radius_choices is given
    radius_choices: tuple[float, ...] = ()  # a mix: each robot's radius drawn from these
    speed_range: tuple[float, float] = (0.5, 1.5)  # m/s
    start_time_range: tuple[float, float] = (0.0, 10.0)  # s, the start delays
    timed_fraction: float = 0.0  # share of robots given per-point `times` (piecewise speeds)
    id_prefix: str = "amr"

    def __post_init__(self) -> None:
        """Reject parameters that would produce invalid robots."""
        radii = self.radius_choices or (self.radius,)
        if min(radii) <= 0:
            raise ValueError(f"radii must be positive: {radii}")
        low, high = self.speed_range
        if not 0 < low <= high:
            raise ValueError(f"speed_range must satisfy 0 < low <= high: {self.speed_range}")
        low, high = self.start_time_range
        if not 0 <= low <= high:
            raise ValueError(f"start_time_range must satisfy 0 <= low <= high: {low, high}")
        if not 0 <= self.timed_fraction <= 1:
            raise ValueError(f"timed_fraction must be in [0, 1]: {self.timed_fraction}")

    @property
    def max_radius(self) -> float:
        """The largest footprint any robot can get: layouts size bays and gaps for it."""
        return max(self.radius_choices or (self.radius,))


def check_robot_count(n_robots: int) -> None:
    """Worlds hold 2 to 250 robots: the range the service's paths form is tuned and tested for."""
    if not MIN_ROBOTS <= n_robots <= MAX_ROBOTS:
        raise ValueError(f"n_robots must be in [{MIN_ROBOTS}, {MAX_ROBOTS}]: {n_robots}")


def sample_radii(n_robots: int, fleet: FleetParams, rng: np.random.Generator) -> np.ndarray:
    """(n,) radius of each robot: the single radius, or draws from the mix."""
    if not fleet.radius_choices:
        return np.full(n_robots, fleet.radius)
    return rng.choice(np.asarray(fleet.radius_choices, dtype=np.float64), size=n_robots)


def clean_path(points: np.ndarray) -> np.ndarray:
    """A path rounded to ``ROUND_DIGITS``, without repeated or collinear interior points.

    Shapes: (N, 2) -> (M, 2), M >= 2 when the ends differ. A zero-length segment
    has no heading (the service rejects it); a straight run needs no midpoints.
    """
    pts = np.round(np.asarray(points, dtype=np.float64), ROUND_DIGITS)
    keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0, axis=1)])
    pts = pts[keep]
    if len(pts) < 3:
        return pts
    before, after = pts[1:-1] - pts[:-2], pts[2:] - pts[1:-1]
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    forward = np.einsum("ij,ij->i", before, after) > 0
    straight = (np.abs(cross) <= COLLINEAR_TOL) & forward
    return pts[np.concatenate([[True], ~straight, [True]])]


def make_robots(
    paths: Sequence[np.ndarray],
    radii: np.ndarray,
    fleet: FleetParams,
    rng: np.random.Generator,
) -> list[dict[str, Any]]:
    """Paths-form robot objects for the given polylines, with drawn delays and speeds."""
    n = len(paths)
    starts = rng.uniform(*fleet.start_time_range, size=n)
    speeds = rng.uniform(*fleet.speed_range, size=n)
    timed = rng.random(n) < fleet.timed_fraction
    robots = []
    for k, raw in enumerate(paths):
        path = clean_path(raw)
        robot: dict[str, Any] = {
            "id": f"{fleet.id_prefix}-{k:03d}",
            "path": path.tolist(),
            "radius": float(radii[k]),
        }
        if timed[k]:
            robot["times"] = piecewise_times(path, float(starts[k]), fleet, rng).tolist()
        else:
            robot["speed"] = float(speeds[k])
            robot["start_time"] = float(starts[k])
        robots.append(robot)
    return robots


def piecewise_times(
    path: np.ndarray, start_time: float, fleet: FleetParams, rng: np.random.Generator
) -> np.ndarray:
    """(N,) strictly increasing times: each segment driven at its own drawn speed."""
    lengths = np.linalg.norm(np.diff(path, axis=0), axis=1)
    speeds = rng.uniform(*fleet.speed_range, size=len(lengths))
    return start_time + np.concatenate([[0.0], np.cumsum(lengths / speeds)])
