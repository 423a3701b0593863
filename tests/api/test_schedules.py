"""POST /v1/schedules on valid requests: every solver, every objective, the wire format."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

import httpx
import pytest

from service.core.schemas import OBJECTIVES, SOLVER_NAMES
from service.learning import infer
from service.learning.generate import stitched_problem

from .helpers import assert_valid_answer, long_chain, post_json, without_fast_parse

pytestmark = pytest.mark.anyio


async def test_tiny_request_is_answered_and_valid(
    client: httpx.AsyncClient, tiny: dict[str, Any]
) -> None:
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert_valid_answer(tiny, answer)
    assert answer["solver"]["name"] == "auto" and answer["solver"]["optimal"]
    assert answer["solver"]["detail"] == "start; proven optimal by CP-SAT"  # 3 conflicts
    assert all(set(x) == {"from", "to", "type"} for x in answer["assignment"])


@pytest.mark.parametrize("solver", SOLVER_NAMES)
async def test_every_solver_answers(
    client: httpx.AsyncClient, tiny: dict[str, Any], solver: str
) -> None:
    tiny["options"]["solver"] = solver
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert_valid_answer(tiny, answer)
    if solver == "gnn_vae":  # the shipped model answers
        assert answer["solver"]["name"] == "gnn_vae"
        assert answer["solver"]["model"].startswith(f"gnn_vae/{tiny['objective']}/")
        assert answer["solver"]["samples"] == 100
    else:
        assert answer["solver"]["name"] == solver


@pytest.mark.parametrize("objective", OBJECTIVES)
async def test_every_objective(
    client: httpx.AsyncClient, tiny: dict[str, Any], objective: str
) -> None:
    tiny["objective"] = objective
    response = await post_json(client, tiny)
    assert response.status_code == 200, response.text
    assert_valid_answer(tiny, response.json())


async def test_defaults_apply_without_options_and_conflicts(client: httpx.AsyncClient) -> None:
    request = {"robots": [{"id": "solo", "nodes": [{"id": "n", "enter": 1.0, "exit": 2.0}]}]}
    response = await post_json(client, request)
    assert response.status_code == 200, response.text
    answer = response.json()
    assert_valid_answer(request, answer)
    assert answer["assignment"] == [] and answer["cost"] == 2.0


async def test_openapi_docs(client: httpx.AsyncClient) -> None:
    assert (await client.get("/docs")).status_code == 200
    schema = (await client.get("/openapi.json")).json()
    post = schema["paths"]["/v1/schedules"]["post"]
    assert {"200", "413", "422", "503"} <= set(post["responses"])
    assignment = schema["components"]["schemas"]["AssignmentOut"]
    assert "from" in assignment["properties"]


@pytest.mark.parametrize("objective", ["avg_completion", "sync_completion"])
async def test_gnn_vae_in_chunks_answers_as_in_one_batch(
    client: httpx.AsyncClient, monkeypatch: pytest.MonkeyPatch, objective: str
) -> None:
    request = stitched_problem(5, 12, 3.0)
    request.update(objective=objective, options={"solver": "gnn_vae", "samples": 9})
    whole = (await post_json(client, request)).json()
    monkeypatch.setattr(infer, "CHUNK_BYTES", 1)  # one sample at a time
    chunked = (await post_json(client, request)).json()
    assert whole["solver"]["samples"] == chunked["solver"]["samples"] == 9
    assert chunked["assignment"] == whole["assignment"] and chunked["cost"] == whole["cost"]


# Peak memory of issue 14's request (1,000 robots, one with 10,000 nodes, gnn_vae with
# 40 samples) beyond what the process held before solving: it was 7.2 GB (measured
# 6.2 GB here); chunked, 0.24-0.30 GB (the bound: CHUNK_BYTES plus one sample).
PEAK_GROWTH_MB = 1024

MEASURE_PEAK = """
import json, resource, sys
from service.api.runtime import build_runtime, load_models
from service.core.schemas import ScheduleRequest
from service.settings import Settings
from service.solvers.dispatch import dispatch
runtime = build_runtime(Settings())
load_models(runtime, runtime.model_store)
request = ScheduleRequest.model_validate(json.loads(sys.stdin.read()))
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
answer = dispatch(request, runtime.policy)
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"grown_mb": (after - before) / 1024, "solver": answer.solver.name}))
"""


def test_a_long_robot_among_many_stays_within_the_memory_bound() -> None:
    request = long_chain(1000, 10_000, time_limit_s=2.0)
    request["options"].update(solver="gnn_vae", samples=40)
    run = subprocess.run(
        [sys.executable, "-c", MEASURE_PEAK],
        input=json.dumps(request),
        capture_output=True,
        text=True,
        check=True,
    )
    measured = json.loads(run.stdout)
    assert measured["solver"] == "gnn_vae"
    assert measured["grown_mb"] < PEAK_GROWTH_MB, measured


async def test_the_answer_is_encoded_in_the_worker_thread_as_fastapi_would(
    client: httpx.AsyncClient, tiny: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The JSON body is made where the solve ran (not in the event loop, where a 250-robot
    answer blocked every other request for ~0.1 s), and it is what FastAPI's own encoding
    of the answer against the response model gives."""
    import threading

    from fastapi.encoders import jsonable_encoder

    from service.api import encoding
    from service.api.routes import schedules

    made: list[tuple[str, Any]] = []
    with_json = encoding.with_json

    def spied(work: Any) -> Any:
        encode = with_json(work)

        def run() -> Any:
            answer, content = encode()
            made.append((threading.current_thread().name, answer))
            return answer, content

        return run

    monkeypatch.setattr(schedules, "with_json", spied)
    loop_thread = threading.current_thread().name
    response = await post_json(client, tiny)
    assert response.status_code == 200 and response.headers["content-type"] == "application/json"
    [(thread, answer)] = made
    assert thread != loop_thread
    assert response.json() == jsonable_encoder(answer, by_alias=True)


async def test_the_paths_routes_answer_what_their_models_encode(client: httpx.AsyncClient) -> None:
    """``/v1/coordination-graphs`` and ``/v1/simulations`` send the JSON their answer models
    give (encoded in the worker thread, as ``/v1/schedules``): what FastAPI's own encoding
    of the same answers gives."""
    from pathlib import Path

    from fastapi.encoders import jsonable_encoder

    from service.core.path_schemas import PathsRequest, SimulationRequest
    from service.geometry.graph import GeometrySettings
    from service.motion.plan import coordination_graph
    from service.simulation.simulate import simulate

    examples = Path(__file__).resolve().parents[2] / "schemas" / "examples" / "paths"
    paths = json.loads((examples / "wh_two_lane_12.json").read_text())
    graph = await client.post("/v1/coordination-graphs", json=paths)
    assert graph.status_code == 200 and graph.headers["content-type"] == "application/json"
    expected = coordination_graph(PathsRequest.model_validate(paths), GeometrySettings())
    assert graph.json() == jsonable_encoder(expected, by_alias=True)
    answer = (await post_json(client, paths)).json()
    body = {"robots": paths["robots"], "dependencies": answer["dependencies"]}
    run = await client.post("/v1/simulations", json=body)
    assert run.status_code == 200, run.text
    assert run.json() == jsonable_encoder(simulate(SimulationRequest.model_validate(body)))


@pytest.mark.parametrize("form", ["graph", "paths"])
async def test_a_json_body_is_validated_from_its_bytes_as_fastapi_would(
    client: httpx.AsyncClient,
    tiny: dict[str, Any],
    monkeypatch: pytest.MonkeyPatch,
    form: str,
) -> None:
    """A body declared JSON is validated from its bytes: with FastAPI's own decoding
    (Starlette's ``Request.json``) broken, both forms of ``/v1/schedules`` and both paths
    routes still answer, and the schedules are those of the same body that FastAPI parsed
    itself."""
    from pathlib import Path

    from starlette import requests

    examples = Path(__file__).resolve().parents[2] / "schemas" / "examples" / "paths"
    paths = json.loads((examples / "wh_two_lane_12.json").read_text())
    request = tiny if form == "graph" else paths
    with monkeypatch.context() as patched:
        without_fast_parse(patched)
        reference = await post_json(client, request)
    assert reference.status_code == 200, reference.text

    async def broken(self: requests.Request) -> Any:
        raise AssertionError("FastAPI decoded the body")

    monkeypatch.setattr(requests.Request, "json", broken)
    answer = await post_json(client, request)
    assert answer.status_code == 200, answer.text
    timed = ("solver", "timings")  # runtimes differ from run to run
    assert {k: v for k, v in answer.json().items() if k not in timed} == {
        k: v for k, v in reference.json().items() if k not in timed
    }
    if form == "paths":
        graph = await client.post("/v1/coordination-graphs", json=paths)
        assert graph.status_code == 200, graph.text
        run = {"robots": paths["robots"], "dependencies": answer.json()["dependencies"]}
        simulated = await client.post("/v1/simulations", json=run)
        assert simulated.status_code == 200, simulated.text


async def test_a_body_failing_the_fast_parse_is_named_by_fastapi_as_before(
    client: httpx.AsyncClient, tiny: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    """An invalid body gets FastAPI's own 422, as without the fast parse: that only ever
    passes a valid model on."""
    tiny["robots"][0]["nodes"][0]["exit"] = "soon"
    answer = await post_json(client, tiny)
    without_fast_parse(monkeypatch)
    reference = await post_json(client, tiny)
    assert answer.status_code == reference.status_code == 422
    assert answer.json() == reference.json()
