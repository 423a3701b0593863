"""The committed JSON Schemas and examples match the code, and the examples are valid."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from service.core.schemas import ScheduleRequest
from service.solvers.dispatch import DispatchPolicy, dispatch

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas"


def _generator():
    spec = importlib.util.spec_from_file_location("schemas_generate", SCHEMAS / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_committed_files_match_the_code() -> None:
    gen = _generator()
    for path, content in gen.documents().items():
        assert path.read_text() == gen.render(content), (
            f"{path.name} drifted from the code: run `python schemas/generate.py`"
        )


@pytest.mark.parametrize("name", ["tiny.json", "mid.json"])
def test_examples_are_valid_and_solve(name: str) -> None:
    request = ScheduleRequest.model_validate(json.loads((SCHEMAS / "examples" / name).read_text()))
    answer = dispatch(request, DispatchPolicy())
    assert answer.checks.acyclic and answer.checks.density
    assert len(answer.assignment) == len(request.conflicts)


def test_response_schema_names_from_by_alias() -> None:
    schema = json.loads((SCHEMAS / "response.schema.json").read_text())
    assert "from" in schema["$defs"]["AssignmentOut"]["properties"]
