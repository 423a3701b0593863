"""World: JSON round trip and the request body."""

from __future__ import annotations

import json

from service.scenarios import World, generate


def test_json_round_trip_keeps_everything() -> None:
    world = generate("floor_mixed", 12, seed=3)
    again = World.from_json(world.to_json())
    assert again == world
    assert len(again.obstacle_polygons()) == len(world.obstacles) > 0


def test_request_body_is_the_paths_form() -> None:
    world = generate("wh_two_lane", 5, seed=0)
    body = world.to_request("max_completion", {"time_limit_s": 2.0})
    assert set(body) == {"objective", "robots", "options"}
    assert body["objective"] == "max_completion"
    assert body["options"] == {"time_limit_s": 2.0}
    assert body["robots"] == world.robots and body["robots"] is not world.robots
    assert json.loads(json.dumps(body)) == body
    assert world.to_request()["options"] == {}
