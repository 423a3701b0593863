"""A generated world: its layout (obstacles, bounds) and the robots of a paths-form request.

A world is plain data so that it round-trips through JSON unchanged: pictures
draw its obstacles, tests replay it, and ``to_request`` hands its robots to the
service as the body of a paths-form ``POST``.
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass
from typing import Any

from shapely.geometry import Polygon

__all__ = ["ROUND_DIGITS", "Ring", "World", "ring_of"]

# Coordinates are rounded to 0.1 mm: far below any footprint, and it keeps the JSON short.
ROUND_DIGITS = 4

Ring = list[list[float]]  # an obstacle's exterior ring, [[x, y], ...] in metres


@dataclass(frozen=True)
class World:
    """One seeded world: what was asked for (``params``), the floor, and the robots.

    Example: ``World.from_json(world.to_json()) == world`` for every generated world.
    """

    kind: str
    params: dict[str, Any]  # every parameter the world was built from, defaults resolved
    obstacles: list[Ring]  # exterior rings of the obstacle polygons (racks, disks, boxes)
    bounds: tuple[float, float, float, float]  # xmin, ymin, xmax, ymax of the floor
    robots: list[dict[str, Any]]  # paths-form robots: id, path, radius, speed/start_time or times

    def __post_init__(self) -> None:
        """Store params as their JSON form (tuples become lists) so a JSON round trip is exact."""
        object.__setattr__(self, "params", json.loads(json.dumps(self.params)))
        object.__setattr__(self, "bounds", tuple(float(v) for v in self.bounds))

    def obstacle_polygons(self) -> list[Polygon]:
        """The obstacles as shapely polygons, for clearance checks and drawing."""
        return [Polygon(ring) for ring in self.obstacles]

    def to_request(
        self, objective: str = "avg_completion", options: dict[str, Any] | None = None
    ) -> dict[str, Any]:
        """A paths-form request body ``{"objective", "robots", "options"}`` (robots copied)."""
        return {
            "objective": objective,
            "robots": copy.deepcopy(self.robots),
            "options": dict(options or {}),
        }

    def to_dict(self) -> dict[str, Any]:
        """The world as JSON-ready plain data."""
        return {
            "kind": self.kind,
            "params": self.params,
            "bounds": list(self.bounds),
            "obstacles": self.obstacles,
            "robots": self.robots,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> World:
        """The inverse of ``to_dict``."""
        return cls(
            kind=data["kind"],
            params=data["params"],
            obstacles=data["obstacles"],
            bounds=tuple(data["bounds"]),
            robots=data["robots"],
        )

    def to_json(self, indent: int | None = None) -> str:
        """The world as JSON text (obstacles included, so pictures can draw them)."""
        return json.dumps(self.to_dict(), indent=indent)

    @classmethod
    def from_json(cls, text: str) -> World:
        """The inverse of ``to_json``."""
        return cls.from_dict(json.loads(text))


def ring_of(polygon: Polygon) -> Ring:
    """The exterior ring of a polygon in the stored (rounded, plain) form."""
    return [[round(x, ROUND_DIGITS), round(y, ROUND_DIGITS)] for x, y in polygon.exterior.coords]
