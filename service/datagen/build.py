"""Training data for the GNN-VAE: seeded problems with their best exact assignments.

``python -m service.datagen --out data/small-v1 --problems 10000`` writes a
versioned dataset directory in the format of :mod:`service.learning.data`:
shards of one JSON record per problem, targets best first, and a manifest with
the settings, counts (per kind, proven share per objective) and a SHA-256 over
the shards. Kinds (``--kind``):

* ``small`` (default): the published generator, CP-SAT's top-L;
* ``stitched``: stitched problems of 10-40 robots, CP-SAT's best within the limit;
* ``scenario``: graphs derived from generated worlds (:mod:`service.datagen.worlds`;
  ``--kinds`` / ``--hold-out`` choose the world kinds, ``--robots`` the range),
  labelled by the exact portfolio with each label's gap
  (:mod:`service.datagen.labels`); records add ``"world": {"kind", "robots",
  "seed", "redraws", "drawn"}`` (drawn: the kind's per-seed parameters).

Problem ``i`` is generated from ``SeedSequence([seed, i])`` and solved by CP-SAT
with one worker and a fixed seed, so a dataset is reproducible from its
manifest wherever labels are proven (a label cut by the time limit depends on
the machine's speed). Shards are written atomically and skipped when present,
so an interrupted run resumes where it stopped. Shards run on local processes
(``--workers``) or, with ``--executor ray`` or ``--address``, as Ray tasks
(:mod:`service.datagen.executors`); every node then needs this package installed
at the same version.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
from collections import Counter
from itertools import takewhile, zip_longest
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from service.core.problem import problem_from_request
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.datagen.config import DATASET_KINDS, DatasetConfig, ScenarioConfig, config_dict
from service.datagen.executors import Executor, run_shards
from service.datagen.labels import contexts, portfolio_labels, top_labels
from service.datagen.worlds import draw_world
from service.learning.data import DATASET_FORMAT, MANIFEST, iter_problems, shard_path
from service.learning.generate import GeneratorConfig, small_problem, stitched_problem
from service.scenarios import KINDS

__all__ = [
    "agree_where_proven",
    "build_dataset",
    "datasets_agree",
    "main",
    "problem_seed",
    "shard_text",
    "solve_problem",
]


def problem_seed(cfg: DatasetConfig, index: int) -> int:
    """The seed of problem ``index``: independent streams per index (``SeedSequence``)."""
    return int(np.random.SeedSequence([cfg.seed, index]).generate_state(1)[0])


def _generated(cfg: DatasetConfig, seed: int) -> dict[str, Any]:
    """The request of ``seed`` for the small and stitched kinds (objective included)."""
    if cfg.kind == "small":
        return small_problem(seed, cfg.objectives[0], cfg.generator)
    rng = np.random.default_rng(seed)
    robots = int(rng.integers(cfg.stitched_robots[0], cfg.stitched_robots[1] + 1))
    density = float(rng.uniform(*cfg.stitched_density))
    return stitched_problem(seed, robots, density, cfg.objectives[0], cfg.generator)


def _targets(cfg: DatasetConfig, request: ScheduleRequest) -> dict[str, list[dict[str, Any]]]:
    """The labels of every objective (top-L, or the portfolio's for the scenario kind)."""
    labeller = portfolio_labels if cfg.kind == "scenario" else top_labels
    problem = problem_from_request(request)
    return {
        objective: labeller(ctx, cfg.top)
        for objective, ctx in contexts(problem, cfg.objectives, cfg.solve_time_limit_s).items()
    }


def solve_problem(cfg: DatasetConfig, index: int) -> dict[str, Any]:
    """The record of problem ``index``: its request (without objective) and its labels."""
    seed = problem_seed(cfg, index)
    if cfg.kind != "scenario":
        request = _generated(cfg, seed)
        targets = _targets(cfg, ScheduleRequest.model_validate(request))
        del request["objective"]
        return {"index": index, "seed": seed, "request": request, "targets": targets}
    assert cfg.scenario is not None  # resolved by DatasetConfig
    drawn = draw_world(cfg.scenario, seed)
    return {
        "index": index,
        "seed": seed,
        "world": drawn.world_record(),
        "request": drawn.request.model_dump(
            mode="json", by_alias=True, exclude_none=True, exclude={"objective", "options"}
        ),
        "targets": _targets(cfg, drawn.request),
    }


def _problem_part(record: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in record.items() if key != "targets"}


def _both_proven(pair: tuple[dict[str, Any], dict[str, Any]]) -> bool:
    return pair[0]["optimal"] and pair[1]["optimal"]


def agree_where_proven(first: dict[str, Any], second: dict[str, Any]) -> bool:
    """Whether two builds of a record agree wherever both proved their labels: the same
    problem, and per objective the same targets as far as both are proven (a label cut by
    the time limit depends on the machine's speed, and so does how many labels are proven)."""
    return _problem_part(first) == _problem_part(second) and all(
        one == other
        for objective, targets in first["targets"].items()
        for one, other in takewhile(
            _both_proven, zip(targets, second["targets"][objective], strict=False)
        )
    )


def datasets_agree(first: Path, second: Path) -> bool:
    """Whether two datasets hold the same problems and agree wherever both proved labels."""
    pairs = zip_longest(iter_problems(first), iter_problems(second))
    return all(a is not None and b is not None and agree_where_proven(a, b) for a, b in pairs)


def shard_text(cfg: DatasetConfig, shard: int) -> str:
    """The text of shard ``shard``: one JSON line per problem of its index range."""
    start = shard * cfg.shard_size
    stop = min(start + cfg.shard_size, cfg.problems)
    lines = [json.dumps(solve_problem(cfg, i), separators=(",", ":")) for i in range(start, stop)]
    return "\n".join(lines) + "\n"


def _write_atomic(path: Path, text: str) -> None:
    """Write ``path`` so that it is either absent or complete (a shard's presence means done)."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _counts(cfg: DatasetConfig, out: Path) -> dict[str, Any]:
    """Problems per world kind, the share whose best label is proven per objective, and the
    worlds redrawn (refused or conflict-free) on the way."""
    kinds: Counter[str] = Counter()
    proven: Counter[str] = Counter()
    redraws, total = 0, 0
    for record in iter_problems(out):
        world = record.get("world", {"kind": cfg.kind})
        kinds[world["kind"]] += 1
        redraws += world.get("redraws", 0)
        proven.update(o for o, ts in record["targets"].items() if ts and ts[0]["optimal"])
        total += 1
    return {
        "kinds": dict(sorted(kinds.items())),
        "proven": {o: round(proven[o] / max(total, 1), 4) for o in cfg.objectives},
        "redraws": redraws,
    }


def build_dataset(
    cfg: DatasetConfig, out: Path, workers: int = 2, executor: Executor | None = None
) -> dict[str, Any]:
    """Write (or resume) the dataset at ``out``; returns its manifest.

    ``executor`` (default: ``workers`` local processes) says where shards run.
    """
    executor = executor or Executor("local", workers)
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / MANIFEST
    if manifest_path.exists():
        old = json.loads(manifest_path.read_text())
        if old["config"] != config_dict(cfg):
            raise SystemExit(f"{out} holds a dataset with other settings; choose another --out")
    n_shards = -(-cfg.problems // cfg.shard_size)
    todo = [s for s in range(n_shards) if not shard_path(out, s).exists()]
    head = {"format": DATASET_FORMAT, "config": config_dict(cfg)}
    manifest_path.write_text(json.dumps({**head, "complete": False}, indent=1))
    left = sum(min(cfg.shard_size, cfg.problems - s * cfg.shard_size) for s in todo)
    with tqdm(total=left, desc="problems", unit="problem", smoothing=0.1) as bar:
        for shard, text in run_shards(shard_text, cfg, todo, executor):
            _write_atomic(shard_path(out, shard), text)
            bar.update(text.count("\n"))
    digest = hashlib.sha256()
    for s in range(n_shards):
        digest.update(shard_path(out, s).read_bytes())
    manifest = {
        **head,
        "complete": True,
        "shards": n_shards,
        "problems": cfg.problems,
        "sha256": digest.hexdigest(),
        "counts": _counts(cfg, out),
    }
    manifest_path.write_text(json.dumps(manifest, indent=1))
    return manifest


def _parser() -> argparse.ArgumentParser:
    """The command line's options."""
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
    parser.add_argument("--kind", choices=DATASET_KINDS, default="small")
    parser.add_argument("--objectives", nargs="+", choices=OBJECTIVES, default=list(OBJECTIVES))
    parser.add_argument("--solve-time-limit", type=float, default=DatasetConfig.solve_time_limit_s)
    scenario = parser.add_argument_group("scenario kind")
    scenario.add_argument("--kinds", nargs="+", choices=list(KINDS), help="world kinds (all)")
    scenario.add_argument("--hold-out", nargs="+", choices=list(KINDS), default=[])
    scenario.add_argument("--robots", nargs=2, type=int, metavar=("LOW", "HIGH"))
    cluster = parser.add_argument_group("where shards run")
    cluster.add_argument("--executor", choices=("local", "ray"), default="local")
    cluster.add_argument("--address", help="a Ray cluster to join (auto, host:port): implies ray")
    return parser


def _scenario_config(args: argparse.Namespace) -> ScenarioConfig:
    """The scenario settings of the command line (defaults where a flag is absent)."""
    kinds = [k for k in (args.kinds or ScenarioConfig.kinds) if k not in args.hold_out]
    robots = tuple(args.robots) if args.robots else ScenarioConfig.robots
    return ScenarioConfig(kinds=tuple(kinds), robots=robots)


def main(argv: list[str] | None = None) -> None:
    """CLI entry: build or resume a dataset."""
    parser = _parser()
    args = parser.parse_args(argv)
    scenario_flags = args.kinds or args.hold_out or args.robots
    if scenario_flags and args.kind != "scenario":
        parser.error("--kinds, --hold-out and --robots are for --kind scenario")
    cfg = DatasetConfig(
        problems=args.problems,
        seed=args.seed,
        top=args.top,
        shard_size=args.shard_size,
        generator=GeneratorConfig(time_scale=args.time_scale),
        kind=args.kind,
        objectives=tuple(args.objectives),
        solve_time_limit_s=args.solve_time_limit,
        scenario=_scenario_config(args) if args.kind == "scenario" else None,
    )
    executor = Executor(args.executor, args.workers, args.address)
    manifest = build_dataset(cfg, args.out, executor=executor)
    print(json.dumps({k: manifest[k] for k in ("problems", "shards", "sha256", "counts")}))


if __name__ == "__main__":
    main()
