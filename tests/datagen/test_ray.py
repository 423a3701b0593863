"""On a Ray cluster (2 local nodes of 1 CPU): the same problems and proven labels as locally."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from service.datagen.build import build_dataset, datasets_agree
from service.datagen.executors import Executor, local_cluster
from service.learning.data import load_manifest
from tests.datagen.conftest import TINY

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def cluster() -> Iterator[str]:
    """Two nodes of one CPU each on this machine; yields the address to join."""
    with local_cluster(2) as address:
        yield address


def test_a_cluster_builds_the_local_dataset(
    cluster: str, tiny_dataset: Path, tmp_path: Path
) -> None:
    out = tmp_path / "on-ray"
    manifest = build_dataset(TINY, out, executor=Executor("ray", address=cluster))
    assert not ray.is_initialized()  # the executor leaves no connection behind
    assert datasets_agree(out, tiny_dataset)
    assert manifest["sha256"] == load_manifest(tiny_dataset)["sha256"]  # TINY proves every label
