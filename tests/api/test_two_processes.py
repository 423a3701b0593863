"""Two ``python -m service`` processes give identical answers for the same request and seed."""

from __future__ import annotations

import copy
import json
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import httpx

from .helpers import TINY, service_process, wait_ready_sync

EXAMPLES = TINY.parent
# Keys whose values are measured, not computed: left out of the comparison.
MEASURED = frozenset({"runtime_s", "timings"})


def with_solver(path: Path, solver: str) -> dict[str, Any]:
    """The example at ``path`` asking for ``solver`` (seed and time limit as committed)."""
    body = json.loads(path.read_text())
    body["options"] = {**body.get("options", {}), "solver": solver}
    return body


def computed(value: Any) -> Any:
    """``value`` without the measured keys, at any depth."""
    if isinstance(value, dict):
        return {k: computed(v) for k, v in value.items() if k not in MEASURED}
    if isinstance(value, list):
        return [computed(v) for v in value]
    return value


REQUESTS = {
    "tiny": json.loads(TINY.read_text()),
    "mid exact": with_solver(EXAMPLES / "mid.json", "exact"),
    "mid gnn_vae": with_solver(EXAMPLES / "mid.json", "gnn_vae"),
    "paths tiny": json.loads((EXAMPLES / "paths" / "tiny.json").read_text()),
}


def test_two_processes_answer_alike(tmp_path: Path) -> None:
    with ExitStack() as stack:
        urls = [stack.enter_context(service_process(tmp_path / f"server{i}.log")) for i in (0, 1)]
        clients = [stack.enter_context(httpx.Client(base_url=u, timeout=120.0)) for u in urls]
        for client in clients:
            wait_ready_sync(client)
        for name, body in REQUESTS.items():
            first, second = (c.post("/v1/schedules", json=copy.deepcopy(body)) for c in clients)
            assert (first.status_code, second.status_code) == (200, 200), name
            assert computed(first.json()) == computed(second.json()), name
