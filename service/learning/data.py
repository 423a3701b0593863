"""Reading training datasets: the record and manifest format, and iteration over records.

A dataset is a directory (built by :mod:`service.datagen`, which may import the
solvers; this module must not, since the solvers import the learning package):

* ``shard-00000.jsonl`` ...: one line per problem, ``{"index", "seed", "request",
  "targets": {objective: [{"a_first": "0101..", "following": "00..", "cost",
  "optimal"}, ...]}}``, targets best first; ``request`` is a graph-form request
  body without its objective;
* ``manifest.json``: ``{"format", "config", "complete", "shards", "problems",
  "sha256"}``, the settings the dataset was built from and a SHA-256 over the
  shards in order.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["DATASET_FORMAT", "MANIFEST", "iter_problems", "load_manifest", "shard_path"]

MANIFEST = "manifest.json"
DATASET_FORMAT = 1


def shard_path(path: Path, shard: int) -> Path:
    """The file of shard number ``shard`` of the dataset at ``path``."""
    return path / f"shard-{shard:05d}.jsonl"


def load_manifest(path: Path) -> dict[str, Any]:
    """The manifest of the dataset at ``path``."""
    return json.loads((path / MANIFEST).read_text())


def iter_problems(path: Path, limit: int | None = None) -> Iterator[dict[str, Any]]:
    """Records of the dataset at ``path`` in index order (complete shards only)."""
    count = 0
    for shard in sorted(path.glob("shard-*.jsonl")):
        for line in shard.read_text().splitlines():
            if limit is not None and count >= limit:
                return
            count += 1
            yield json.loads(line)
