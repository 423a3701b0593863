"""Write the JSON Schemas of the v1 request and response, and the mid-size example.

``python -m schemas.generate`` (from the repository root) regenerates ``request.schema.json``,
``response.schema.json`` and ``examples/mid.json`` from the pydantic models and
the seeded generator; ``tests/test_schemas.py`` fails when they drift.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from service.core.schemas import ScheduleRequest, ScheduleResponse
from service.learning.generate import stitched_problem

HERE = Path(__file__).resolve().parent
# pydantic 2 writes JSON Schema draft 2020-12; saying so lets validators pick the right rules.
DIALECT = "https://json-schema.org/draft/2020-12/schema"
# The mid-size example: 20 robots, about 3 conflicts per robot, fixed seed.
MID_SEED, MID_ROBOTS, MID_DENSITY = 20, 20, 3.0


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
