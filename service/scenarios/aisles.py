"""The aisle graph of a warehouse and turn-aware shortest routes on it.

Lanes are axis-aligned centre lines (one-way or both ways); the graph's nodes
are lane ends, lane crossings, and the points where a bay's spur joins a lane.
Routes are shortest paths (networkx Dijkstra) on a graph of states
(node, heading at crossings): one-way lanes are driven forward only, a turn
costs ``TURN_PENALTY`` extra so routes with few turns win, U-turns at
crossings are not allowed, and bays are route ends, never passed through.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import networkx as nx
import numpy as np

__all__ = ["AisleGraph", "Bay", "Lane", "Point", "key"]

Point = tuple[float, float]
# Headings of axis-aligned moves: east, north, west, south; (h + 2) % 4 reverses h.
EAST, NORTH, WEST, SOUTH = range(4)
FREE = -1  # state without a heading: a start, or a lane point where no lane turn is possible
END = 4  # state of a robot that has arrived, whatever its heading
# Metres of driving one turn is worth: among routes within a few metres of the
# shortest, the one with fewest turns wins (each turn means slowing down).
TURN_PENALTY = 3.0
# Digits of a node key: points computed by different formulas that agree to a
# micrometre are one node.
KEY_DIGITS = 6

State = tuple[Point, int]


@dataclass(frozen=True)
class Lane:
    """An axis-aligned lane centre line; a one-way lane is driven from start to end only."""

    start: Point
    end: Point
    one_way: bool

    @property
    def vertical(self) -> bool:
        return self.start[0] == self.end[0]

    def covers(self, p: Point) -> bool:
        """Whether ``p`` lies on this lane (between its ends, on its line)."""
        axis = 1 if self.vertical else 0
        low, high = sorted((self.start[axis], self.end[axis]))
        return p[1 - axis] == self.start[1 - axis] and low <= p[axis] <= high


@dataclass(frozen=True)
class Bay:
    """A place robots start or end at, off the lanes; its spur joins each ``access`` point."""

    point: Point
    access: tuple[Point, ...]  # lane points, nearest first


def key(p: Sequence[float]) -> Point:
    """The node key of a point (rounded, so equal points from different formulas coincide)."""
    return (round(float(p[0]), KEY_DIGITS), round(float(p[1]), KEY_DIGITS))


def heading(u: Point, v: Point) -> int:
    """Heading of the axis-aligned move from ``u`` to ``v``."""
    if u[1] == v[1]:
        return EAST if v[0] > u[0] else WEST
    return NORTH if v[1] > u[1] else SOUTH


def crossing(a: Lane, b: Lane) -> Point | None:
    """Where a vertical and a horizontal lane cross, if they do."""
    if a.vertical == b.vertical:
        return None
    vertical, horizontal = (a, b) if a.vertical else (b, a)
    p = (vertical.start[0], horizontal.start[1])
    return p if vertical.covers(p) and horizontal.covers(p) else None


def lane_graph(lanes: Sequence[Lane], bays: Sequence[Bay]) -> tuple[nx.DiGraph, set[Point]]:
    """Directed graph of lane segments and bay spurs (edge ``weight`` in metres), and
    the lane crossings (the only nodes where a route can turn from lane to lane)."""
    points: list[set[Point]] = [{lane.start, lane.end} for lane in lanes]
    crossings: set[Point] = set()
    for i, a in enumerate(lanes):
        for j in range(i + 1, len(lanes)):
            p = crossing(a, lanes[j])
            if p is not None:
                points[i].add(p)
                points[j].add(p)
                crossings.add(p)
    by_line: dict[tuple[bool, float], list[int]] = defaultdict(list)
    for i, lane in enumerate(lanes):
        by_line[lane.vertical, lane.start[0] if lane.vertical else lane.start[1]].append(i)
    for bay in bays:
        for p in bay.access:
            for vertical in (True, False):
                for i in by_line.get((vertical, p[0] if vertical else p[1]), []):
                    if lanes[i].covers(p):
                        points[i].add(p)
    graph = nx.DiGraph()
    for lane, on_lane in zip(lanes, points, strict=True):
        ordered = sorted(on_lane, key=lambda p: math.dist(lane.start, p))
        for u, v in pairwise(ordered):
            graph.add_edge(u, v, weight=math.dist(u, v))
            if not lane.one_way:
                graph.add_edge(v, u, weight=math.dist(u, v))
    for bay in bays:
        for p in bay.access:
            graph.add_edge(bay.point, p, weight=math.dist(bay.point, p))
            graph.add_edge(p, bay.point, weight=math.dist(bay.point, p))
    return graph, crossings


def turn_graph(graph: nx.DiGraph, crossings: set[Point], ends: set[Point]) -> nx.DiGraph:
    """Graph of route states with turn costs.

    A crossing has one state per arrival heading (a turn there costs
    ``TURN_PENALTY``, a U-turn is not allowed); any other lane point has one
    state ``FREE`` (its only turns are into and out of bay spurs, which every
    route makes alike). An end (bay) is left from ``(bay, FREE)`` and reached
    at ``(bay, END)``, so no route passes through it.
    """

    def arrival(u: Point, v: Point) -> State:
        if v in ends:
            return (v, END)
        return (v, heading(u, v) if v in crossings else FREE)

    states = nx.DiGraph()
    arrivals = {v: {heading(u, v) for u in graph.predecessors(v)} for v in crossings}
    for u, v, length in graph.edges(data="weight"):
        h = heading(u, v)
        if u not in crossings:
            states.add_edge((u, FREE), arrival(u, v), weight=length)
            continue
        for h_in in arrivals[u]:
            if h_in != (h + 2) % 4:
                states.add_edge(
                    (u, h_in), arrival(u, v), weight=length + TURN_PENALTY * (h_in != h)
                )
    return states


class AisleGraph:
    """Routes between bays (and lane points) of one warehouse layout."""

    def __init__(self, lanes: Sequence[Lane], bays: Sequence[Bay]) -> None:
        self.graph, crossings = lane_graph(lanes, bays)
        self.states = turn_graph(self.graph, crossings, {bay.point for bay in bays})

    def routes(self, trips: Sequence[tuple[Point, Point]]) -> list[np.ndarray]:
        """(N_k, 2) route of each (start, goal) trip.

        Trips sharing a goal (robots bound for one station) share one reverse
        Dijkstra; every other trip gets its own search from its start.
        """
        sharing = defaultdict(list)
        for k, (_, goal) in enumerate(trips):
            sharing[goal].append(k)
        routes: list[np.ndarray] = [np.empty((0, 2))] * len(trips)
        for goal, members in sharing.items():
            if len(members) == 1:
                start = trips[members[0]][0]
                _, chain = nx.bidirectional_dijkstra(self.states, (start, FREE), (goal, END))
                routes[members[0]] = self._points(chain)
                continue
            towards, _ = nx.dijkstra_predecessor_and_distance(
                self.states.reverse(copy=False), (goal, END)
            )
            for k in members:
                chain = [(trips[k][0], FREE)]
                while chain[-1] != (goal, END):
                    chain.append(towards[chain[-1]][0])
                routes[k] = self._points(chain)
        return routes

    @staticmethod
    def _points(chain: Sequence[State]) -> np.ndarray:
        """(N, 2) the places of a chain of states, each once."""
        places = [chain[0][0]] + [s[0] for a, s in pairwise(chain) if s[0] != a[0]]
        return np.asarray(places, dtype=np.float64)
