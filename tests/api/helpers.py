"""Helpers of the HTTP tests: posting, waiting for readiness, checking answers independently."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import AbstractAsyncContextManager, contextmanager
from pathlib import Path
from typing import Any

import anyio
import httpx
import numpy as np
import pytest

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import find_cliques
from service.core.evaluate import Evaluator
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest

TINY = Path(__file__).parents[2] / "schemas" / "examples" / "tiny.json"
READY_TIMEOUT_S = 180.0  # warm-up compiles every numba kernel on a fresh clone (no cache)
# A server process: imports (torch, ortools) and warm-up on a loaded machine.
START_TIMEOUT_S = 120.0

# The ``serve`` fixture: ``async with serve(settings, ready=..., app=...) as client``.
Serve = Callable[..., AbstractAsyncContextManager[httpx.AsyncClient]]


async def wait_ready(client: httpx.AsyncClient) -> httpx.Response:
    """Poll ``/readyz`` until it answers 200 (bounded)."""
    with anyio.fail_after(READY_TIMEOUT_S):
        while (response := await client.get("/readyz")).status_code != 200:
            await anyio.sleep(0.01)
    return response


def free_port() -> int:
    """A loopback port nothing listens on (now)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@contextmanager
def service_process(log: Path) -> Iterator[str]:
    """Base URL of a ``python -m service`` on a free port, logging to ``log``; stopped after.

    The log is printed at the end (pytest shows it only when the test failed).
    """
    port = free_port()
    env = {**os.environ, "SCHEDULER_HOST": "127.0.0.1", "SCHEDULER_PORT": str(port)}
    with log.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "service"], env=env, stdout=out, stderr=subprocess.STDOUT
        )
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        process.terminate()
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=20)
        print(log.read_text())


def wait_ready_sync(client: httpx.Client) -> None:
    """Poll a server process's ``/readyz`` until it answers 200 (bounded)."""
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        try:
            if client.get("/readyz").status_code == 200:
                return
        except httpx.TransportError:
            pass
        time.sleep(0.2)
    pytest.fail(f"service not ready within {START_TIMEOUT_S} s")


async def post_json(client: httpx.AsyncClient, body: Any) -> httpx.Response:
    """POST ``body`` to /v1/schedules as JSON; NaN and Infinity are sent as JS literals."""
    return await client.post(
        "/v1/schedules", content=json.dumps(body), headers={"content-type": "application/json"}
    )


def assert_valid_answer(request: dict[str, Any], answer: dict[str, Any]) -> None:
    """Check ``answer`` against ``request`` independently of the service's own checks.

    Every conflict appears exactly once in the assignment, the schedule has one entry
    per robot with its nodes in order, and the assignment mapped back to indices
    passes :func:`service.core.check.check` and costs what the answer says.
    """
    objective = request.get("objective", "avg_completion")
    request_conflicts = request.get("conflicts", [])
    conflicts = [frozenset((c["a"], c["b"])) for c in request_conflicts]
    decided = Counter(frozenset((x["from"], x["to"])) for x in answer["assignment"])
    assert decided == Counter(conflicts) and max(decided.values(), default=1) == 1
    assert answer["checks"] == {"acyclic": True, "density": True, "forced": True}
    assert answer["objective"] == objective
    assert answer["cost"] == answer["costs"][objective]
    assert [s["robot"] for s in answer["schedule"]] == [r["id"] for r in request["robots"]]
    for robot, entry in zip(request["robots"], answer["schedule"], strict=True):
        assert [n["id"] for n in entry["nodes"]] == [n["id"] for n in robot["nodes"]]
    problem = problem_from_request(ScheduleRequest.model_validate(request))
    first = {frozenset((x["from"], x["to"])): x for x in answer["assignment"]}
    chosen = [first[pair] for pair in conflicts]
    assignments = Assignments.single(
        np.array([x["from"] == c["a"] for x, c in zip(chosen, request_conflicts, strict=True)]),
        np.array([x["type"] == "following" for x in chosen]),
    )
    assert check(problem, find_cliques(problem), assignments).ok[0]
    cost = Evaluator(problem).evaluate(assignments).costs[objective][0]
    assert cost == pytest.approx(answer["cost"], rel=1e-9, abs=1e-9)


def multipartite(robots: int, nodes: int, time_limit_s: float = 1.0) -> dict[str, Any]:
    """A complete multipartite conflict graph: every node of every robot conflicts with
    every node of every other robot, so it has nodes^robots maximal cliques.
    """
    request: dict[str, Any] = {
        "robots": [
            {
                "id": f"r{r}",
                "nodes": [
                    {"id": f"r{r}n{i}", "enter": 10.0 * i, "exit": 10.0 * i + 5, "density": 2}
                    for i in range(nodes)
                ],
            }
            for r in range(robots)
        ],
        "conflicts": [
            {"a": f"r{a}n{i}", "b": f"r{b}n{j}"}
            for a in range(robots)
            for b in range(a + 1, robots)
            for i in range(nodes)
            for j in range(nodes)
        ],
        "options": {"time_limit_s": time_limit_s},
    }
    return request


def long_chain(robots: int, chain: int, time_limit_s: float = 1.0) -> dict[str, Any]:
    """One robot with ``chain`` nodes, crossed twice by each of ``robots - 1`` short robots.

    The shape of issue 14's memory hog: work that grows with robots x the longest path.
    """
    nodes = [{"id": f"L{i}", "enter": 10.0 * i, "exit": 10.0 * i + 5} for i in range(chain)]
    request: dict[str, Any] = {
        "robots": [{"id": "L", "nodes": nodes}],
        "conflicts": [],
        "options": {"time_limit_s": time_limit_s},
    }
    for r in range(1, robots):
        base = (r * 97) % max(1, chain - 7)
        request["robots"].append(
            {
                "id": f"r{r}",
                "nodes": [
                    {
                        "id": f"r{r}n{j}",
                        "enter": 10.0 * (base + 3 * j),
                        "exit": 10.0 * (base + 3 * j) + 6,
                    }
                    for j in range(3)
                ],
            }
        )
        request["conflicts"] += [{"a": f"L{base + 3 * j}", "b": f"r{r}n{j}"} for j in (0, 2)]
    return request


def without_fast_parse(monkeypatch: pytest.MonkeyPatch) -> None:
    """No body validated from its bytes (:mod:`service.api.body`): every body left to
    FastAPI (decoded, then validated), as before session 43."""
    from service.api import body

    monkeypatch.setattr(body, "_validated", lambda model, raw: None)
