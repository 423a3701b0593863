"""The floor plan: obstacles, each robot's path and footprint, and the conflict sections.

A conflict section is the stretch of a robot's path covered by one coordination
graph node (``node_spans``: arc-length interval on the owner's path). It is
coloured by how the conflicts involving the node were assigned, so that the
picture shows where the schedule makes robots take turns and where it lets
them follow each other.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Polygon

from service.pictures.geometry import sub_polyline
from service.pictures.plan import (
    Bounds,
    Category,
    Json,
    node_categories,
    node_owners,
    plot_bounds,
    robot_paths,
)
from service.pictures.style import (
    LABEL_FONT_SIZE,
    MAX_LABELLED_ROBOTS,
    OBSTACLE_COLOUR,
    TYPE_COLOURS,
    TYPE_LABELS,
    new_figure,
    robot_colours,
    save_png,
    world_figure_size,
)

__all__ = ["draw_layout", "draw_world", "conflict_sections"]

LONG_SIDE_IN = 9.0
MAX_ASPECT = 2.0
PATH_WIDTH = 1.0
SECTION_WIDTH = 4.0
SECTION_ALPHA = 0.6
FOOTPRINT_ALPHA = 0.25
MARKER_SIZE = 30  # points^2, shrunk as 1/robots beyond MAX_LABELLED_ROBOTS
START_MARKER = "o"
GOAL_MARKER = "X"
LEGEND_FONT_SIZE = 8
LEGEND_COLUMNS = 3
NEUTRAL_COLOUR = "0.3"


def draw_world(axes: Axes, bounds: Bounds, world: Json | None) -> None:
    """Draw the obstacles in grey and frame the floor with equal aspect.

    Shared with the animation, whose background is this same floor.
    """
    obstacles = (world or {}).get("obstacles") or []
    axes.add_collection(
        PatchCollection(
            [Polygon(np.asarray(polygon, dtype=float), closed=True) for polygon in obstacles],
            facecolor=OBSTACLE_COLOUR,
            edgecolor="none",
        )
    )
    axes.set_xlim(bounds[0], bounds[2])
    axes.set_ylim(bounds[1], bounds[3])
    axes.set_aspect("equal")


def conflict_sections(request: Json, response: Json) -> dict[Category, list[np.ndarray]]:
    """The sub-polylines of every node in ``node_spans``, grouped by assignment category.

    Nodes whose robot is not in the request are skipped (nothing to draw them on).
    """
    paths = robot_paths(request)
    owners = node_owners(response)
    categories = node_categories(response)
    sections: dict[Category, list[np.ndarray]] = {}
    for node_id, (s_enter, s_exit) in (response.get("node_spans") or {}).items():
        robot = owners.get(node_id)
        if robot in paths:
            category = categories.get(node_id, "unassigned")
            sections.setdefault(category, []).append(sub_polyline(paths[robot], s_enter, s_exit))
    return sections


def _draw_robots(axes: Axes, request: Json) -> None:
    """Paths as thin lines, start and goal markers and start footprints, in robot colours."""
    paths = robot_paths(request)
    colours = robot_colours(paths)
    robot_colour = [colours[robot] for robot in paths]
    axes.add_collection(LineCollection(list(paths.values()), colors=robot_colour, lw=PATH_WIDTH))
    starts = np.array([path[0] for path in paths.values()])
    goals = np.array([path[-1] for path in paths.values()])
    size = MARKER_SIZE * min(1.0, MAX_LABELLED_ROBOTS / len(paths))
    axes.scatter(*starts.T, s=size, marker=START_MARKER, c=robot_colour, zorder=3)
    axes.scatter(*goals.T, s=size, marker=GOAL_MARKER, c=robot_colour, zorder=3)
    footprints = [
        Circle(tuple(start), robot["radius"])
        for start, robot in zip(starts, request["robots"], strict=True)
    ]
    axes.add_collection(
        PatchCollection(
            footprints,
            facecolor=[(*colour[:3], FOOTPRINT_ALPHA) for colour in robot_colour],
            edgecolor=robot_colour,
        )
    )
    if len(paths) <= MAX_LABELLED_ROBOTS:
        for robot, start in zip(paths, starts, strict=True):
            axes.annotate(
                robot, start, xytext=(4, 4), textcoords="offset points", fontsize=LABEL_FONT_SIZE
            )


def _legend_handles(categories: list[Category], has_obstacles: bool) -> list[Line2D | Patch]:
    """Proxy artists for the legend: robot symbols, obstacles, the section colours drawn."""
    handles: list[Line2D | Patch] = [
        Line2D([], [], color=NEUTRAL_COLOUR, lw=PATH_WIDTH, label="path (robot colour)"),
        Line2D([], [], color=NEUTRAL_COLOUR, ls="", marker=START_MARKER, label="start"),
        Line2D([], [], color=NEUTRAL_COLOUR, ls="", marker=GOAL_MARKER, label="goal"),
        Patch(facecolor="none", edgecolor=NEUTRAL_COLOUR, label="footprint at start"),
    ]
    if has_obstacles:
        handles.append(Patch(facecolor=OBSTACLE_COLOUR, label="obstacle"))
    handles += [
        Line2D(
            [],
            [],
            color=TYPE_COLOURS[c],
            lw=SECTION_WIDTH,
            alpha=SECTION_ALPHA,
            label=f"conflict section: {TYPE_LABELS[c]}",
        )
        for c in categories
    ]
    return handles


def draw_layout(
    request: Json,
    response: Json | None = None,
    world: Json | None = None,
    path: str | Path = "layout.png",
) -> Path:
    """Draw the floor plan of a paths-form request as PNG and return its path.

    Args:
        request: the paths-form request (``robots`` with ``id``, ``path``, ``radius``).
        response: optional answer; its ``node_spans`` give the conflict sections,
            its ``assignment`` their colours.
        world: optional ``bounds`` and ``obstacles`` (polygons).
        path: where to write the PNG.
    """
    bounds = plot_bounds(request, world)
    figure = new_figure(*world_figure_size(bounds, LONG_SIDE_IN, MAX_ASPECT))
    figure.set_layout_engine("constrained")
    axes = figure.add_subplot()
    draw_world(axes, bounds, world)
    _draw_robots(axes, request)
    sections = conflict_sections(request, response) if response else {}
    for category, lines in sections.items():
        axes.add_collection(
            LineCollection(
                lines,
                colors=TYPE_COLOURS[category],
                lw=SECTION_WIDTH,
                alpha=SECTION_ALPHA,
                zorder=2,
            )
        )
    axes.set_xlabel("x (m)")
    axes.set_ylabel("y (m)")
    has_obstacles = bool((world or {}).get("obstacles"))
    figure.legend(
        handles=_legend_handles(sorted(sections), has_obstacles),
        loc="outside lower center",
        ncols=LEGEND_COLUMNS,
        fontsize=LEGEND_FONT_SIZE,
    )
    return save_png(figure, path)
