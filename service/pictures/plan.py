"""Reading the paths-form request, the response and the world (plain JSON-like dicts).

The pictures depend on the wire format only, never on the service's models, so
that they can draw a saved request/response pair anywhere. Every accessor here
tolerates the optional parts of a response (``graph`` may be null, a
coordination-graph answer has no ``assignment`` or ``schedule``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from service.pictures.geometry import wait_intervals

__all__ = [
    "Json",
    "Category",
    "Bounds",
    "robot_paths",
    "trajectories",
    "completions",
    "scheduled_nodes",
    "node_owners",
    "node_categories",
    "robot_waits",
    "plot_bounds",
]

Json = Mapping[str, Any]
# How a node's conflicts were resolved: any "following" wins (the robots share the
# section in a convoy), else "exclusive"; "unassigned" when the response has no
# assignment for it (a coordination-graph answer).
Category = Literal["exclusive", "following", "unassigned"]
Bounds = tuple[float, float, float, float]

# Margin around the paths when the world gives no bounds, as a fraction of the
# larger side of the paths' bounding box (plus the largest footprint radius).
BOUNDS_MARGIN_FRACTION = 0.05


def robot_paths(request: Json) -> dict[str, np.ndarray]:
    """Each robot's path as an ``(n, 2)`` array, in request order."""
    return {robot["id"]: np.asarray(robot["path"], dtype=float) for robot in request["robots"]}


def trajectories(response: Json) -> dict[str, np.ndarray]:
    """Each robot's timed waypoints as an ``(n, 3)`` array of ``[t, x, y]``, in response order."""
    return {
        entry["robot"]: np.asarray(entry["points"], dtype=float).reshape(-1, 3)
        for entry in response.get("trajectories") or []
        if entry["points"]
    }


def completions(response: Json) -> dict[str, float]:
    """Each scheduled robot's completion time."""
    return {entry["robot"]: float(entry["completion"]) for entry in response.get("schedule") or []}


def scheduled_nodes(response: Json) -> dict[str, list[tuple[str, float, float]]]:
    """Each robot's nodes as ``(node_id, enter, exit)`` from the schedule."""
    return {
        entry["robot"]: [(n["id"], float(n["enter"]), float(n["exit"])) for n in entry["nodes"]]
        for entry in response.get("schedule") or []
    }


def node_owners(response: Json) -> dict[str, str]:
    """The robot whose path each node lies on, from the schedule and the graph."""
    graph_robots = (response.get("graph") or {}).get("robots") or []
    owners = {node["id"]: robot["id"] for robot in graph_robots for node in robot["nodes"]}
    for robot, nodes in scheduled_nodes(response).items():
        owners.update({node_id: robot for node_id, _, _ in nodes})
    return owners


def node_categories(response: Json) -> dict[str, Category]:
    """How the conflicts involving each node were assigned (see ``Category``).

    Nodes that no assignment entry names are absent: callers default them to
    ``"unassigned"``.
    """
    categories: dict[str, Category] = {}
    for entry in response.get("assignment") or []:
        for node_id in (entry["from"], entry["to"]):
            if categories.get(node_id) != "following":
                categories[node_id] = entry["type"]
    return categories


def robot_waits(response: Json) -> dict[str, list[tuple[float, float]]]:
    """Each robot's waits: intervals in which it stands still, present and not finished.

    A robot finishes at its scheduled completion, else at its last waypoint.
    """
    finished = completions(response)
    return {
        robot: wait_intervals(points, finished.get(robot))
        for robot, points in trajectories(response).items()
    }


def plot_bounds(request: Json, world: Json | None = None) -> Bounds:
    """The floor area to draw: the world's bounds, else the paths' box with a margin."""
    if world and world.get("bounds"):
        xmin, ymin, xmax, ymax = (float(v) for v in world["bounds"])
        return xmin, ymin, xmax, ymax
    points = np.vstack(list(robot_paths(request).values()))
    low, high = points.min(axis=0), points.max(axis=0)
    radius = max(float(robot["radius"]) for robot in request["robots"])
    margin = BOUNDS_MARGIN_FRACTION * float(np.max(high - low)) + radius
    return low[0] - margin, low[1] - margin, high[0] + margin, high[1] + margin
