"""POST /v1/schedules with fixed directions: honoured by every solver, circular waits are 422."""

from __future__ import annotations

from typing import Any

import httpx
import pytest

from service.core.schemas import SOLVER_NAMES

from .helpers import assert_valid_answer, post_json

pytestmark = pytest.mark.anyio

# Robot r2 fixed first everywhere: r2/a before r1/a, r2/b before r1/b and r3/a. FCFS
# (and the free optimum) let r1, which enters earlier, pass first at r1/a.
R2_FIRST = ("b", "b", "a")


@pytest.mark.parametrize("solver", SOLVER_NAMES)
async def test_every_solver_honours_fixed_directions(
    client: httpx.AsyncClient, tiny: dict[str, Any], solver: str
) -> None:
    tiny["options"]["solver"] = solver
    for conflict, first in zip(tiny["conflicts"], R2_FIRST, strict=True):
        conflict["first"] = first
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert_valid_answer(tiny, answer)
    assert answer["checks"]["forced"] is True
    decided = [(x["from"], x["to"]) for x in answer["assignment"]]
    assert decided == [("r2/a", "r1/a"), ("r2/b", "r1/b"), ("r2/b", "r3/a")]


async def test_free_answer_differs_from_the_fixed_one(
    client: httpx.AsyncClient, tiny: dict[str, Any]
) -> None:
    """Without fixed directions r1 passes first at r1/a: the test above is not vacuous."""
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    assert response.json()["assignment"][0]["from"] == "r1/a"


async def test_circular_wait_of_fixed_directions_is_422(
    client: httpx.AsyncClient, tiny: dict[str, Any]
) -> None:
    """r1/b before r2/a, r2/a before r1/a, and r1/a before r1/b on r1's path: a cycle."""
    tiny["conflicts"][0]["first"] = "b"
    tiny["conflicts"].append({"a": "r1/b", "b": "r2/a", "first": "a"})
    response = await post_json(client, tiny)
    assert response.status_code == 422, response.text
    errors = response.json()["detail"]
    assert [e["loc"] for e in errors] == [
        ["body", "conflicts", 0, "first"],
        ["body", "conflicts", 3, "first"],
    ]
    assert all("fixed directions form a circular wait" in e["msg"] for e in errors)
    assert all("conflicts [0, 3]" in e["msg"] for e in errors)


async def test_unknown_first_side_is_422(client: httpx.AsyncClient, tiny: dict[str, Any]) -> None:
    tiny["conflicts"][0]["first"] = "c"
    response = await post_json(client, tiny)
    assert response.status_code == 422, response.text
    assert response.json()["detail"][0]["loc"] == ["body", "conflicts", 0, "first"]
