"""A tiny scenario dataset, built once, that the datagen tests read."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from service.datagen.build import build_dataset
from service.datagen.config import DatasetConfig, ScenarioConfig
from service.datagen.executors import Executor
from service.learning.data import iter_problems
from service.scenarios import KINDS

HELD_OUT = ("wh_two_lane", "floor_passages")
# Small worlds with a generous limit: every label proves, so builds compare byte for byte.
TINY = DatasetConfig(
    kind="scenario",
    problems=6,
    shard_size=2,
    top=2,
    solve_time_limit_s=5.0,
    scenario=ScenarioConfig(kinds=tuple(k for k in KINDS if k not in HELD_OUT), robots=(5, 12)),
)


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """TINY built by one local process."""
    out = tmp_path_factory.mktemp("datagen") / "tiny"
    build_dataset(TINY, out, executor=Executor("local", workers=1))
    return out


def proven_view(path: Path) -> list[dict[str, Any]]:
    """What must be the same wherever a dataset is built: every problem and its proven labels
    (labels cut by a time limit depend on the machine's speed)."""
    return [
        {
            **{k: v for k, v in record.items() if k != "targets"},
            "targets": {
                objective: [t for t in targets if t["optimal"]]
                for objective, targets in record["targets"].items()
            },
        }
        for record in iter_problems(path)
    ]
