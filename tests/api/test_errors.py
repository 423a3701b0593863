"""Every bad input gets its 4xx with a message naming the offending field or id; never a 500."""

from __future__ import annotations

import math
import time
from collections.abc import AsyncIterator, Callable
from typing import Any

import httpx
import numpy as np
import pytest

from service.core.assignment import Assignments
from service.settings import Settings
from service.solvers import dispatch as dispatch_module
from service.solvers.registry import SolveContext, SolverOutput

from .helpers import TINY, Serve, multipartite, post_json

pytestmark = pytest.mark.anyio

Request = dict[str, Any]
Edit = Callable[[Request], None]


def put(*path_and_value: Any) -> Edit:
    """An edit setting ``request[k1][k2]...[kn] = value`` for ``put(k1, ..., kn, value)``."""
    *keys, last, value = path_and_value

    def edit(request: Request) -> None:
        target = request
        for key in keys:
            target = target[key]
        target[last] = value

    return edit


def add_conflict(conflict: dict[str, Any]) -> Edit:
    return lambda request: request["conflicts"].append(conflict)


def reverse_nodes(request: Request) -> None:
    request["robots"][0]["nodes"].reverse()


def messages(response: httpx.Response) -> list[str]:
    """Each error of a 422 as ``loc.joined: msg``."""
    return [".".join(map(str, e["loc"])) + ": " + e["msg"] for e in response.json()["detail"]]


NODE = ("robots", 0, "nodes", 0)
NODE_LOC = "body.robots.0.nodes.0"

# (edit of the tiny request, text one error message must contain)
INVALID: dict[str, tuple[Edit, str]] = {
    # rules spanning several fields (service.core.problem)
    "unknown node in conflict": (put("conflicts", 0, "b", "ghost"), "unknown node id 'ghost'"),
    "conflict within one robot": (
        add_conflict({"a": "r1/a", "b": "r1/b"}),
        "'r1/a' and 'r1/b' of the same robot 'r1'",
    ),
    "duplicate robot id": (put("robots", 1, "id", "r1"), "duplicate robot id 'r1'"),
    "duplicate node id": (put("robots", 1, "nodes", 1, "id", "r1/b"), "duplicate node id 'r1/b'"),
    "duplicate conflict": (add_conflict({"a": "r1/b", "b": "r2/b"}), "duplicate conflict"),
    "duplicate conflict reversed": (
        add_conflict({"a": "r2/b", "b": "r1/b"}),
        "conflicts.3: duplicate conflict between 'r2/b' and 'r1/b'",
    ),
    "exit equals enter": (put(*NODE, "exit", 0.0), f"{NODE_LOC}.exit: node 'r1/a': exit"),
    "exit before enter": (
        put("robots", 2, "nodes", 0, "exit", 3.0),
        "robots.2.nodes.0.exit: node 'r3/a': exit",
    ),
    "pair time outside its node": (
        put("conflicts", 0, "a_exit", 2.2),
        "conflicts.0.a_exit: a_exit (2.2) must lie inside node 'r1/a'",
    ),
    "pair enter not before pair exit": (
        put("conflicts", 0, "b_enter", 2.5),
        "conflicts.0.b_exit: b_exit (2.5) must be greater than b_enter (2.5)",
    ),
    "nodes out of order": (reverse_nodes, "node 'r1/a' must enter (0.0) after node 'r1/b'"),
    "nodes overlapping": (
        put("robots", 0, "nodes", 1, "enter", 1.5),
        "robots.0.nodes.1.enter: node 'r1/b' must enter",
    ),
    "nodes touching": (
        put("robots", 0, "nodes", 1, "enter", 2.0),
        "robots.0.nodes.1.enter: node 'r1/b' must enter",
    ),
    "goal time too early": (
        put("robots", 0, "goal_time", 4.0),
        "robots.0.goal_time: goal_time (4.0) of robot 'r1'",
    ),
    "density limit not a clique": (
        put("density_limits", [{"nodes": ["r1/a", "r3/a"], "max_robots": 1}]),
        "density_limits.0.nodes: nodes are not a clique of the conflict graph: "
        "no conflict between 'r1/a' and 'r3/a'",
    ),
    "density limit unknown node": (
        put("density_limits", [{"nodes": ["r1/a", "ghost"], "max_robots": 1}]),
        "density_limits.0.nodes: unknown node id 'ghost'",
    ),
    "density limit node twice": (
        put("density_limits", [{"nodes": ["r1/a", "r2/a", "r1/a"], "max_robots": 1}]),
        "density_limits.0.nodes: a node is listed twice",
    ),
    # field by field (pydantic)
    "time NaN": (put(*NODE, "enter", math.nan), f"{NODE_LOC}.enter: Input should be a finite"),
    "time Infinity": (put(*NODE, "exit", math.inf), f"{NODE_LOC}.exit: Input should be a finite"),
    "time negative": (put(*NODE, "enter", -1.0), f"{NODE_LOC}.enter: Input should be greater"),
    "time huge": (put(*NODE, "exit", 2e9), f"{NODE_LOC}.exit: Input should be less than"),
    "time string": (put(*NODE, "enter", "0.0"), f"{NODE_LOC}.enter: Input should be a valid"),
    "time boolean": (put(*NODE, "enter", False), f"{NODE_LOC}.enter: Input should be a valid"),
    "goal time NaN": (put("robots", 0, "goal_time", math.nan), "robots.0.goal_time"),
    "pair time NaN": (put("conflicts", 0, "a_enter", math.nan), "conflicts.0.a_enter"),
    "density 0": (put(*NODE, "density", 0), f"{NODE_LOC}.density: Input should be greater"),
    "density fractional": (put(*NODE, "density", 1.5), f"{NODE_LOC}.density: Input should be"),
    "robot without nodes": (put("robots", 0, "nodes", []), "body.robots.0.nodes: List should"),
    "no robots": (put("robots", []), "body.robots: List should have at least 1 item"),
    "unknown top-level field": (put("densty", 2), "body.densty: Extra inputs"),
    "unknown robot field": (put("robots", 0, "densty", 2), "body.robots.0.densty: Extra"),
    "unknown node field": (put(*NODE, "densty", 2), f"{NODE_LOC}.densty: Extra"),
    "unknown conflict field": (put("conflicts", 0, "densty", 2), "conflicts.0.densty: Extra"),
    "unknown density limit field": (
        put("density_limits", [{"nodes": ["r1/b", "r2/b"], "max_robots": 1, "densty": 2}]),
        "density_limits.0.densty: Extra",
    ),
    "unknown options field": (put("options", "densty", 2), "body.options.densty: Extra"),
    "unknown objective": (put("objective", "fastest"), "body.objective: Input should be"),
    "unknown solver": (put("options", "solver", "magic"), "body.options.solver: Input should"),
    "samples 0": (put("options", "samples", 0), "body.options.samples: Input should be greater"),
    "samples 1001": (put("options", "samples", 1001), "body.options.samples: Input should be less"),
    "time limit 0": (put("options", "time_limit_s", 0), "body.options.time_limit_s: Input should"),
    "time limit 301": (put("options", "time_limit_s", 301), "body.options.time_limit_s: Input"),
    # integers beyond 64 bits (numpy cannot hold them): refused by the wire models' bounds
    "density 2^63": (put(*NODE, "density", 2**63), f"{NODE_LOC}.density: Input should be less"),
    "max_robots 2^63": (
        put("density_limits", [{"nodes": ["r1/b", "r2/b"], "max_robots": 2**63}]),
        "density_limits.0.max_robots: Input should be less",
    ),
    "seed 2^63": (put("options", "seed", 2**63), "body.options.seed: Input should be less"),
    "samples 2^63": (put("options", "samples", 2**63), "body.options.samples: Input should"),
    "time limit 2^63": (put("options", "time_limit_s", 2**63), "body.options.time_limit_s"),
    "time 10^400": (put(*NODE, "exit", 10**400), f"{NODE_LOC}.exit: Input should be a valid"),
}


@pytest.mark.parametrize(("edit", "needle"), INVALID.values(), ids=INVALID.keys())
async def test_invalid_request_is_422_naming_the_fault(
    client: httpx.AsyncClient, tiny: Request, edit: Edit, needle: str
) -> None:
    edit(tiny)
    response = await post_json(client, tiny)
    assert response.status_code == 422, response.text
    assert all(set(e) == {"loc", "msg", "type"} for e in response.json()["detail"])
    assert any(needle in m for m in messages(response)), messages(response)


@pytest.mark.parametrize(
    ("body", "content_type", "needle"),
    [
        (b'{"robots": [', "application/json", "body.12: JSON decode error: Expecting value"),
        (b"[]", "application/json", "body: Input should be a valid dictionary"),
        (b"", "application/json", "body: Field required"),
        (TINY.read_bytes(), "text/plain", "body: Input should be a valid dictionary"),
        (b"[" * 100_000 + b"]" * 100_000, "application/json", "body: JSON decode error: max"),
        (b"9" * 5000, "application/json", "body: JSON decode error: Exceeds the limit"),
    ],
    ids=["malformed", "not an object", "empty", "not declared JSON", "deep", "long integer"],
)
async def test_malformed_json_is_422(
    client: httpx.AsyncClient, body: bytes, content_type: str, needle: str
) -> None:
    response = await client.post(
        "/v1/schedules", content=body, headers={"content-type": content_type}
    )
    assert response.status_code == 422, response.text
    assert any(needle in m for m in messages(response)), messages(response)


async def test_body_over_cap_by_content_length_is_413(serve: Serve, tiny: Request) -> None:
    async with serve(Settings(max_body_bytes=200)) as client:
        response = await post_json(client, tiny)
    assert response.status_code == 413
    assert "max_body_bytes (200)" in response.json()["detail"]


async def test_body_over_cap_without_content_length_is_413(serve: Serve) -> None:
    async def chunks() -> AsyncIterator[bytes]:
        for _ in range(10):
            yield b" " * 50

    async with serve(Settings(max_body_bytes=200)) as client:
        response = await client.post(
            "/v1/schedules", content=chunks(), headers={"content-type": "application/json"}
        )
    assert response.status_code == 413
    assert "more than 200 bytes exceeds max_body_bytes" in response.json()["detail"]


async def test_body_under_cap_streamed_in_chunks_is_served(serve: Serve, tiny: Request) -> None:
    body = httpx.Request("POST", "/", json=tiny).content

    async def chunks() -> AsyncIterator[bytes]:
        for i in range(0, len(body), 100):
            yield body[i : i + 100]

    async with serve(Settings(max_body_bytes=len(body))) as client:
        response = await client.post(
            "/v1/schedules", content=chunks(), headers={"content-type": "application/json"}
        )
    assert response.status_code == 200, response.text


@pytest.mark.parametrize(
    ("cap", "needle"),
    [
        ({"max_robots": 2}, "3 robots exceed max_robots (2)"),
        ({"max_nodes": 4}, "5 nodes exceed max_nodes (4)"),
        ({"max_conflicts": 2}, "3 conflicts exceed max_conflicts (2)"),
    ],
    ids=["robots", "nodes", "conflicts"],
)
async def test_problem_over_cap_is_413_naming_the_cap(
    serve: Serve, tiny: Request, cap: dict[str, int], needle: str
) -> None:
    async with serve(Settings(**cap)) as client:
        response = await post_json(client, tiny)
    assert response.status_code == 413
    assert needle in response.json()["detail"]


def broken(name: str) -> Callable[[SolveContext], SolverOutput | None]:
    """Every solver raises."""

    def solve(ctx: SolveContext) -> SolverOutput | None:
        raise RuntimeError(f"solver {name} exploded")

    return solve


def cyclic(name: str) -> Callable[[SolveContext], SolverOutput | None]:
    """Every solver answers a2 -> b1 and b2 -> a1: with the paths, a cycle."""
    return lambda ctx: SolverOutput(Assignments.single(np.array([False, True]), np.zeros(2)))


@pytest.mark.parametrize("get_solver", [broken, cyclic], ids=["raises", "invalid answer"])
async def test_solver_failure_is_503_never_500(
    client: httpx.AsyncClient,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    get_solver: Callable[[str], Any],
) -> None:
    crossing = {
        "robots": [
            {
                "id": r,
                "nodes": [
                    {"id": f"{r}1", "enter": 0, "exit": 1},
                    {"id": f"{r}2", "enter": 2, "exit": 3},
                ],
            }
            for r in ("a", "b")
        ],
        "conflicts": [{"a": "a1", "b": "b2"}, {"a": "a2", "b": "b1"}],
    }
    monkeypatch.setattr(dispatch_module, "get_solver", get_solver)
    response = await post_json(client, crossing)
    assert response.status_code == 503
    assert "failed unexpectedly" in response.json()["detail"]
    assert "unexpected error in POST /v1/schedules" in caplog.text


async def test_a_conflict_graph_with_too_many_cliques_is_413_in_time(
    client: httpx.AsyncClient,
) -> None:
    request = multipartite(8, 5, time_limit_s=30.0)  # 5^8 = 390,625 maximal cliques
    start = time.monotonic()
    response = await post_json(client, request)
    assert response.status_code == 413, response.text
    assert "more than 20000 maximal cliques (max_cliques)" in response.json()["detail"]
    assert time.monotonic() - start < 5.0  # refused long before its time limit


async def test_the_clique_bounds_are_settings(serve: Serve) -> None:
    async with serve(Settings(max_clique_incidences=2)) as client:
        response = await post_json(client, multipartite(3, 1))  # one clique of 3 conflicts
    assert response.status_code == 413
    assert "more than 2 conflicts in all (max_clique_incidences)" in response.json()["detail"]
    async with serve(Settings(max_cliques=7)) as client:
        response = await post_json(client, multipartite(3, 2))  # 2^3 = 8 cliques
    assert response.status_code == 413
    assert "more than 7 maximal cliques (max_cliques)" in response.json()["detail"]
