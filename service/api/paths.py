"""What the paths-form routes share: caps, geometry settings and error mapping."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

from service.api.errors import TooLarge
from service.api.request_log import RequestRecord
from service.api.runtime import SolvePool
from service.core.path_schemas import PathRobotIn
from service.geometry.graph import GeometrySettings
from service.geometry.interference import TooComplex
from service.settings import Settings

__all__ = ["check_path_caps", "geometry_settings", "run_paths_work"]

T = TypeVar("T")


def geometry_settings(settings: Settings) -> GeometrySettings:
    """The geometry's resolution, margin and work bound from the service settings."""
    return GeometrySettings(
        resolution=settings.geometry_resolution_m,
        margin=settings.geometry_margin_m,
        max_pairs=settings.max_interference_pairs,
    )


def check_path_caps(robots: Sequence[PathRobotIn], settings: Settings) -> None:
    """Refuse (413) more robots, points per path or points in total than the settings allow."""
    over = []
    if len(robots) > settings.max_robots:
        over.append(f"{len(robots)} robots exceed max_robots ({settings.max_robots})")
    longest = max((len(r.path) for r in robots), default=0)
    if longest > settings.max_path_points:
        over.append(
            f"a path of {longest} points exceeds max_path_points ({settings.max_path_points})"
        )
    total = sum(len(r.path) for r in robots)
    if total > settings.max_total_path_points:
        over.append(
            f"{total} path points exceed max_total_path_points ({settings.max_total_path_points})"
        )
    if over:
        raise TooLarge("problem too large: " + "; ".join(over))


async def run_paths_work(
    work: Callable[[], T], limiter: SolvePool, record: RequestRecord | None = None
) -> T:
    """Run blocking paths-form work in the solve pool, mapping its errors to API errors."""
    try:
        return await limiter.run(work, record)
    except TooComplex as exc:
        raise TooLarge(str(exc)) from exc
