"""Nodes from box intervals: folding the intervals into hulls before sorting gives exactly
the nodes of the plain rule (sort each robot's intervals by start; a node starts where an
interval starts more than TOUCH_TOL after every earlier one has ended)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from service.geometry.graph import TOUCH_TOL, _merge_nodes
from service.geometry.interference import Boxes

# Starts on a coarse grid, nudged by about the tolerance, so that intervals touch, overlap
# and leave gaps just below and above TOUCH_TOL in every order.
NUDGES = (-2 * TOUCH_TOL, -TOUCH_TOL, -0.5 * TOUCH_TOL, 0.0, 0.5 * TOUCH_TOL, 1.5 * TOUCH_TOL)
LENGTHS = (0.0, 1e-3, 0.25, 0.5, 1.0)  # 0: a stretch rounded to a point


@st.composite
def box_sets(draw: st.DrawFn) -> tuple[Boxes, int]:
    """Boxes of a few robots whose intervals touch and nearly touch, in any order."""
    n_robots = draw(st.integers(2, 5))
    n = draw(st.integers(0, 60))
    i = np.array([draw(st.integers(0, n_robots - 2)) for _ in range(n)], dtype=np.int64)
    j = np.array([draw(st.integers(a + 1, n_robots - 1)) for a in i.tolist()], dtype=np.int64)

    def intervals() -> tuple[np.ndarray, np.ndarray]:
        lo = np.array(
            [draw(st.integers(0, 12)) * 0.25 + draw(st.sampled_from(NUDGES)) for _ in range(n)]
        )
        lo = np.maximum(lo, 0.0)
        return lo, lo + np.array([draw(st.sampled_from(LENGTHS)) for _ in range(n)])

    (x0, x1), (y0, y1) = intervals(), intervals()
    flags = np.zeros(n, dtype=bool)
    return Boxes(i, j, x0, x1, y0, y1, flags, flags), n_robots


def _plain_nodes(boxes: Boxes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """node_robot (V,), node_span (V, 2) and each interval's node (2B,) by the plain rule."""
    robot = np.concatenate([boxes.i, boxes.j])
    lo = np.concatenate([boxes.x0, boxes.y0])
    hi = np.concatenate([boxes.x1, boxes.y1])
    node_robot, spans, node_of = [], [], np.empty(robot.size, dtype=np.int64)
    for k in np.lexsort((lo, robot)).tolist():
        if not node_robot or node_robot[-1] != robot[k] or lo[k] > spans[-1][1] + TOUCH_TOL:
            node_robot.append(int(robot[k]))
            spans.append([lo[k], hi[k]])
        else:
            spans[-1][1] = max(spans[-1][1], hi[k])
        node_of[k] = len(node_robot) - 1
    return np.array(node_robot, dtype=np.int64), np.array(spans).reshape(-1, 2), node_of


@settings(max_examples=300, deadline=None, derandomize=True)
@given(case=box_sets())
def test_nodes_are_those_of_the_plain_rule(case: tuple[Boxes, int]) -> None:
    boxes, n_robots = case
    node_robot, node_span, node_i, node_j = _merge_nodes(boxes, n_robots)
    want_robot, want_span, want_of = _plain_nodes(boxes)
    assert node_robot.tolist() == want_robot.tolist()
    assert node_span.tolist() == want_span.tolist()
    assert np.concatenate([node_i, node_j]).tolist() == want_of.tolist()
