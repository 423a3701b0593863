"""Reading the request, response and world dicts the pictures are drawn from."""

from __future__ import annotations

import pytest

from service.pictures.layout import conflict_sections
from service.pictures.plan import (
    node_categories,
    node_owners,
    plot_bounds,
    robot_waits,
)
from tests.pictures.conftest import Json


def test_gantt_waits_find_the_robot_held_before_the_crossing(response_body: Json) -> None:
    assert robot_waits(response_body) == {"amr-a": [], "amr-b": [(4.0, 6.5)], "amr-c": []}


def test_waits_end_at_the_scheduled_completion(response_body: Json) -> None:
    response_body["schedule"][1]["completion"] = 5.0
    assert robot_waits(response_body)["amr-b"] == [(4.0, 5.0)]


def test_following_wins_over_exclusive(response_body: Json) -> None:
    response_body["assignment"].append({"from": "a0", "to": "c1", "type": "following"})
    categories = node_categories(response_body)
    assert categories["a0"] == "following"
    assert categories["b0"] == "exclusive"
    assert categories["c0"] == "following"


def test_node_owners_come_from_schedule_and_graph(response_body: Json) -> None:
    response_body["graph"] = {"robots": [{"id": "amr-c", "nodes": [{"id": "c9"}]}]}
    owners = node_owners(response_body)
    assert owners["a0"] == "amr-a" and owners["b1"] == "amr-b" and owners["c9"] == "amr-c"


def test_conflict_sections_follow_the_owner_path(request_body: Json, response_body: Json) -> None:
    sections = {
        k: [line.tolist() for line in v]
        for k, v in conflict_sections(request_body, response_body).items()
    }
    assert sections["following"] == [[[1, 0], [3, 0]], [[2, -1], [2, 1]]]
    assert [[4, 3], [6, 3]] in sections["exclusive"]
    assert [[5, -1], [5, 1]] in sections["exclusive"]
    assert len(sections["exclusive"]) == 4


def test_bounds_from_world_or_from_paths(request_body: Json, world_body: Json) -> None:
    assert plot_bounds(request_body, world_body) == (-1, -6, 11, 6)
    # Paths span x 0..10, y -5..5: margin 5 % of 10 m plus the largest radius 0.5 m.
    assert plot_bounds(request_body) == pytest.approx((-1.0, -6.0, 11.0, 6.0))


def test_sections_without_assignment_are_unassigned(
    request_body: Json, response_body: Json
) -> None:
    del response_body["assignment"]
    assert list(conflict_sections(request_body, response_body)) == ["unassigned"]
