"""Floor obstacles: disks and axis-aligned boxes, with exact distance fields.

The planner needs the clearance of thousands of grid cells at once; for these
two shapes it is a closed form in numpy. The polygons handed to shapely (and
stored in the world) lie inside the exact shapes (a disk's polygon is
inscribed), so a clearance from the closed form never overstates the clearance
to the stored polygons.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapely.geometry import Point, Polygon, box

__all__ = ["Box", "Disk", "Shape"]

# Segments per quarter circle of a disk's polygon: 32 vertices, within 0.5 % of
# the radius of the true circle.
DISK_QUAD_SEGS = 8


@dataclass(frozen=True)
class Disk:
    """A round obstacle (pillar, bin) of radius ``r`` around ``(cx, cy)``."""

    cx: float
    cy: float
    r: float

    def distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Distance from points to the disk, 0 inside. Shapes: x, y (...) -> (...)."""
        return np.maximum(np.hypot(x - self.cx, y - self.cy) - self.r, 0.0)

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        """xmin, ymin, xmax, ymax."""
        return (self.cx - self.r, self.cy - self.r, self.cx + self.r, self.cy + self.r)

    def polygon(self) -> Polygon:
        """The inscribed polygon stored in the world."""
        return Point(self.cx, self.cy).buffer(self.r, quad_segs=DISK_QUAD_SEGS)


@dataclass(frozen=True)
class Box:
    """An axis-aligned rectangular obstacle (pallet, machine, wall piece)."""

    xmin: float
    ymin: float
    xmax: float
    ymax: float

    def distance(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Distance from points to the box, 0 inside. Shapes: x, y (...) -> (...)."""
        dx = np.maximum(np.maximum(self.xmin - x, x - self.xmax), 0.0)
        dy = np.maximum(np.maximum(self.ymin - y, y - self.ymax), 0.0)
        return np.hypot(dx, dy)

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        """xmin, ymin, xmax, ymax."""
        return (self.xmin, self.ymin, self.xmax, self.ymax)

    def polygon(self) -> Polygon:
        """The box as a polygon."""
        return box(self.xmin, self.ymin, self.xmax, self.ymax)


Shape = Disk | Box
