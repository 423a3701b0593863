"""POST /v1/schedules as a re-schedule (previous + progress): every solver keeps the past,
answers from progress.time on, and bad progress is a 422 naming the field."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from service.core.schemas import SOLVER_NAMES

from .helpers import post_json

pytestmark = pytest.mark.anyio


async def _first_answer(client: httpx.AsyncClient, tiny: dict[str, Any]) -> dict[str, Any]:
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    return response.json()


def _late_r2(answer: dict[str, Any]) -> dict[str, Any]:
    """At 3.2 s: r1 passed r1/a (its section of conflict 0 too), r2 entered conflict 0's
    section (planned 1.0) and runs 2 s late; r3 has not started."""
    return {
        "previous": answer["assignment"],
        "progress": {
            "time": 3.2,
            "robots": {
                "r1": {"passed_until": 2.0, "delay": 0.0},
                "r2": {"passed_until": 1.0, "delay": 2.0},
            },
        },
    }


async def test_dependencies_come_with_every_answer(
    client: httpx.AsyncClient, tiny: dict[str, Any]
) -> None:
    answer = await _first_answer(client, tiny)
    plan = {d["robot"]: d["waits"] for d in answer["dependencies"]}
    assert set(plan) == {"r1", "r2", "r3"}
    second = {(x["from"], x["to"]) for x in answer["assignment"]}
    # Whoever passes second at conflict 0 waits at its pair enter (1.0) for the first.
    waiter = "r2" if ("r1/a", "r2/a") in second else "r1"
    assert any(w["time"] == 1.0 for w in plan[waiter])


@pytest.mark.parametrize("solver", SOLVER_NAMES)
async def test_every_solver_reschedules_from_progress_keeping_the_past(
    client: httpx.AsyncClient, tiny: dict[str, Any], solver: str
) -> None:
    first = await _first_answer(client, tiny)
    assert first["assignment"][0] == {"from": "r1/a", "to": "r2/a", "type": "exclusive"}
    body = {**tiny, **_late_r2(first)}
    body["options"] = {**tiny["options"], "solver": solver}
    response = await post_json(client, body)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert answer["checks"] == {"acyclic": True, "density": True, "forced": True}
    assert answer["assignment"][0] == first["assignment"][0]  # realized: kept as it was
    schedule = {s["robot"]: s for s in answer["schedule"]}
    assert schedule["r2"]["completion"] >= 5.5 + 2.0  # at least 2 s late from now on
    assert schedule["r3"]["nodes"][0]["enter"] >= 4.0  # not before its planned time
    plan = {d["robot"]: d["waits"] for d in answer["dependencies"]}
    assert all(w["time"] > 1.0 for w in plan["r2"])  # nothing left at passed points


@pytest.mark.parametrize(
    ("progress", "loc"),
    [
        ({"time": 3.0, "robots": {"r9": {}}}, ["body", "progress", "robots", "r9"]),
        (
            {"time": 3.0, "robots": {"r1": {"passed_until": 5.0}}},
            ["body", "progress", "robots", "r1", "passed_until"],
        ),
        (
            {"time": 3.0, "robots": {"r1": {"delay": -1.0}}},
            ["body", "progress", "robots", "r1", "delay"],
        ),
    ],
)
async def test_bad_progress_is_422_naming_the_field(
    client: httpx.AsyncClient, tiny: dict[str, Any], progress: dict[str, Any], loc: list[Any]
) -> None:
    response = await post_json(client, {**tiny, "progress": progress})
    assert response.status_code == 422, response.text
    assert response.json()["detail"][0]["loc"] == loc
