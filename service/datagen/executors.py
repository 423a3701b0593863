"""Where shards are computed: local processes (the default) or Ray tasks on a cluster.

Both run a module-level function ``make_shard(cfg, shard) -> str`` (the shard's
text) and yield ``(shard, text)`` as shards finish, in any order; the driver
writes the files, so cluster nodes need no shared disk. Ray is imported only
when it is used (the ``distributed`` extra): the service and the default CLI do
not need it. With Ray, shards are tasks of ``num_cpus=1`` each (a shard batches
many problems, so scheduling overhead stays small), at most ``IN_FLIGHT_PER_CPU``
per cluster CPU in flight (``ray.wait``), so a large run never queues every
task's arguments and results at once.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Literal

from service.datagen.config import DatasetConfig

__all__ = ["Executor", "IN_FLIGHT_PER_CPU", "local_cluster", "run_shards"]

# Ray tasks in flight per cluster CPU: one running, one queued, so a CPU never idles
# waiting for the driver to submit.
IN_FLIGHT_PER_CPU = 2

MakeShard = Callable[[DatasetConfig, int], str]


@dataclass(frozen=True)
class Executor:
    """How to run shards.

    Example: ``Executor("ray", address="auto")`` joins a running Ray cluster;
    ``Executor("ray", workers=2)`` starts a local Ray instance of 2 CPUs;
    ``Executor("local", workers=2)`` uses two processes of this machine.

    ``workers``: processes (local) or the CPUs of a Ray instance started here
    (ignored when joining a cluster, whose CPUs all count).
    """

    kind: Literal["local", "ray"] = "local"
    workers: int = 2
    address: str | None = None  # a Ray cluster to join ("auto", "host:port"); implies Ray


def run_shards(
    make_shard: MakeShard, cfg: DatasetConfig, shards: Sequence[int], executor: Executor
) -> Iterator[tuple[int, str]]:
    """``(shard, make_shard(cfg, shard))`` for every shard, as each finishes."""
    if executor.kind == "ray" or executor.address is not None:
        return _ray_shards(make_shard, cfg, shards, executor)
    return _local_shards(make_shard, cfg, shards, executor.workers)


def _local_shards(
    make_shard: MakeShard, cfg: DatasetConfig, shards: Sequence[int], workers: int
) -> Iterator[tuple[int, str]]:
    """Shards computed by a pool of local processes."""
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(make_shard, cfg, shard): shard for shard in shards}
        for future in as_completed(futures):
            yield futures.pop(future), future.result()


def _ray_shards(
    make_shard: MakeShard, cfg: DatasetConfig, shards: Sequence[int], executor: Executor
) -> Iterator[tuple[int, str]]:
    """Shards computed as Ray tasks, joining ``executor.address`` (or a Ray the caller
    already connected to, or a local one started here and stopped at the end)."""
    import ray  # the optional ``distributed`` extra

    started = not ray.is_initialized()
    if started:
        local = executor.address is None
        ray.init(
            address=executor.address,
            num_cpus=executor.workers if local else None,
            include_dashboard=False if local else None,
            logging_level=logging.WARNING,
        )
    try:
        task = ray.remote(num_cpus=1)(make_shard)
        limit = IN_FLIGHT_PER_CPU * max(1, int(ray.cluster_resources().get("CPU", 1)))
        todo, pending = list(shards)[::-1], {}
        while todo or pending:
            while todo and len(pending) < limit:
                shard = todo.pop()
                pending[task.remote(cfg, shard)] = shard
            done, _ = ray.wait(list(pending), num_returns=1)
            yield pending.pop(done[0]), ray.get(done[0])
    finally:
        if started:
            ray.shutdown()


@contextmanager
def local_cluster(nodes: int) -> Iterator[str]:
    """A Ray cluster of ``nodes`` one-CPU nodes on this machine, as a cluster of one-CPU
    machines would be (for tests and throughput measurements); yields its address."""
    from ray.cluster_utils import Cluster  # the optional ``distributed`` extra

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    for _ in range(nodes - 1):
        cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    try:
        yield cluster.address
    finally:
        cluster.shutdown()
