"""Probes: liveness always, readiness only after warm-up; both answer during long solves."""

from __future__ import annotations

import json
import threading
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest
from anyio import to_thread

from service import main as main_module
from service.api import runtime as runtime_module
from service.api.runtime import Runtime
from service.core.schemas import OBJECTIVES
from service.main import create_app
from service.settings import DEFAULT_MODEL_STORE, Settings
from service.solvers import dispatch as dispatch_module
from service.solvers.registry import SolveContext, SolverOutput

from .helpers import Serve, post_json, wait_ready

pytestmark = pytest.mark.anyio

# Generous bound on every wait; reached only when the behaviour under test is broken.
WAIT_S = 30.0


async def poll_readiness(
    client: httpx.AsyncClient, until: Callable[[dict], bool]
) -> httpx.Response:
    """Poll ``/readyz`` until its body satisfies ``until`` (bounded)."""
    with anyio.fail_after(WAIT_S):
        while not until((response := await client.get("/readyz")).json()):
            await anyio.sleep(0.01)
    return response


async def test_live_and_ready(client: httpx.AsyncClient) -> None:
    assert (await client.get("/healthz")).json() == {"status": "ok"}
    response = await client.get("/readyz")
    assert response.status_code == 200
    body = response.json()
    assert body["ready"] is True
    assert {"exact", "fcfs", "gnn_vae"} <= set(body["solvers"])
    shipped = json.loads((DEFAULT_MODEL_STORE / "manifest.json").read_text())["default"]
    assert body["models"] == {o: f"gnn_vae/{o}/{v}" for o, v in shipped.items()}
    assert body["model_errors"] == {}


async def test_missing_models_degrade_but_stay_ready(
    serve: Serve, tiny: dict[str, Any], tmp_path: Path
) -> None:
    (tmp_path / "manifest.json").write_text('{"default": {"avg_completion": "v9"}}')
    async with serve(Settings(model_store=tmp_path)) as client:
        body = (await client.get("/readyz")).json()
        assert body["ready"] is True and body["models"] == {}
        assert set(body["model_errors"]) == set(OBJECTIVES)
        tiny["options"]["solver"] = "gnn_vae"
        answer = (await post_json(client, tiny)).json()
        assert answer["solver"]["name"] == "exact"
        assert answer["solver"]["fallback_from"] == "gnn_vae"
        assert answer["checks"] == {"acyclic": True, "density": True, "forced": True}


async def test_not_ready_until_warm_up_finishes(
    serve: Serve, monkeypatch: pytest.MonkeyPatch
) -> None:
    release = threading.Event()
    real_dispatch = runtime_module.dispatch

    def slow_dispatch(*args: Any) -> Any:
        release.wait(WAIT_S)
        return real_dispatch(*args)

    monkeypatch.setattr(runtime_module, "dispatch", slow_dispatch)
    async with serve(ready=False) as client:
        try:
            assert (await client.get("/healthz")).status_code == 200
            response = await client.get("/readyz")
            assert response.status_code == 503
            assert response.json()["detail"] == "warming up"
        finally:
            release.set()
        assert (await wait_ready(client)).json()["ready"] is True


async def test_failed_warm_up_stays_live_but_not_ready(
    serve: Serve, monkeypatch: pytest.MonkeyPatch
) -> None:
    def failing_dispatch(*args: Any) -> Any:
        raise RuntimeError("no CP-SAT today")

    monkeypatch.setattr(runtime_module, "dispatch", failing_dispatch)
    async with serve(ready=False) as client:
        response = await poll_readiness(client, lambda b: b["detail"] != "warming up")
        assert response.status_code == 503
        assert response.json()["detail"] == "warm-up failed: RuntimeError: no CP-SAT today"
        assert (await client.get("/healthz")).status_code == 200


async def test_not_ready_when_large_solver_is_not_registered(serve: Serve) -> None:
    async with serve(Settings(large_solver="nope"), ready=False) as client:
        response = await poll_readiness(client, lambda b: b["detail"] != "warming up")
    assert response.status_code == 503
    assert response.json()["detail"] == "solvers not registered: nope"


class BlockingSolver:
    """Stands in for ``auto`` (and ``exact``): blocks until released, then answers with FCFS."""

    def __init__(self) -> None:
        self.entered = 0
        self.started = threading.Event()
        self.release = threading.Event()
        self.timed_out = threading.Event()
        self._fcfs = dispatch_module.get_solver("fcfs")

    def __call__(self, ctx: SolveContext) -> SolverOutput | None:
        self.entered += 1
        self.started.set()
        if not self.release.wait(WAIT_S):
            self.timed_out.set()
        return self._fcfs(ctx)

    def install(self, monkeypatch: pytest.MonkeyPatch) -> None:
        real = dispatch_module.get_solver
        monkeypatch.setattr(
            dispatch_module,
            "get_solver",
            lambda name: self if name in ("auto", "exact") else real(name),
        )


@pytest.fixture
def blocking(monkeypatch: pytest.MonkeyPatch) -> Iterator[BlockingSolver]:
    solver = BlockingSolver()
    solver.install(monkeypatch)
    yield solver
    solver.release.set()


async def test_probes_answer_during_a_long_solve(
    client: httpx.AsyncClient, blocking: BlockingSolver, tiny: dict
) -> None:
    responses: list[httpx.Response] = []
    async with anyio.create_task_group() as tasks:

        async def solve() -> None:
            responses.append(await post_json(client, tiny))

        tasks.start_soon(solve)
        try:
            assert await to_thread.run_sync(blocking.started.wait, WAIT_S)
            assert (await client.get("/healthz")).status_code == 200
            assert (await client.get("/readyz")).status_code == 200
            # Had the solve blocked the event loop, the probes would only have been
            # answered after the solver gave up waiting.
            assert not blocking.timed_out.is_set()
        finally:
            blocking.release.set()
    assert responses[0].status_code == 200


@asynccontextmanager
async def one_running_one_queued(
    client: httpx.AsyncClient, app: Any, monkeypatch: pytest.MonkeyPatch, body: dict
) -> AsyncIterator[tuple[BlockingSolver, Any, list[httpx.Response]]]:
    """Two posts of ``body``: one blocked in its solve, one queued behind it (with one
    solve slot); inside the block both are pending, and they are released on exit."""
    blocking = BlockingSolver()
    blocking.install(monkeypatch)
    pool = app.state.runtime.limiter
    responses: list[httpx.Response] = []
    async with anyio.create_task_group() as tasks:

        async def solve() -> None:
            responses.append(await post_json(client, body))

        tasks.start_soon(solve)
        tasks.start_soon(solve)
        try:
            with anyio.fail_after(WAIT_S):
                while pool.waiting < 1 or not blocking.started.is_set():
                    await anyio.sleep(0.01)
            yield blocking, pool, responses
        finally:
            blocking.release.set()


async def test_solves_beyond_solve_concurrency_wait(
    serve: Serve, monkeypatch: pytest.MonkeyPatch, tiny: dict
) -> None:
    app = create_app()
    async with (
        serve(Settings(solve_concurrency=1), app=app) as client,
        one_running_one_queued(client, app, monkeypatch, tiny) as (blocking, pool, responses),
    ):
        assert blocking.entered == 1 and pool.running == 1
        metrics = (await client.get("/metrics")).text
        assert "scheduler_queued_solves 1.0" in metrics
        assert "scheduler_running_solves 1.0" in metrics
    assert [r.status_code for r in responses] == [200, 200]
    assert blocking.entered == 2


async def test_a_full_queue_is_503_with_retry_after(
    serve: Serve, monkeypatch: pytest.MonkeyPatch, tiny: dict
) -> None:
    app = create_app()
    settings = Settings(solve_concurrency=1, queue_size=1, retry_after_s=3)
    async with serve(settings, app=app) as client:
        async with one_running_one_queued(client, app, monkeypatch, tiny) as (_, _, responses):
            refused = await post_json(client, tiny)
        rejected = (await client.get("/metrics")).text
    assert refused.status_code == 503 and refused.headers["retry-after"] == "3"
    assert "saturated" in refused.json()["detail"]
    assert 'scheduler_rejected_requests_total{reason="saturated"} 1.0' in rejected
    assert [r.status_code for r in responses] == [200, 200]


async def test_queue_wait_counts_in_the_time_limit(
    serve: Serve, monkeypatch: pytest.MonkeyPatch, tiny: dict
) -> None:
    app = create_app()
    async with serve(Settings(solve_concurrency=1), app=app) as client:
        seen: list[float] = []
        real = dispatch_module.get_solver

        def spy(name: str) -> Any:
            solver = real(name)

            def solve(ctx: SolveContext) -> SolverOutput | None:
                seen.append(ctx.time_limit_s)
                return solver(ctx)

            return solve

        blocking = BlockingSolver()
        blocking.install(monkeypatch)
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(post_json, client, tiny)
            with anyio.fail_after(WAIT_S):
                while not blocking.started.is_set():
                    await anyio.sleep(0.01)
            tiny["options"] = {"solver": "fcfs", "time_limit_s": 2.0}
            tasks.start_soon(post_json, client, tiny)
            await anyio.sleep(0.5)
            monkeypatch.setattr(dispatch_module, "get_solver", spy)
            blocking.release.set()
    assert seen and seen[0] < 1.6  # waited >= 0.5 s of its 2 s in the queue


async def test_post_before_ready_is_503_with_retry_after(
    serve: Serve, monkeypatch: pytest.MonkeyPatch, tiny: dict
) -> None:
    release = threading.Event()
    real_warm_up = runtime_module.warm_up

    def slow_warm_up(runtime: Runtime) -> None:
        release.wait(WAIT_S)
        real_warm_up(runtime)

    monkeypatch.setattr(main_module, "warm_up", slow_warm_up)
    async with serve(Settings(retry_after_s=2), ready=False) as client:
        try:
            response = await post_json(client, tiny)
        finally:
            release.set()
        await wait_ready(client)
        assert (await post_json(client, tiny)).status_code == 200
    assert response.status_code == 503 and response.headers["retry-after"] == "2"
    assert "not ready yet (warming up)" in response.json()["detail"]
