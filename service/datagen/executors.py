"""Where shards are computed: local processes.

A module-level function ``make_shard(cfg, shard) -> str`` (the shard's text)
runs for every shard, yielding ``(shard, text)`` as shards finish, in any order;
the driver writes the files.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Literal

from service.datagen.config import DatasetConfig

__all__ = ["Executor", "run_shards"]

MakeShard = Callable[[DatasetConfig, int], str]


@dataclass(frozen=True)
class Executor:
    """How to run shards: ``Executor("local", workers=2)`` uses two processes of this machine."""

    kind: Literal["local"] = "local"
    workers: int = 2


def run_shards(
    make_shard: MakeShard, cfg: DatasetConfig, shards: Sequence[int], executor: Executor
) -> Iterator[tuple[int, str]]:
    """``(shard, make_shard(cfg, shard))`` for every shard, as each finishes."""
    return _local_shards(make_shard, cfg, shards, executor.workers)


def _local_shards(
    make_shard: MakeShard, cfg: DatasetConfig, shards: Sequence[int], workers: int
) -> Iterator[tuple[int, str]]:
    """Shards computed by a pool of local processes."""
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(make_shard, cfg, shard): shard for shard in shards}
        for future in as_completed(futures):
            yield futures.pop(future), future.result()
