"""Write the JSON Schemas of the v1 bodies, and the mid-size example.

``python -m schemas.generate`` (from the repository root) regenerates ``request.schema.json``,
``response.schema.json``, the paths form's ``paths-*.schema.json``,
``coordination-graph-response.schema.json``, ``simulation-*.schema.json`` and
``examples/mid.json`` from the pydantic models and the seeded generator;
``tests/test_schemas.py`` fails when they drift.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from service.core.path_schemas import (
    CoordinationGraphResponse,
    PathsRequest,
    PathsScheduleResponse,
    SimulationRequest,
    SimulationResponse,
)
from service.core.schemas import ScheduleRequest, ScheduleResponse
from service.learning.generate import stitched_problem

HERE = Path(__file__).resolve().parent
# pydantic 2 writes JSON Schema draft 2020-12; saying so lets validators pick the right rules.
DIALECT = "https://json-schema.org/draft/2020-12/schema"
# The mid-size example: 20 robots, about 3 conflicts per robot, fixed seed.
MID_SEED, MID_ROBOTS, MID_DENSITY = 20, 20, 3.0


# The paths form's bodies (docs/paths.md): file stem, model, validation or serialization.
PATHS_MODELS = (
    ("paths-request", PathsRequest, "validation"),
    ("paths-response", PathsScheduleResponse, "serialization"),
    ("coordination-graph-response", CoordinationGraphResponse, "serialization"),
    ("simulation-request", SimulationRequest, "validation"),
    ("simulation-response", SimulationResponse, "serialization"),
)


def documents() -> dict[Path, Any]:
    """Every generated file and its content."""
    mid = stitched_problem(MID_SEED, MID_ROBOTS, MID_DENSITY)
    mid["options"] = {"solver": "auto", "time_limit_s": 10.0, "seed": 0}
    return {
        HERE / "request.schema.json": {
            "$schema": DIALECT,
            **ScheduleRequest.model_json_schema(mode="validation"),
        },
        HERE / "response.schema.json": {
            "$schema": DIALECT,
            **ScheduleResponse.model_json_schema(mode="serialization", by_alias=True),
        },
        HERE / "examples" / "mid.json": mid,
        **{
            HERE / f"{name}.schema.json": {
                "$schema": DIALECT,
                **model.model_json_schema(mode=mode, by_alias=True),
            }
            for name, model, mode in PATHS_MODELS
        },
    }


def render(content: Any) -> str:
    """Stable JSON text."""
    return json.dumps(content, indent=1) + "\n"


def main() -> None:
    for path, content in documents().items():
        path.write_text(render(content))
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
