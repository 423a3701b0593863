"""The Gantt chart: per robot, when it moves, occupies its nodes, waits and finishes.

One row per robot (response order): the trajectory's time span as a light bar
in the robot's colour, the scheduled node occupations (``enter``-``exit``) as
boxes coloured by assignment type, the waits (standing still before finishing)
hatched orange, and the completion time as a black tick. Everything of one kind
is a single collection, so hundreds of robots draw quickly; the figure grows
with the rows (up to a cap) and the row labels thin out.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from service.pictures.plan import (
    Category,
    Json,
    completions,
    node_categories,
    robot_waits,
    scheduled_nodes,
    trajectories,
)
from service.pictures.style import (
    TYPE_COLOURS,
    TYPE_LABELS,
    WAIT_COLOUR,
    WAIT_HATCH,
    new_figure,
    robot_colours,
    save_png,
)

__all__ = ["draw_gantt"]

WIDTH_IN = 11.0
ROW_HEIGHT_IN = 0.22
# Room for the axis and the legend around the rows.
FRAME_HEIGHT_IN = 1.6
# Beyond this height (thousands of robots) the rows are squeezed instead.
MAX_HEIGHT_IN = 60.0
# At most this many robot ids on the y axis; more rows show every k-th id.
MAX_ROW_LABELS = 60
ROW_LABEL_FONT_SIZE = 7
LEGEND_FONT_SIZE = 8
GRID_ALPHA = 0.3
SPAN_HALF_HEIGHT = 0.35
NODE_HALF_HEIGHT = 0.25
WAIT_HALF_HEIGHT = 0.15
# Waits lie on the light span bar or on a node box: a white ground keeps the
# orange hatching visible on both.
WAIT_FILL = "white"
SPAN_ALPHA = 0.35
SPAN_LEGEND_COLOUR = "0.5"
NODE_EDGE_COLOUR = "0.2"
NODE_EDGE_WIDTH = 0.4
COMPLETION_MARKER = "|"
COMPLETION_MARKER_SIZE = 80
COMPLETION_COLOUR = "black"

Box = tuple[int, float, float]  # row, start time, end time


def _rectangles(boxes: list[Box], half_height: float) -> list[np.ndarray]:
    """Corner arrays ``(4, 2)`` of time boxes centred on their rows."""
    return [
        np.array(
            [
                [start, row - half_height],
                [end, row - half_height],
                [end, row + half_height],
                [start, row + half_height],
            ]
        )
        for row, start, end in boxes
    ]


def _rows(response: Json) -> list[str]:
    """Robots in response order: those with a trajectory, then scheduled ones without."""
    robots = list(trajectories(response))
    return robots + [robot for robot in scheduled_nodes(response) if robot not in robots]


def _draw_spans(axes: Axes, response: Json, row_of: dict[str, int]) -> None:
    """Each trajectory's time span as a light bar in its robot's colour."""
    colours = robot_colours(row_of)
    spans = {robot: (pts[0, 0], pts[-1, 0]) for robot, pts in trajectories(response).items()}
    axes.add_collection(
        PolyCollection(
            _rectangles([(row_of[r], *span) for r, span in spans.items()], SPAN_HALF_HEIGHT),
            facecolors=[(*colours[r][:3], SPAN_ALPHA) for r in spans],
            edgecolors="none",
        )
    )


def _draw_nodes(axes: Axes, response: Json, row_of: dict[str, int]) -> list[Category]:
    """Scheduled node occupations as boxes coloured by assignment; returns the colours used."""
    categories = node_categories(response)
    boxes: dict[Category, list[Box]] = {}
    for robot, nodes in scheduled_nodes(response).items():
        for node_id, enter, exit_ in nodes:
            category = categories.get(node_id, "unassigned")
            boxes.setdefault(category, []).append((row_of[robot], enter, exit_))
    for category, category_boxes in boxes.items():
        axes.add_collection(
            PolyCollection(
                _rectangles(category_boxes, NODE_HALF_HEIGHT),
                facecolors=TYPE_COLOURS[category],
                edgecolors=NODE_EDGE_COLOUR,
                linewidths=NODE_EDGE_WIDTH,
            )
        )
    return sorted(boxes)


def _draw_waits(axes: Axes, response: Json, row_of: dict[str, int]) -> bool:
    """Waits (standing still before finishing) as hatched orange boxes; whether any."""
    waits = [(row_of[r], *w) for r, intervals in robot_waits(response).items() for w in intervals]
    axes.add_collection(
        PolyCollection(
            _rectangles(waits, WAIT_HALF_HEIGHT),
            facecolors=WAIT_FILL,
            edgecolors=WAIT_COLOUR,
            hatch=WAIT_HATCH,
        )
    )
    return bool(waits)


def _draw_completions(axes: Axes, response: Json, row_of: dict[str, int]) -> bool:
    """Each scheduled completion as a black tick on its row; whether any."""
    finished = completions(response)
    axes.scatter(
        list(finished.values()),
        [row_of[robot] for robot in finished],
        s=COMPLETION_MARKER_SIZE,
        marker=COMPLETION_MARKER,
        c=COMPLETION_COLOUR,
        zorder=3,
    )
    return bool(finished)


def _label_rows(axes: Axes, robots: list[str]) -> None:
    """Robot ids on the y axis (every k-th one when there are many), first robot on top.

    A chart with thinned labels is tall: it gets the time axis at the top too.
    """
    step = max(1, math.ceil(len(robots) / MAX_ROW_LABELS))
    axes.set_yticks(range(0, len(robots), step), robots[::step], fontsize=ROW_LABEL_FONT_SIZE)
    axes.set_ylim(len(robots) - 0.5, -0.5)
    axes.tick_params(axis="x", labeltop=step > 1, top=step > 1)


def _legend_handles(
    categories: list[Category], has_waits: bool, has_completions: bool
) -> list[Line2D | Patch]:
    """Proxy artists for the legend: the span, and the node colours, waits, completions drawn."""
    handles: list[Line2D | Patch] = [
        Patch(facecolor=SPAN_LEGEND_COLOUR, alpha=SPAN_ALPHA, label="present (robot colour)"),
        *(Patch(facecolor=TYPE_COLOURS[c], label=f"node: {TYPE_LABELS[c]}") for c in categories),
    ]
    if has_waits:
        handles.append(
            Patch(facecolor=WAIT_FILL, edgecolor=WAIT_COLOUR, hatch=WAIT_HATCH, label="wait")
        )
    if has_completions:
        handles.append(
            Line2D(
                [], [], color=COMPLETION_COLOUR, ls="", marker=COMPLETION_MARKER, label="completion"
            )
        )
    return handles


def draw_gantt(response: Json, path: str | Path = "gantt.png") -> Path:
    """Draw the Gantt chart of a paths-form response as PNG and return its path.

    Args:
        response: the answer (``trajectories``, ``schedule``, ``assignment``).
        path: where to write the PNG.
    """
    robots = _rows(response)
    row_of = {robot: row for row, robot in enumerate(robots)}
    height = min(FRAME_HEIGHT_IN + ROW_HEIGHT_IN * len(robots), MAX_HEIGHT_IN)
    figure = new_figure(WIDTH_IN, height)
    figure.set_layout_engine("constrained")
    axes = figure.add_subplot()
    _draw_spans(axes, response, row_of)
    categories = _draw_nodes(axes, response, row_of)
    has_waits = _draw_waits(axes, response, row_of)
    has_completions = _draw_completions(axes, response, row_of)
    _label_rows(axes, robots)
    axes.autoscale_view(scaley=False)
    axes.set_xlabel("time (s)")
    axes.grid(axis="x", alpha=GRID_ALPHA)
    handles = _legend_handles(categories, has_waits, has_completions)
    figure.legend(
        handles=handles, loc="outside upper center", ncols=len(handles), fontsize=LEGEND_FONT_SIZE
    )
    return save_png(figure, path)
