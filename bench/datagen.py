"""Throughput of dataset generation on local Ray clusters, and what 100,000 problems would take.

Usage::

    python -m bench.datagen                       # 40 scenario problems on 1 and 2 nodes
    python -m bench.datagen --problems 8 --nodes 2 --solve-time-limit 0.2   # smoke run

Each run builds the same scenario dataset (:mod:`service.datagen`, seed 0) from
scratch on a Ray cluster of ``n`` nodes of one CPU each on this machine
(``ray.cluster_utils.Cluster``, as a real cluster of one-CPU workers), with
``--local`` also on one local process (no Ray: its overhead). It reports the
build's wall time (workers' start-up included, the cluster's not), problems per
second, the hours 100,000 problems would take at that rate, and whether every
run produced the same problems, with the same labels wherever both runs proved
them. Shards are small (``--shard-size``, default 2), since one 100-robot
problem takes ~50 times a 5-robot one and a few shards must not leave a node
idle. Needs the ``distributed`` extra. Writes ``results.json`` under ``--out``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bench.report import format_table, machine_info, write_json
from service.core.schemas import OBJECTIVES
from service.datagen.build import build_dataset, datasets_agree
from service.datagen.config import DatasetConfig, ScenarioConfig
from service.datagen.executors import Executor, local_cluster

PROJECTED_PROBLEMS = 100_000


@dataclass(frozen=True)
class Config:
    """What one measurement builds, and where."""

    problems: int = 40
    shard_size: int = 2
    nodes: tuple[int, ...] = (1, 2)
    local: bool = False
    robots: tuple[int, int] = (5, 100)
    top: int = 2
    solve_time_limit_s: float = 1.0
    out: Path = Path("bench/out/datagen")

    def dataset(self) -> DatasetConfig:
        """The scenario dataset every run builds."""
        return DatasetConfig(
            kind="scenario",
            problems=self.problems,
            shard_size=self.shard_size,
            top=self.top,
            objectives=OBJECTIVES,
            solve_time_limit_s=self.solve_time_limit_s,
            scenario=ScenarioConfig(robots=self.robots),
        )


def timed_build(cfg: DatasetConfig, executor: Executor, out: Path) -> dict[str, Any]:
    """Build ``cfg`` from scratch at ``out``: wall time, rate, projection, proven labels."""
    shutil.rmtree(out, ignore_errors=True)
    load = os.getloadavg()[0]  # other work on the machine slows every run down
    start = time.perf_counter()
    manifest = build_dataset(cfg, out, executor=executor)
    seconds = time.perf_counter() - start
    rate = cfg.problems / seconds
    return {
        "load_avg_1min": [round(load, 2), round(os.getloadavg()[0], 2)],  # before, after
        "seconds": round(seconds, 1),
        "problems_per_s": round(rate, 3),
        "projected_hours": round(PROJECTED_PROBLEMS / rate / 3600, 1),
        "proven": manifest["counts"]["proven"],
        "kinds": manifest["counts"]["kinds"],
        "dataset": out,
    }


def measure(cfg: Config, scratch: Path) -> list[dict[str, Any]]:
    """One row per run: the local process (with ``--local``), then each cluster size."""
    dataset = cfg.dataset()
    rows = []
    if cfg.local:
        row = timed_build(dataset, Executor("local", workers=1), scratch / "local")
        rows.append({"run": "1 local process", "cpus": 1, **row})
    for nodes in cfg.nodes:
        with local_cluster(nodes) as address:
            row = timed_build(dataset, Executor("ray", address=address), scratch / f"ray{nodes}")
        rows.append({"run": f"Ray, {nodes} node(s) of 1 CPU", "cpus": nodes, **row})
    return rows


def report(cfg: Config, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The results, with whether every run gave the same problems and agreed wherever both
    proved a label (:func:`service.datagen.build.agree_where_proven`)."""
    return {
        "config": {**asdict(cfg), "out": str(cfg.out)},
        "machine": machine_info(),
        "agree": all(datasets_agree(rows[0]["dataset"], r["dataset"]) for r in rows),
        "runs": [{k: v for k, v in r.items() if k != "dataset"} for r in rows],
    }


def main(argv: list[str] | None = None) -> int:
    """CLI entry: measure, print the table, write ``results.json``."""
    parser = argparse.ArgumentParser(prog="python -m bench.datagen", description=__doc__)
    parser.add_argument("--problems", type=int, default=Config.problems)
    parser.add_argument("--shard-size", type=int, default=Config.shard_size)
    parser.add_argument("--nodes", type=int, nargs="+", default=list(Config.nodes))
    parser.add_argument("--local", action="store_true", help="also time one local process")
    parser.add_argument("--robots", type=int, nargs=2, default=list(Config.robots))
    parser.add_argument("--top", type=int, default=Config.top)
    parser.add_argument("--solve-time-limit", type=float, default=Config.solve_time_limit_s)
    parser.add_argument("--out", type=Path, default=Config.out)
    args = parser.parse_args(argv)
    cfg = Config(
        problems=args.problems,
        shard_size=args.shard_size,
        nodes=tuple(args.nodes),
        local=args.local,
        robots=tuple(args.robots),
        top=args.top,
        solve_time_limit_s=args.solve_time_limit,
        out=args.out,
    )
    with tempfile.TemporaryDirectory() as scratch:
        results = report(cfg, measure(cfg, Path(scratch)))
    cfg.out.mkdir(parents=True, exist_ok=True)
    write_json(cfg.out / "results.json", results)
    headers = ("run", "seconds", "problems/s", f"hours for {PROJECTED_PROBLEMS:,}", "load")
    table = [
        (r["run"], r["seconds"], r["problems_per_s"], r["projected_hours"], r["load_avg_1min"])
        for r in results["runs"]
    ]
    print(format_table(headers, table))
    print(f"same problems, same labels where proven, in every run: {results['agree']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
