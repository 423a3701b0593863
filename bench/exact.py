"""Benchmark CLI: exact-solve times by problem size, and evaluator/decoder throughput.

Usage::

    python -m bench.exact            # full run (~5 min on 2 cores)
    python -m bench.exact --quick    # smoke run (< 1 min)

Part (a) solves deterministic problem sets with :func:`service.solvers.exact.solve`,
warm-started from FCFS as the ``exact`` solver of the service is, and reports solve
time percentiles and the fraction proven optimal: small generated problems grouped
by robot count, and stitched larger problems at a sparse and a dense conflict
density. The time of a solve is the wall time of ``solve()`` (model building and
CP-SAT search); validating the request and finding cliques are not counted.

Part (b) times :class:`service.core.evaluate.Evaluator` on one stitched graph
(default 250 robots, ~1000 conflicts) for a batch of 1 and of S assignments decoded
from random bids by :class:`service.core.decode.Decoder`, and the decoder itself
for S samples: the per-request work of a sampling solver. The numba JIT is warmed
up first; each figure is the median over repeats.

Results: plain-text tables on stdout, and under ``--out`` (default ``bench/out/``)
``results.json`` (configuration, machine, raw runs, summaries), ``exact_runs.csv``
and ``solve_times.png``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.problems import BenchProblem, derive_seed, small_set, stitched_set
from bench.report import (
    format_table,
    machine_info,
    plot_solve_times,
    summarize_solves,
    write_csv,
    write_json,
)
from service.core.decode import Decoder
from service.core.evaluate import Evaluator
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.solvers.dispatch import DispatchPolicy, dispatch
from service.solvers.exact import solve
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext

__all__ = ["Config", "QUICK", "main", "run_auto", "run_evaluator", "run_exact"]

DEFAULT_OUT = Path("bench/out")
# Family tag of the evaluator graph's seed (the problem sets use 1 and 2).
_EVAL = 3


@dataclass(frozen=True)
class Config:
    """What one benchmark run measures. The defaults are the full run of docs/benchmarks.md."""

    objectives: tuple[str, ...] = OBJECTIVES
    small_robots: tuple[int, ...] = (2, 3, 4, 5, 6, 7, 8)
    small_count: int = 50  # problems per robot count
    large_robots: tuple[int, ...] = (10, 25, 50)
    # Sparse and dense: ~2 conflicts per robot is what the published large graphs
    # look like; ~4 is where CP-SAT starts to hit the time limit at 50 robots.
    large_densities: tuple[float, ...] = (2.0, 4.0)
    large_count: int = 5  # problems per (robots, density)
    time_limit_s: float = 10.0
    workers: int = 1
    hint: bool = True  # warm-start from FCFS, as the service's exact solver does
    eval_robots: int = 250
    eval_conflicts_per_robot: float = 4.0  # 250 robots -> ~1000 conflicts
    eval_samples: int = 100
    repeats: int = 30
    seed: int = 0


# The service's routing without learned models (small problems never reach them).
AUTO_POLICY = DispatchPolicy()

# A smoke run: the same code paths on fewer and smaller problems (< 1 min on 2 cores).
QUICK = Config(
    small_count=5,
    large_robots=(10, 25),
    large_count=2,
    time_limit_s=2.0,
    repeats=10,
)


def _solve_one(bp: BenchProblem, objective: str, cfg: Config) -> dict[str, Any]:
    """Solve one problem for one objective and record the timing."""
    ctx = SolveContext(bp.problem, objective, cfg.time_limit_s, seed=cfg.seed, workers=cfg.workers)
    hint = fcfs(ctx).assignment if cfg.hint else None
    start = time.perf_counter()
    result = solve(
        bp.problem,
        bp.cliques,
        objective,
        cfg.time_limit_s,
        seed=cfg.seed,
        workers=cfg.workers,
        hint=hint,
    )
    elapsed = time.perf_counter() - start
    return {
        "family": bp.family,
        "robots": bp.robots,
        "conflicts_per_robot": bp.conflicts_per_robot,
        "index": bp.index,
        "seed": bp.seed,
        "objective": objective,
        "n_nodes": bp.problem.n_nodes,
        "n_conflicts": bp.problem.n_conflicts,
        "time_s": elapsed,
        "found": result is not None,
        "optimal": result is not None and result.optimal,
    }


def _problem_sets(cfg: Config, progress: bool) -> list[BenchProblem]:
    """Every problem of the run: small sets by robot count, then stitched sets."""
    groups = [("small", r, None) for r in cfg.small_robots]
    groups += [("stitched", r, d) for r in cfg.large_robots for d in cfg.large_densities]
    problems: list[BenchProblem] = []
    for family, robots, density in tqdm(groups, desc="generate", disable=not progress):
        if family == "small":
            problems += small_set(robots, cfg.small_count, cfg.seed)
        else:
            problems += stitched_set(robots, density, cfg.large_count, cfg.seed)
    return problems


def _auto_one(bp: BenchProblem, objective: str, cfg: Config) -> dict[str, Any]:
    """One small problem through ``auto`` end to end, as the service answers it: the
    request validated from its JSON form, the portfolio, the check and the answer."""
    body = {**bp.request, "objective": objective}
    body["options"] = {"solver": "auto", "time_limit_s": cfg.time_limit_s, "seed": cfg.seed}
    start = time.perf_counter()
    answer = dispatch(ScheduleRequest.model_validate(body), AUTO_POLICY)
    elapsed = time.perf_counter() - start
    return {
        "family": "auto",
        "robots": bp.robots,
        "conflicts_per_robot": None,
        "index": bp.index,
        "objective": objective,
        "n_conflicts": bp.problem.n_conflicts,
        "time_s": elapsed,
        "found": True,
        "optimal": answer.solver.optimal,
    }


def run_auto(cfg: Config, problems: Sequence[BenchProblem], progress: bool) -> list[dict]:
    """``auto`` end to end on the small problems (issue 11: proven optima, p95 <= 50 ms)."""
    small = [bp for bp in problems if bp.family == "small"]
    todo = [(bp, objective) for bp in small for objective in cfg.objectives]
    return [
        _auto_one(bp, objective, cfg)
        for bp, objective in tqdm(todo, desc="auto end to end", disable=not progress)
    ]


def run_exact(
    cfg: Config, problems: Sequence[BenchProblem], progress: bool = True
) -> list[dict[str, Any]]:
    """Solve every problem of the run for every objective -> one record per solve."""
    runs = []
    with tqdm(total=len(problems) * len(cfg.objectives), desc="exact", disable=not progress) as bar:
        for bp in problems:
            for objective in cfg.objectives:
                bar.set_postfix_str(f"{bp.family} {bp.robots} robots", refresh=False)
                runs.append(_solve_one(bp, objective, cfg))
                bar.update()
    return runs


def _median_ms(fn, repeats: int) -> tuple[float, float]:
    """Median and minimum wall time of ``fn()`` over ``repeats`` calls, in ms."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)) * 1e3, float(np.min(times)) * 1e3


def run_evaluator(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Decoder and evaluator timings on one large stitched graph."""
    seed = derive_seed(cfg.seed, _EVAL, cfg.eval_robots)
    (bp,) = stitched_set(cfg.eval_robots, cfg.eval_conflicts_per_robot, 1, cfg.seed)
    problem, cliques = bp.problem, bp.cliques
    decoder, evaluator = Decoder(problem, cliques), Evaluator(problem)
    rng = np.random.default_rng(seed)
    n = cfg.eval_samples
    bids = rng.uniform(0.05, 1.0, size=(n, problem.n_nodes))  # (S, V) positive
    scores = rng.random(size=(n, problem.n_conflicts))  # (S, M)
    batch = decoder.decode(bids, scores)
    single = batch.take(0)
    evaluator.evaluate(batch)  # warm up the numba JIT (compiles or loads its cache)
    evaluator.evaluate(single)
    steps = [
        ("decode", n, lambda: decoder.decode(bids, scores)),
        ("evaluate", 1, lambda: evaluator.evaluate(single)),
        ("evaluate", n, lambda: evaluator.evaluate(batch)),
    ]
    timings = []
    for name, size, fn in tqdm(steps, desc="evaluator", disable=not progress):
        median_ms, min_ms = _median_ms(fn, cfg.repeats)
        timings.append(
            {
                "step": name,
                "batch": size,
                "median_ms": median_ms,
                "min_ms": min_ms,
                "per_second": size / (median_ms / 1e3),
            }
        )
    return {
        "robots": problem.n_robots,
        "nodes": problem.n_nodes,
        "conflicts": problem.n_conflicts,
        "events": int(problem.events.size),
        "cliques": int(cliques.budget.size),
        "seed": bp.seed,
        "repeats": cfg.repeats,
        "timings": timings,
    }


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.1f}"


def _exact_tables(summary: Sequence[dict[str, Any]], cfg: Config) -> str:
    """The small-problem table (ms) and the stitched-problem table (s)."""
    small = [r for r in summary if r["family"] == "small"]
    large = [r for r in summary if r["family"] == "stitched"]
    parts = []
    if small:
        parts.append(
            f"Exact solve, small problems ({cfg.small_count} per robot count, "
            f"time limit {cfg.time_limit_s:g} s, {cfg.workers} worker(s)), times in ms"
        )
        parts.append(
            format_table(
                ["objective", "robots", "conflicts", "p50", "p95", "max", "optimal"],
                [
                    [
                        r["objective"],
                        r["robots"],
                        f"{r['conflicts_mean']:.1f}",
                        _ms(r["p50_s"]),
                        _ms(r["p95_s"]),
                        _ms(r["max_s"]),
                        f"{r['optimal']:.0%}",
                    ]
                    for r in small
                ],
            )
        )
    if large:
        parts.append(
            f"Exact solve, stitched problems ({cfg.large_count} per size and density, "
            f"time limit {cfg.time_limit_s:g} s, {cfg.workers} worker(s)), times in s"
        )
        parts.append(
            format_table(
                [
                    "objective",
                    "robots",
                    "confl/robot",
                    "conflicts",
                    "p50",
                    "p95",
                    "max",
                    "found",
                    "optimal",
                ],
                [
                    [
                        r["objective"],
                        r["robots"],
                        f"{r['conflicts_per_robot']:g}",
                        f"{r['conflicts_mean']:.0f}",
                        f"{r['p50_s']:.2f}",
                        f"{r['p95_s']:.2f}",
                        f"{r['max_s']:.2f}",
                        f"{r['found']:.0%}",
                        f"{r['optimal']:.0%}",
                    ]
                    for r in large
                ],
            )
        )
    return "\n\n".join(parts)


def _auto_table(summary: Sequence[dict[str, Any]], cfg: Config) -> str:
    """``auto`` end to end on the small problems, times in ms, against issue 11's 50 ms."""
    head = (
        f"auto end to end (validate, portfolio, check, answer), small problems "
        f"({cfg.small_count} per robot count, time limit {cfg.time_limit_s:g} s), times in ms; "
        "issue 11: proven optimal, p95 <= 50 ms"
    )
    rows = [
        [
            r["objective"],
            r["robots"],
            _ms(r["p50_s"]),
            _ms(r["p95_s"]),
            _ms(r["max_s"]),
            f"{r['optimal']:.0%}",
        ]
        for r in summary
    ]
    table = format_table(["objective", "robots", "p50", "p95", "max", "optimal"], rows)
    return head + "\n" + table


def _evaluator_table(ev: dict[str, Any]) -> str:
    """Decoder and evaluator timings as a table with the graph's size above it."""
    head = (
        f"Evaluator and decoder: stitched graph of {ev['robots']} robots, {ev['nodes']} nodes, "
        f"{ev['conflicts']} conflicts, {ev['events']} events; median of {ev['repeats']} repeats"
    )
    table = format_table(
        ["step", "batch", "median ms", "min ms", "assignments/s"],
        [
            [
                t["step"],
                t["batch"],
                f"{t['median_ms']:.2f}",
                f"{t['min_ms']:.2f}",
                f"{t['per_second']:,.0f}",
            ]
            for t in ev["timings"]
        ],
    )
    return f"{head}\n{table}"


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="python -m bench.exact",
        description="Exact-solve times by problem size and evaluator throughput.",
    )
    p.add_argument("--quick", action="store_true", help="a smoke run of under a minute")
    p.add_argument(
        "--objective",
        choices=[*OBJECTIVES, "all"],
        default="all",
        help="objective to solve for (default: each of the four)",
    )
    p.add_argument(
        "--small-robots",
        type=int,
        nargs="+",
        metavar="R",
        help="robot counts of the small sets (default 2..8)",
    )
    p.add_argument(
        "--small-count",
        type=int,
        metavar="N",
        help="small problems per robot count (default 50; quick 5)",
    )
    p.add_argument(
        "--large-robots",
        type=int,
        nargs="*",
        metavar="R",
        help="robot counts of the stitched sets (default 10 25 50; quick 10 25)",
    )
    p.add_argument(
        "--large-densities",
        type=float,
        nargs="+",
        metavar="D",
        help="conflicts per robot of the stitched sets (default 2 4)",
    )
    p.add_argument(
        "--large-count",
        type=int,
        metavar="N",
        help="stitched problems per size and density (default 5; quick 2)",
    )
    p.add_argument(
        "--time-limit",
        dest="time_limit_s",
        type=float,
        metavar="S",
        help="CP-SAT time limit per solve in seconds (default 10; quick 2)",
    )
    p.add_argument("--workers", type=int, help="CP-SAT workers (default 1)")
    p.add_argument(
        "--no-hint",
        dest="hint",
        action="store_false",
        default=None,
        help="do not warm-start CP-SAT from FCFS",
    )
    p.add_argument("--eval-robots", type=int, help="robots of the evaluator graph (default 250)")
    p.add_argument(
        "--eval-conflicts-per-robot",
        type=float,
        help="conflicts per robot of the evaluator graph (default 4)",
    )
    p.add_argument("--eval-samples", type=int, help="assignments per batch (default 100)")
    p.add_argument("--repeats", type=int, help="timing repeats (default 30; quick 10)")
    p.add_argument("--seed", type=int, help="base seed of every problem set (default 0)")
    p.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"directory for results.json, exact_runs.csv, solve_times.png "
        f"(default {DEFAULT_OUT}/)",
    )
    p.add_argument("--no-plot", action="store_true", help="skip the PNG plot")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    return p.parse_args(argv)


def config_from_args(args: argparse.Namespace) -> Config:
    """The run's configuration: --quick or full defaults, overridden by explicit flags."""
    base = QUICK if args.quick else Config()
    given = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(Config)
        if getattr(args, f.name, None) is not None
    }
    for key in ("small_robots", "large_robots", "large_densities"):
        if key in given:
            given[key] = tuple(given[key])
    if args.objective != "all":
        given["objectives"] = (args.objective,)
    cfg = dataclasses.replace(base, **given)
    if cfg.small_count < 1 or cfg.large_count < 1 or cfg.repeats < 1 or cfg.eval_samples < 1:
        raise SystemExit("counts, samples and repeats must be at least 1")
    if cfg.time_limit_s <= 0 or cfg.workers < 1:
        raise SystemExit("the time limit must be positive and workers at least 1")
    return cfg


def main(argv: Sequence[str] | None = None) -> int:
    """Run the benchmark, print its tables and write its files; returns the exit code."""
    args = _parse_args(argv)
    cfg = config_from_args(args)
    progress = not args.no_progress
    machine = machine_info()
    print(
        f"{machine['date']}  {machine['cpu']}  {machine['cpus']} CPU(s)  "
        f"Python {machine['python']}  OR-Tools {machine['packages']['ortools']}  "
        f"commit {machine['commit']}",
        flush=True,
    )

    started = time.perf_counter()
    problems = _problem_sets(cfg, progress)
    runs = run_exact(cfg, problems, progress)
    summary = summarize_solves(runs)
    auto_runs = run_auto(cfg, problems, progress)
    auto_summary = summarize_solves(auto_runs)
    ev = run_evaluator(cfg, progress)
    total_s = time.perf_counter() - started

    print()
    print(_exact_tables(summary, cfg))
    print()
    print(_auto_table(auto_summary, cfg))
    print()
    print(_evaluator_table(ev))
    print(f"\nTotal benchmark time: {total_s:.0f} s", flush=True)

    args.out.mkdir(parents=True, exist_ok=True)
    write_json(
        args.out / "results.json",
        {
            "config": dataclasses.asdict(cfg),
            "machine": machine,
            "total_s": total_s,
            "exact": {"summary": summary, "runs": runs},
            "auto": {"summary": auto_summary, "runs": auto_runs},
            "evaluator": ev,
        },
    )
    write_csv(args.out / "exact_runs.csv", runs)
    written = ["results.json", "exact_runs.csv"]
    if not args.no_plot:
        plot_solve_times(summary, cfg.time_limit_s, args.out / "solve_times.png")
        written.append("solve_times.png")
    print(f"Wrote {', '.join(str(args.out / w) for w in written)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
