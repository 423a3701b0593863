"""The committed JSON Schemas and examples match the code, and the examples are valid.

Validation against the JSON Schemas themselves needs the ``jsonschema`` package,
which is not a project dependency: those tests are skipped where it is missing.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any

import pytest

from service.core.path_schemas import PathsRequest, SimulationRequest
from service.core.schemas import ScheduleRequest
from service.geometry.graph import GeometrySettings
from service.motion.plan import plan_paths
from service.simulation.simulate import simulate
from service.solvers.dispatch import DispatchPolicy, dispatch

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas"
EXAMPLES = sorted(p.name for p in (SCHEMAS / "examples").glob("*.json"))


def _generator():
    spec = importlib.util.spec_from_file_location("schemas_generate", SCHEMAS / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _load(path: Path) -> Any:
    return json.loads(path.read_text())


def _validator(name: str):
    """A draft 2020-12 validator of a committed schema (skips without ``jsonschema``)."""
    jsonschema = pytest.importorskip("jsonschema")
    schema = _load(SCHEMAS / name)
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def test_committed_files_match_the_code() -> None:
    gen = _generator()
    for path, content in gen.documents().items():
        assert path.read_text() == gen.render(content), (
            f"{path.name} drifted from the code: run `python -m schemas.generate`"
        )


def test_both_examples_are_committed() -> None:
    assert {"tiny.json", "mid.json"} <= set(EXAMPLES)


@pytest.mark.parametrize("name", EXAMPLES)
def test_examples_are_valid_and_solve(name: str) -> None:
    request = ScheduleRequest.model_validate(_load(SCHEMAS / "examples" / name))
    answer = dispatch(request, DispatchPolicy())
    assert answer.checks.acyclic and answer.checks.density
    assert len(answer.assignment) == len(request.conflicts)


@pytest.mark.parametrize("name", EXAMPLES)
def test_examples_validate_against_the_request_schema(name: str) -> None:
    _validator("request.schema.json").validate(_load(SCHEMAS / "examples" / name))


def test_request_schema_rejects_what_the_model_rejects() -> None:
    validator = _validator("request.schema.json")
    mid = _load(SCHEMAS / "examples" / "mid.json")
    for broken in (
        {**mid, "surprise": 1},  # unknown field
        {**mid, "objective": "fastest"},
        {**mid, "robots": []},
    ):
        assert not validator.is_valid(broken)
        with pytest.raises(ValueError):
            ScheduleRequest.model_validate(broken)


def test_a_response_validates_against_the_response_schema() -> None:
    request = ScheduleRequest.model_validate(_load(SCHEMAS / "examples" / "mid.json"))
    body = dispatch(request, DispatchPolicy()).model_dump(mode="json", by_alias=True)
    _validator("response.schema.json").validate(body)
    assert "from" in body["assignment"][0]


def test_response_schema_names_from_by_alias() -> None:
    schema = _load(SCHEMAS / "response.schema.json")
    assert "from" in schema["$defs"]["AssignmentOut"]["properties"]


PATHS_EXAMPLES = sorted(p.name for p in (SCHEMAS / "examples" / "paths").glob("*.json"))


@pytest.mark.parametrize("name", PATHS_EXAMPLES)
def test_paths_examples_plan_and_validate_against_their_schemas(name: str) -> None:
    """Each paths example is a valid body whose answer validates and posts back as a graph."""
    body = _load(SCHEMAS / "examples" / "paths" / name)
    _validator("paths-request.schema.json").validate(body)
    answer = plan_paths(PathsRequest.model_validate(body), DispatchPolicy(), GeometrySettings())
    wire = json.loads(answer.content)  # what the route sends
    _validator("paths-response.schema.json").validate(wire)
    assert wire == answer.response.model_dump(mode="json", by_alias=True)
    assert answer.response.checks.collision_free
    _validator("request.schema.json").validate(wire["graph"])
    ScheduleRequest.model_validate(wire["graph"])
    simulation = {"robots": body["robots"], "dependencies": wire["dependencies"]}
    _validator("simulation-request.schema.json").validate(simulation)
    report = simulate(SimulationRequest.model_validate(simulation))
    _validator("simulation-response.schema.json").validate(report.model_dump(mode="json"))
    assert report.collision_free and not report.deadlocked


def test_paths_request_schema_rejects_mixed_forms() -> None:
    validator = _validator("paths-request.schema.json")
    tiny = _load(SCHEMAS / "examples" / "paths" / "tiny.json")
    assert validator.is_valid(tiny)
    for broken in (
        {**tiny, "conflicts": []},
        {**tiny, "robots": [{**tiny["robots"][0], "nodes": []}]},
        {**tiny, "robots": [{**tiny["robots"][0], "radius": 0}]},
    ):
        assert not validator.is_valid(broken)
