"""The schedule route's body model as ``service.api.body`` validates it from the bytes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import TypeAdapter, ValidationError

from service.api.body import _body_model
from service.api.routes.schedules import router

from .helpers import TINY

PATHS_TINY = Path(__file__).resolve().parents[2] / "schemas" / "examples" / "paths" / "tiny.json"


def _body_field_info() -> Any:
    (route,) = [r for r in router.routes if getattr(r, "body_field", None) is not None]
    return route.body_field.field_info


def _robot(form: str, k: int) -> dict[str, Any]:
    """Robot k of a graph body, of a paths body, of both (every key of each) or of neither."""
    graph = json.loads(TINY.read_text())["robots"]
    paths = json.loads(PATHS_TINY.read_text())["robots"]
    of = {"graph": graph[k % len(graph)], "paths": paths[k % len(paths)]}
    if form in of:
        return of[form]
    return {**of["graph"], **of["paths"]} if form == "both" else {"id": f"r{k}"}


def _outcome(model: TypeAdapter[Any], body: bytes) -> object:
    try:
        return model.validate_json(body)
    except ValidationError:
        return "invalid"


@settings(max_examples=120, deadline=None, derandomize=True)
@given(
    forms=st.lists(st.sampled_from(["graph", "paths", "both", "neither"]), min_size=1, max_size=3),
    conflicts=st.booleans(),
)
def test_the_forms_tried_in_turn_give_the_discriminated_model(
    forms: list[str], conflicts: bool
) -> None:
    """Tried member by member (the fast parse), a body is valid exactly where the
    discriminated union (FastAPI's model) finds it valid, as the same model."""
    info = _body_field_info()
    tiny = json.loads(TINY.read_text())
    body: dict[str, Any] = {"robots": [_robot(form, k) for k, form in enumerate(forms)]}
    if conflicts:
        body["conflicts"] = tiny["conflicts"]
    raw = json.dumps(body).encode()
    fast = _outcome(_body_model(info), raw)
    slow = _outcome(TypeAdapter(Annotated[info.annotation, info]), raw)
    assert fast == slow
    assert type(fast) is type(slow)
