"""Colours, styling constants and figure handling shared by the three pictures.

Figures are built with matplotlib's object-oriented API on an Agg canvas, never
through ``pyplot``: no global figure registry (nothing leaks across hundreds of
frames or concurrent requests) and no display backend is needed, whatever
backend the importing process has chosen.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import hsv_to_rgb, to_rgba
from matplotlib.figure import Figure

from service.pictures.plan import Bounds, Category

__all__ = [
    "TYPE_COLOURS",
    "TYPE_LABELS",
    "WAIT_COLOUR",
    "WAIT_HATCH",
    "OBSTACLE_COLOUR",
    "DPI",
    "MAX_LABELLED_ROBOTS",
    "LABEL_FONT_SIZE",
    "robot_colours",
    "new_figure",
    "world_figure_size",
    "save_png",
]

# Conflict sections and node boxes by how their conflicts were assigned.
TYPE_COLOURS: dict[Category, str] = {
    "exclusive": "tab:red",
    "following": "tab:blue",
    "unassigned": "tab:purple",
}
TYPE_LABELS: dict[Category, str] = {
    "exclusive": "exclusive only",
    "following": "has following",
    "unassigned": "not assigned",
}
WAIT_COLOUR = "tab:orange"
WAIT_HATCH = "////"
OBSTACLE_COLOUR = "0.65"
DPI = 100
# Robot ids are written on the floor pictures only up to this many robots
# (beyond, they overlap into a blot).
MAX_LABELLED_ROBOTS = 20
LABEL_FONT_SIZE = 7

# The tab10 colours that mean nothing else here (red, blue, purple: assignment
# types; orange: waits; grey: obstacles). More robots get hues spaced by the
# golden ratio, so that neighbours in id order stay distinct.
ROBOT_PALETTE = ("tab:green", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
GOLDEN_RATIO_CONJUGATE = 0.618033988749895
ROBOT_SATURATION = 0.75
ROBOT_VALUE = 0.85


def robot_colours(robot_ids: Iterable[str]) -> dict[str, tuple[float, float, float, float]]:
    """One RGBA colour per robot, keyed by id.

    Colours follow the sorted ids, so the layout (request order), the Gantt chart
    and the animation (response order) give a robot the same colour.
    """
    ids = sorted(set(robot_ids))
    if len(ids) <= len(ROBOT_PALETTE):
        return {robot: to_rgba(colour) for robot, colour in zip(ids, ROBOT_PALETTE, strict=False)}
    hues = (np.arange(len(ids)) * GOLDEN_RATIO_CONJUGATE) % 1.0
    hsv = np.stack((hues, np.full_like(hues, ROBOT_SATURATION), np.full_like(hues, ROBOT_VALUE)), 1)
    return {robot: (*map(float, rgb), 1.0) for robot, rgb in zip(ids, hsv_to_rgb(hsv), strict=True)}


def new_figure(width_in: float, height_in: float) -> Figure:
    """A figure of the given size (inches at ``DPI``) attached to its own Agg canvas."""
    figure = Figure(figsize=(width_in, height_in), dpi=DPI)
    FigureCanvasAgg(figure)
    return figure


def world_figure_size(
    bounds: Bounds, long_side_in: float, max_aspect: float
) -> tuple[float, float]:
    """Figure size whose shape follows the floor's, its longer side ``long_side_in``.

    The aspect ratio is capped at ``max_aspect`` so that a corridor-shaped floor
    still gives a usable picture (the axes then leave blank space).
    """
    width, height = bounds[2] - bounds[0], bounds[3] - bounds[1]
    ratio = float(np.clip(height / width, 1.0 / max_aspect, max_aspect))
    if ratio <= 1.0:
        return long_side_in, long_side_in * ratio
    return long_side_in / ratio, long_side_in


def save_png(figure: Figure, path: str | Path) -> Path:
    """Write a figure as PNG (creating the folder) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, format="png", dpi=DPI)
    return path
