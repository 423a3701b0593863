"""A hand-made paths-form request/response: three robots crossing, one of them waiting.

- ``amr-a`` drives east along y = 0 from t = 0 at 1 m/s.
- ``amr-b`` drives north along x = 5; it waits at (5, -1) from t = 4 to 6.5 so
  that ``amr-a`` clears the crossing (exclusive), then goes on.
- ``amr-c`` goes north along x = 2 then east along y = 3 from t = 1: it follows
  ``amr-a`` over the first crossing and passes ``amr-b`` on the second.
"""

from __future__ import annotations

from typing import Any

import pytest

Json = dict[str, Any]


@pytest.fixture
def request_body() -> Json:
    """The paths-form request."""
    return {
        "objective": "avg_completion",
        "robots": [
            {"id": "amr-a", "path": [[0, 0], [10, 0]], "radius": 0.4, "speed": 1.0},
            {"id": "amr-b", "path": [[5, -5], [5, 5]], "radius": 0.5, "speed": 1.0},
            {
                "id": "amr-c",
                "path": [[2, -3], [2, 3], [8, 3]],
                "radius": 0.3,
                "speed": 1.0,
                "start_time": 1.0,
            },
        ],
    }


def _node(node_id: str, enter: float, exit_: float) -> Json:
    """A scheduled node occupation."""
    return {"id": node_id, "enter": enter, "exit": exit_}


@pytest.fixture
def response_body() -> Json:
    """The 200 answer to ``request_body``: assignment, schedule, spans, trajectories."""
    return {
        "assignment": [
            {"from": "a0", "to": "b0", "type": "exclusive"},
            {"from": "a1", "to": "c0", "type": "following"},
            {"from": "c1", "to": "b1", "type": "exclusive"},
        ],
        "schedule": [
            {
                "robot": "amr-a",
                "completion": 10.0,
                "delay": 0.0,
                "nodes": [_node("a1", 1, 3), _node("a0", 4, 6)],
            },
            {
                "robot": "amr-b",
                "completion": 12.5,
                "delay": 2.5,
                "nodes": [_node("b0", 6.5, 8.5), _node("b1", 9.5, 11.5)],
            },
            {
                "robot": "amr-c",
                "completion": 13.0,
                "delay": 0.0,
                "nodes": [_node("c0", 3, 5), _node("c1", 9, 11)],
            },
        ],
        "graph": None,
        "node_spans": {
            "a0": [4.0, 6.0],
            "a1": [1.0, 3.0],
            "b0": [4.0, 6.0],
            "b1": [7.0, 9.0],
            "c0": [2.0, 4.0],
            "c1": [8.0, 10.0],
        },
        "trajectories": [
            {"robot": "amr-a", "points": [[0, 0, 0], [10, 10, 0]]},
            {"robot": "amr-b", "points": [[0, 5, -5], [4, 5, -1], [6.5, 5, -1], [12.5, 5, 5]]},
            {"robot": "amr-c", "points": [[1, 2, -3], [7, 2, 3], [13, 8, 3]]},
        ],
    }


@pytest.fixture
def world_body() -> Json:
    """Floor bounds and two rack blocks clear of the paths."""
    return {
        "bounds": [-1, -6, 11, 6],
        "obstacles": [
            [[6, -4], [9, -4], [9, -2], [6, -2]],
            [[6, 4], [9, 4], [9, 5.5], [6, 5.5]],
        ],
    }
