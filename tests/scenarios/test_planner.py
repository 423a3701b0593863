"""The grid planner: landmark hops, and a floor with obstacles added to a planned one."""

from __future__ import annotations

import networkx as nx
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from service.scenarios.planner import GridPlanner, hop_distances
from service.scenarios.shapes import Box, Disk


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(0.0, 0.6))
def test_hops_are_breadth_first_distances_on_the_free_cells(seed: int, blocked: float) -> None:
    rng = np.random.default_rng(seed)
    free = rng.random((7, 9)) >= blocked  # (H, W)
    source = (int(rng.integers(7)), int(rng.integers(9)))
    free[source] = True
    grid = nx.grid_2d_graph(7, 9)
    grid.add_edges_from(
        ((i, j), (i + 1, j + dj))
        for i in range(6)
        for j in range(9)
        for dj in (-1, 1)
        if 0 <= j + dj < 9
    )
    hops = nx.single_source_shortest_path_length(
        grid.subgraph(map(tuple, np.argwhere(free))), source
    )
    expected = np.full(free.shape, np.inf)
    for (i, j), d in hops.items():
        expected[i, j] = d
    assert np.array_equal(hop_distances(free, source), expected.ravel())


FLOOR = (0.0, 0.0, 12.0, 8.0)
SHAPES = [Box(3.0, 0.0, 3.6, 5.0), Disk(8.0, 5.0, 1.0)]
ADDED = [Disk(6.0, 2.0, 0.9), Box(9.0, 1.0, 11.0, 1.6)]


def test_obstacles_added_to_a_floor_plan_as_a_floor_built_with_them() -> None:
    base = GridPlanner(FLOOR, SHAPES, 0.25, 2.0)
    added = base.with_obstacles(ADDED)
    whole = GridPlanner(FLOOR, [*SHAPES, *ADDED], 0.25, 2.0)
    assert np.array_equal(added.clearance, whole.clearance)
    assert not np.array_equal(base.clearance, whole.clearance)  # the base is left as it was
    rng = np.random.default_rng(0)
    ends = rng.uniform((0.0, 0.0), (12.0, 8.0), (200, 2))
    for a in ends[:10]:
        assert np.array_equal(
            added.segments_clear(a, ends, 0.3), whole.segments_clear(a, ends, 0.3)
        )
    for start, goal in [((2, 2), (20, 44)), ((28, 2), (10, 44)), ((8, 17), (8, 31))]:
        assert np.array_equal(added.plan(start, goal, 0.3), whole.plan(start, goal, 0.3))
    route = added.plan((8, 17), (8, 31), 0.3)  # straight through the added disk on the base
    assert not np.array_equal(route, base.plan((8, 17), (8, 31), 0.3))
