"""A tiny scenario dataset, built once, that the datagen tests read."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.datagen.build import build_dataset
from service.datagen.config import DatasetConfig, ScenarioConfig
from service.datagen.executors import Executor
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
