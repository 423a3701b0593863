"""Training data for the GNN-VAE: random problems with their top-L exact assignments.

``python -m service.datagen --out data/small-v1 --problems 10000`` writes a
versioned dataset directory in the format of :mod:`service.learning.data`:
shards of one JSON record per problem, targets best first (CP-SAT top-L with
no-good clauses), and a manifest with the settings, counts and a SHA-256 over
the shards.

Problem ``i`` is generated from ``SeedSequence([seed, i])`` and solved by CP-SAT
with one worker and a fixed seed, so a dataset is reproducible from its
manifest. Shards are written atomically and skipped when present, so an
interrupted run resumes where it stopped. Workers are separate processes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from service.core.cliques import find_cliques
from service.core.evaluate import Evaluator
from service.core.problem import problem_from_request
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.data import DATASET_FORMAT, MANIFEST, shard_path
from service.learning.generate import GeneratorConfig, small_problem, stitched_problem
from service.solvers.exact import top_assignments

__all__ = ["DatasetConfig", "build_dataset", "main", "solve_problem"]


@dataclass(frozen=True)
class DatasetConfig:
    """Everything that determines a dataset's content."""

    problems: int = 10_000
    seed: int = 0
    top: int = 10  # L: best assignments kept per problem and objective
    objectives: tuple[str, ...] = OBJECTIVES
    shard_size: int = 100
    solve_time_limit_s: float = 10.0  # per CP-SAT solve; small problems take ~10 ms
    generator: GeneratorConfig = field(default_factory=GeneratorConfig)
    # "small": the published generator; "stitched": problems of robots in
    # ``stitched_robots`` with conflicts per robot uniform in ``stitched_density``,
    # labelled by CP-SAT's best within ``solve_time_limit_s`` (not always proven).
    kind: str = "small"
    stitched_robots: tuple[int, int] = (10, 40)
    stitched_density: tuple[float, float] = (1.5, 4.0)


def _bits(mask: np.ndarray) -> str:
    return "".join("1" if x else "0" for x in mask.tolist())


def _generate(cfg: DatasetConfig, seed: int) -> dict[str, Any]:
    """The problem of ``seed`` for the dataset's kind."""
    if cfg.kind == "small":
        return small_problem(seed, cfg.objectives[0], cfg.generator)
    rng = np.random.default_rng(seed)
    robots = int(rng.integers(cfg.stitched_robots[0], cfg.stitched_robots[1] + 1))
    density = float(rng.uniform(*cfg.stitched_density))
    return stitched_problem(seed, robots, density, cfg.objectives[0], cfg.generator)


def solve_problem(cfg: DatasetConfig, index: int) -> dict[str, Any]:
    """Generate problem ``index`` and its top-L assignments for every objective."""
    seed = int(np.random.SeedSequence([cfg.seed, index]).generate_state(1)[0])
    request = _generate(cfg, seed)
    problem = problem_from_request(ScheduleRequest.model_validate(request))
    cliques = find_cliques(problem)
    evaluator = Evaluator(problem)
    targets: dict[str, list[dict[str, Any]]] = {}
    for objective in cfg.objectives:
        found = top_assignments(
            problem, cliques, objective, cfg.top, cfg.solve_time_limit_s, seed=0
        )
        targets[objective] = [
            {
                "a_first": _bits(r.assignment.a_first[0]),
                "following": _bits(r.assignment.following[0]),
                "cost": float(evaluator.evaluate(r.assignment).costs[objective][0]),
                "optimal": r.optimal,
            }
            for r in found
        ]
    del request["objective"]
    return {"index": index, "seed": seed, "request": request, "targets": targets}


def _solve_shard(args: tuple[DatasetConfig, int, str]) -> int:
    """Solve one shard and write it atomically; returns the shard number."""
    cfg, shard, out = args
    path = shard_path(Path(out), shard)
    start = shard * cfg.shard_size
    stop = min(start + cfg.shard_size, cfg.problems)
    lines = [json.dumps(solve_problem(cfg, i), separators=(",", ":")) for i in range(start, stop)]
    tmp = path.with_suffix(".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    os.replace(tmp, path)
    return shard


def _config_dict(cfg: DatasetConfig) -> dict[str, Any]:
    """The config as it reads back from the manifest (tuples become lists)."""
    return json.loads(json.dumps(asdict(cfg)))


def build_dataset(cfg: DatasetConfig, out: Path, workers: int = 2) -> dict[str, Any]:
    """Write (or resume) the dataset at ``out``; returns its manifest."""
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / MANIFEST
    if manifest_path.exists():
        old = json.loads(manifest_path.read_text())
        if old["config"] != _config_dict(cfg):
            raise SystemExit(f"{out} holds a dataset with other settings; choose another --out")
    n_shards = -(-cfg.problems // cfg.shard_size)
    todo = [s for s in range(n_shards) if not shard_path(out, s).exists()]
    manifest_path.write_text(
        json.dumps(
            {"format": DATASET_FORMAT, "config": _config_dict(cfg), "complete": False}, indent=1
        )
    )
    with ProcessPoolExecutor(max_workers=workers) as pool:
        jobs = pool.map(_solve_shard, [(cfg, s, str(out)) for s in todo])
        for _ in tqdm(jobs, total=len(todo), desc="shards", unit="shard"):
            pass
    digest = hashlib.sha256()
    for s in range(n_shards):
        digest.update(shard_path(out, s).read_bytes())
    manifest = {
        "format": DATASET_FORMAT,
        "config": _config_dict(cfg),
        "complete": True,
        "shards": n_shards,
        "problems": cfg.problems,
        "sha256": digest.hexdigest(),
    }
    manifest_path.write_text(json.dumps(manifest, indent=1))
    return manifest


def main(argv: list[str] | None = None) -> None:
    """CLI entry: build or resume a dataset."""
    parser = argparse.ArgumentParser(
        prog="python -m service.datagen", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--problems", type=int, default=DatasetConfig.problems)
    parser.add_argument("--seed", type=int, default=DatasetConfig.seed)
    parser.add_argument("--top", type=int, default=DatasetConfig.top)
    parser.add_argument("--shard-size", type=int, default=DatasetConfig.shard_size)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--time-scale",
        type=float,
        default=1.0,
        help="multiply every generated time (tests time-scale invariance)",
    )
    parser.add_argument("--kind", choices=("small", "stitched"), default="small")
    parser.add_argument("--objectives", nargs="+", choices=OBJECTIVES, default=list(OBJECTIVES))
    parser.add_argument("--solve-time-limit", type=float, default=DatasetConfig.solve_time_limit_s)
    args = parser.parse_args(argv)
    cfg = DatasetConfig(
        problems=args.problems,
        seed=args.seed,
        top=args.top,
        shard_size=args.shard_size,
        generator=GeneratorConfig(time_scale=args.time_scale),
        kind=args.kind,
        objectives=tuple(args.objectives),
        solve_time_limit_s=args.solve_time_limit,
    )
    manifest = build_dataset(cfg, args.out, args.workers)
    print(json.dumps({k: manifest[k] for k in ("problems", "shards", "sha256")}))


if __name__ == "__main__":
    main()
