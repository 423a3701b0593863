"""Property: on random valid problems, every API answer passes the independent checks."""

from __future__ import annotations

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core.schemas import OBJECTIVES
from service.learning.generate import small_problem

from .helpers import assert_valid_answer, post_json

pytestmark = pytest.mark.anyio


@settings(
    max_examples=60,
    deadline=None,  # CP-SAT start-up times vary with machine load
    # One app serves every example: answers do not depend on earlier requests.
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    seed=st.integers(0, 2**32 - 1),
    objective=st.sampled_from(OBJECTIVES),
    solver=st.sampled_from(("auto", "exact", "fcfs")),
)
async def test_every_answer_on_random_problems_is_valid(
    client: httpx.AsyncClient, seed: int, objective: str, solver: str
) -> None:
    request = small_problem(seed, objective)
    request["options"] = {"solver": solver, "time_limit_s": 10.0, "seed": seed % 1000}
    response = await post_json(client, request)
    assert response.status_code == 200, response.text
    assert_valid_answer(request, response.json())
