"""Hand-made fleets for the situations issue 10 names (robots as wire dicts).

Robots drive at 1 m/s with radius 0.4 unless said otherwise; the default geometry
(resolution 0.25 m, margin 0.05 m) makes two such robots interfere within 0.85 m.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from tests.motion.worlds import robot

__all__ = ["SCENARIOS", "Fleet"]

Fleet = list[dict[str, Any]]


def faster_follower() -> Fleet:
    """A fast robot behind a slow one on the same line: it must follow, never pass."""
    return [
        robot("lead", [[0, 0], [20, 0]], speed=0.5),
        robot("fast", [[-6, 0], [20, 0]], speed=2.0),
    ]


def leader_stopped() -> Fleet:
    """A leader and a follower in one corridor; a third robot parked across it at x=10
    until t=12 stops the leader inside the shared section."""
    return [
        robot("lead", [[0, 0], [20, 0]]),
        robot("follow", [[-3, 0], [20, 0]], speed=1.5),
        robot("cross", [[10, 0.3], [10, 10]], speed=0.5, start_time=12.0),
    ]


def parked_start() -> Fleet:
    """A robot waiting at its start (until t=6) 0.3 m beside another one's route."""
    return [
        robot("drive", [[0, 0], [10, 0]]),
        robot("parked", [[5, 0.3], [5, 8]], start_time=6.0),
    ]


def head_on() -> Fleet:
    """A one-lane corridor from x=0 to x=10 entered from both ends at once."""
    return [
        robot("east", [[-5, -3], [0, 0], [10, 0], [15, 3]]),
        robot("west", [[15, -3], [10, 0], [0, 0], [-5, 3]], speed=1.2),
    ]


def queue() -> Fleet:
    """Four robots in a row on one corridor, the ones behind faster."""
    return [robot(f"q{k}", [[-2.0 * k, 0], [20, 0]], speed=0.6 + 0.3 * k) for k in range(4)]


def intersection() -> Fleet:
    """Four robots crossing one point at 45 degree steps, all arriving at about t=5."""
    out = []
    for k in range(4):
        d = np.array([np.cos(k * np.pi / 4), np.sin(k * np.pi / 4)])
        out.append(robot(f"x{k}", [(-5 * d).tolist(), (5 * d).tolist()], speed=1.0 + 0.1 * k))
    return out


def three_way() -> Fleet:
    """Three robots through one point at 120 degrees, arriving together."""
    out = []
    for k in range(3):
        d = np.array([np.cos(2 * k * np.pi / 3), np.sin(2 * k * np.pi / 3)])
        out.append(robot(f"y{k}", [(-4 * d).tolist(), (4 * d).tolist()]))
    return out


def merge_diverge() -> Fleet:
    """Two robots merge into one lane from x=-2 to x=6 and diverge after it."""
    return [
        robot("up", [[-10, 4], [-2, 0], [6, 0], [14, 4]]),
        robot("down", [[-10, -4], [-2, 0], [6, 0], [14, -4]], speed=1.1),
    ]


def issue_example() -> Fleet:
    """The request of issue 10: one robot with speed and start time, one with times."""
    return [
        robot("amr-001", [[1.5, 0.5], [1.5, 7.5], [9.5, 7.5]], speed=1.0, start_time=3.25),
        robot("amr-002", [[0.0, 3.0], [4.0, 3.0], [12.0, 3.0]], times=[0.0, 8.0, 12.0]),
    ]


def out_and_back() -> Fleet:
    """A robot driving an aisle out and back while another crosses it twice (a zigzag)."""
    return [
        robot("aisle", [[0, 0], [10, 0], [0, 0.1]], speed=1.5),
        robot("zigzag", [[3, -4], [3, 4], [7, 4], [7, -4]], start_time=1.0),
    ]


SCENARIOS: dict[str, Callable[[], Fleet]] = {
    f.__name__: f
    for f in (
        faster_follower,
        leader_stopped,
        parked_start,
        head_on,
        queue,
        intersection,
        three_way,
        merge_diverge,
        issue_example,
        out_and_back,
    )
}
