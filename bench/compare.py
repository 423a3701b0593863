"""The published comparison: every solver on the same problems, same machine, side by side.

``python -m bench.compare [--quick]`` runs each method of the solver registry
(random, fcfs, tabu, cmaes, bbts, gnn_vae, gnn_vae_refined, gnn_vae_exact and
exact) on stitched problems of 5 to 250 robots at a sparse and a dense
conflict density and on held-out problems of the training generator (2-8
robots, set ``small``), each with the same time limit, and a sample-count
ablation of the GNN-VAE. It writes, under ``--out``:

* ``tables.md``: per objective, density and robot count, for every method the
  mean and 10th-percentile optimality ratio (reference / cost), the mean delay
  ratio ((ref - free) / (cost - free), where free is the cost with no delay at
  all: the share of the achievable delay reduction), the mean gap, the mean
  runtime, how often it reached the reference and how soon (for the CP-SAT
  based methods: when their first solution that good came), and how long the
  long CP-SAT run needed to reach the method's cost;
* ``compare-<objective>.png`` (ratio, delay ratio and runtime versus robots,
  one line per method, one column per density) and ``ablation.png``;
* ``results.json`` / ``results.csv`` / ``ablation.csv``: every per-problem result.

The reference cost of a problem is the best of CP-SAT with ``--ref-limit``
seconds and every method's cost (``ref_source`` records which). Problem sets
come from seeds (:mod:`bench.problems`); reference solves are cached under
``--cache`` so a re-run, or a run with more methods, does not repeat them.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.problems import BenchProblem, small_set, stitched_set
from bench.report import (
    add_run_args,
    cost_ratio,
    delay_ratio,
    fmt,
    format_table,
    jsonable,
    machine_info,
    nanmean,
    reference_cache,
    save_figure,
    write_csv,
    write_json,
)
from bench.report import config_from_args as _override
from service.core.assignment import Assignments
from service.core.check import check
from service.core.evaluate import Evaluator
from service.core.schemas import OBJECTIVES
from service.learning.generate import GeneratorConfig
from service.learning.store import StoredModel, load_all
from service.memory import settle
from service.solvers.dispatch import DispatchPolicy  # noqa: F401  (registers every solver)
from service.solvers.exact import solve
from service.solvers.registry import SolveContext, get_solver

__all__ = ["Config", "QUICK", "main", "run"]

METHODS = (
    "random",
    "fcfs",
    "tabu",
    "cmaes",
    "bbts",
    "gnn_vae",
    "gnn_vae_refined",
    "gnn_vae_exact",
    "exact",
)
DENSITIES = {"sparse": 2.0, "dense": 4.0}  # conflicts per robot
SMALL = "small"  # the set name of the training generator's (held-out) problems
# Fleets smaller than two default parts (2-8 robots) are stitched from 2-3 robot parts.
SMALL_FLEET = GeneratorConfig(min_robots=2, max_robots=3)
REL_TOL = 1e-9  # a cost within this relative distance of the reference counts as reaching it
MODEL_STORE = Path(__file__).resolve().parents[1] / "model_store"


@dataclass(frozen=True)
class Config:
    """What to run; the defaults are the full run documented in docs/benchmarks.md."""

    objectives: tuple[str, ...] = ("avg_completion",)
    sizes: tuple[int, ...] = (5, 10, 25, 50, 100, 250)
    densities: tuple[str, ...] = ("sparse", "dense")
    per_size: int = 3
    small_sizes: tuple[int, ...] = (4, 8)  # robots of held-out training-generator problems
    small_per_size: int = 20
    methods: tuple[str, ...] = METHODS
    time_limit_s: float = 5.0
    ref_limit_s: float = 60.0
    ablation_sizes: tuple[int, ...] = (10, 50, 250)
    ablation_samples: tuple[int, ...] = (1, 2, 5, 10, 20, 50, 100, 200)
    base_seed: int = 0
    store: Path = MODEL_STORE
    out: Path = Path("bench/out/compare")
    cache: Path = Path("bench/cache")


QUICK = Config(
    sizes=(5, 10, 25),
    per_size=1,
    small_sizes=(4,),
    small_per_size=2,
    time_limit_s=1.0,
    ref_limit_s=5.0,
    ablation_sizes=(25,),
    ablation_samples=(1, 10, 100),
    out=Path("bench/out/compare-quick"),
)


@dataclass
class Case:
    """One problem under one objective, with its reference."""

    bp: BenchProblem
    density: str
    objective: str
    free: float
    ref_cost: float = float("inf")
    ref_optimal: bool = False
    ref_trace: list[tuple[float, float]] = field(default_factory=list)  # CP-SAT (s, cost)


def problem_sets(cfg: Config) -> list[tuple[str, BenchProblem]]:
    """(density name, problem) for every size and density, deterministic from the base seed.

    The held-out problems of the training generator come last, under the name
    ``SMALL`` (their seeds never coincide with the training data's).
    """
    out = []
    for density in cfg.densities:
        for n in cfg.sizes:
            parts = SMALL_FLEET if n < 10 else GeneratorConfig()
            problems = stitched_set(n, DENSITIES[density], cfg.per_size, cfg.base_seed, parts)
            out += [(density, bp) for bp in problems]
    for n in cfg.small_sizes:
        out += [(SMALL, bp) for bp in small_set(n, cfg.small_per_size, cfg.base_seed)]
    return out


class ReferenceCache:
    """Long CP-SAT solves by problem seed, objective and limit, kept in one JSON file."""

    def __init__(self, directory: Path, limit_s: float) -> None:
        self.cache = reference_cache(directory, f"compare-ref-{limit_s:g}s")
        self.limit_s = limit_s

    def get(self, case: Case) -> None:
        """Fill the case's reference from the cache, or solve it and store it."""
        key = f"{case.bp.seed}-{case.bp.robots}-{case.objective}"
        hit = self.cache.get(key, lambda: _reference_solve(case, self.limit_s))
        case.ref_cost, case.ref_optimal = hit["cost"], hit["optimal"]
        case.ref_trace = [tuple(p) for p in hit["trace"]]


def _reference_solve(case: Case, limit_s: float) -> dict[str, Any]:
    """CP-SAT with a long limit, with the time of every improving solution."""
    evaluator = Evaluator(case.bp.problem)
    trace: list[tuple[float, float]] = []

    def record(t: float, assignment: Assignments) -> None:
        trace.append((t, float(evaluator.evaluate(assignment).costs[case.objective][0])))

    result = solve(case.bp.problem, case.bp.cliques, case.objective, limit_s, on_solution=record)
    cost = min((c for _, c in trace), default=float("inf"))
    if result is not None:
        cost = min(cost, float(evaluator.evaluate(result.assignment).costs[case.objective][0]))
    return {"cost": cost, "optimal": bool(result and result.optimal), "trace": trace}


def run_method(
    name: str, case: Case, cfg: Config, models: dict[str, StoredModel], samples: int | None = None
) -> dict[str, Any]:
    """One method on one case: cost, runtime, validity and, for CP-SAT based ones, its trace."""
    trace: list[tuple[float, Assignments]] = []
    start = time.perf_counter()
    ctx = SolveContext(
        case.bp.problem,
        case.objective,
        cfg.time_limit_s,
        samples=samples,
        models=models,
        on_solution=lambda _t, a: trace.append((time.perf_counter() - start, a)),
    )
    out = get_solver(name)(ctx)
    runtime = time.perf_counter() - start
    if out is None:
        return {"method": name, "cost": float("nan"), "runtime_s": runtime, "valid": False}
    evaluate = ctx.evaluator.evaluate
    return {
        "method": name,
        "cost": float(evaluate(out.assignment).costs[case.objective][0]),
        "runtime_s": runtime,
        "valid": bool(check(case.bp.problem, case.bp.cliques, out.assignment).ok[0]),
        "optimal": out.optimal,
        "trace": [(t, float(evaluate(a).costs[case.objective][0])) for t, a in trace],
    }


def _first_time(trace: Sequence[tuple[float, float]], cost: float) -> float | None:
    """When a trace of (seconds, cost) first reached ``cost`` (None: never)."""
    return next((t for t, c in trace if c <= cost * (1 + REL_TOL)), None)


def finish_rows(
    case: Case, results: list[dict[str, Any]], others: Sequence[dict[str, Any]] = ()
) -> list[dict[str, Any]]:
    """Per-method rows of one case, measured against the best cost anyone found.

    ``others`` are earlier results on the same case (the ablation passes the
    comparison's): they count for the reference but get no rows.
    """
    known = [r for r in (*results, *others) if r["valid"]]
    ref = min([case.ref_cost, *(r["cost"] for r in known)])
    if ref < case.ref_cost * (1 - REL_TOL):
        source = next(r["method"] for r in known if r["cost"] == ref)
    else:
        source = "cp-sat optimal" if case.ref_optimal else "cp-sat best"
    rows = []
    for r in results:
        cost, reached = r["cost"], r["valid"] and r["cost"] <= ref * (1 + REL_TOL)
        trace = r.get("trace") or []
        rows.append(
            {
                "objective": case.objective,
                "density": case.density,
                "robots": case.bp.robots,
                "conflicts": case.bp.problem.n_conflicts,
                "index": case.bp.index,
                "seed": case.bp.seed,
                "method": r["method"],
                "valid": r["valid"],
                "cost": cost,
                "runtime_s": r["runtime_s"],
                "ref_cost": ref,
                "ref_source": source,
                "free": case.free,
                "ratio": cost_ratio(ref, cost),
                "delay_ratio": delay_ratio(ref, cost, case.free),
                "gap": cost - ref,
                "reached_ref": bool(reached),
                "time_to_ref_s": _first_time(trace, ref)
                if trace
                else (r["runtime_s"] if reached else None),
                "cpsat_time_to_cost_s": _first_time(case.ref_trace, cost),
            }
        )
    return rows


def _cases(cfg: Config, refs: ReferenceCache, progress: bool) -> list[Case]:
    """Every (problem, objective) of the run, with references solved or read from the cache."""
    cases = [
        Case(bp, density, objective, Evaluator(bp.problem).free_costs()[objective])
        for density, bp in problem_sets(cfg)
        for objective in cfg.objectives
    ]
    for case in tqdm(cases, desc="references", unit="problem", disable=not progress):
        refs.get(case)
    return cases


def warm_up(cfg: Config, models: dict[str, StoredModel]) -> None:
    """Run every method once on a tiny problem: JIT compiling is not part of any runtime."""
    bp = stitched_set(5, 2.0, 1, base_seed=10_000, cfg=SMALL_FLEET)[0]
    for objective in cfg.objectives:
        case = Case(bp, "sparse", objective, 0.0)
        for name in cfg.methods:
            run_method(name, case, replace(cfg, time_limit_s=0.2), models)


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Run the comparison and the ablation; return everything that gets written."""
    models, errors = load_all(cfg.store, cfg.objectives)
    if errors:
        raise SystemExit(f"models failed to load: {errors}")
    refs = ReferenceCache(cfg.cache, cfg.ref_limit_s)
    cases = _cases(cfg, refs, progress)
    warm_up(cfg, models)
    settle()  # the service's collector policy once warm: the cases held escape full collections
    rows: list[dict[str, Any]] = []
    compared: list[list[dict[str, Any]]] = []  # per case, every method's result
    for case in tqdm(cases, desc="methods", unit="problem", disable=not progress):
        compared.append([run_method(m, case, cfg, models) for m in cfg.methods])
        rows += finish_rows(case, compared[-1])
    ablation = []
    chosen = [
        (c, r) for c, r in zip(cases, compared, strict=True) if c.bp.robots in cfg.ablation_sizes
    ]
    for case, others in tqdm(chosen, desc="ablation", unit="problem", disable=not progress):
        results = [run_method("gnn_vae", case, cfg, models, s) for s in cfg.ablation_samples]
        finished = finish_rows(case, results, others)
        ablation += [
            {**row, "samples": s} for s, row in zip(cfg.ablation_samples, finished, strict=True)
        ]
    return {
        "machine": machine_info(),
        "config": jsonable(asdict(cfg)),
        "rows": rows,
        "ablation": ablation,
    }


def summarize(rows: Sequence[dict[str, Any]], by: Sequence[str]) -> list[dict[str, Any]]:
    """Mean/p10 ratio, mean delay ratio, gap and runtime per group of ``by`` keys, in order."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in by), []).append(r)
    out = []
    for key, members in groups.items():
        answered = [m for m in members if m["valid"]]
        ratio = np.array([m["ratio"] for m in answered]) if answered else np.array([np.nan])
        cpsat = [m["cpsat_time_to_cost_s"] for m in answered]
        out.append(
            {
                **dict(zip(by, key, strict=True)),
                "problems": len(members),
                "answered": len(answered),
                "ratio_mean": float(np.mean(ratio)),
                "ratio_p10": float(np.percentile(ratio, 10)),
                "delay_ratio_mean": nanmean([m["delay_ratio"] for m in answered]),
                "gap_mean": nanmean([m["gap"] for m in answered]),
                "runtime_s_mean": float(np.mean([m["runtime_s"] for m in members])),
                "reached_ref": float(np.mean([m["reached_ref"] for m in members])),
                "time_to_ref_s_mean": nanmean(
                    [np.nan if m["time_to_ref_s"] is None else m["time_to_ref_s"] for m in members]
                ),
                "cpsat_reached": sum(t is not None for t in cpsat),
                "cpsat_time_s_mean": nanmean([np.nan if t is None else t for t in cpsat]),
            }
        )
    return out


def comparison_table(summary: Sequence[dict[str, Any]]) -> str:
    """Markdown table of the per-method summary."""
    headers = [
        "objective",
        "density",
        "robots",
        "method",
        "n",
        "ratio",
        "p10 ratio",
        "delay ratio",
        "gap",
        "runtime s",
        "reached ref",
        "s to ref",
        "CP-SAT s to its cost",
    ]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for s in summary:
        cpsat = (
            "never"
            if s["cpsat_reached"] == 0
            else fmt(s["cpsat_time_s_mean"], 2)
            + ("+" if s["cpsat_reached"] < s["answered"] else "")
        )
        cells = [
            s["objective"],
            s["density"],
            s["robots"],
            s["method"],
            s["answered"],
            fmt(s["ratio_mean"], 4),
            fmt(s["ratio_p10"], 4),
            fmt(s["delay_ratio_mean"]),
            fmt(s["gap_mean"], 4),
            fmt(s["runtime_s_mean"]),
            f"{100 * s['reached_ref']:.0f} %",
            fmt(s["time_to_ref_s_mean"], 2),
            cpsat,
        ]
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(lines)


def ablation_table(summary: Sequence[dict[str, Any]]) -> str:
    """Plain-text table of the sample-count ablation."""
    return format_table(
        [
            "objective",
            "density",
            "robots",
            "samples",
            "ratio",
            "p10 ratio",
            "delay ratio",
            "runtime s",
        ],
        [
            [
                s["objective"],
                s["density"],
                s["robots"],
                s["samples"],
                fmt(s["ratio_mean"], 4),
                fmt(s["ratio_p10"], 4),
                fmt(s["delay_ratio_mean"]),
                fmt(s["runtime_s_mean"]),
            ]
            for s in summary
        ],
    )


def plot_comparison(summary: Sequence[dict[str, Any]], objective: str, path: Path) -> None:
    """Ratio, delay ratio and runtime versus robots: one line per method, one column per density."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [s for s in summary if s["objective"] == objective]
    densities = list(dict.fromkeys(s["density"] for s in rows))
    panels = (
        ("ratio_mean", "optimality ratio"),
        ("delay_ratio_mean", "delay ratio"),
        ("runtime_s_mean", "runtime (s)"),
    )
    fig, axes = plt.subplots(3, len(densities), figsize=(6 * len(densities), 11), squeeze=False)
    for col, density in enumerate(densities):
        for method in dict.fromkeys(s["method"] for s in rows):
            sel = sorted(
                (s for s in rows if s["density"] == density and s["method"] == method),
                key=lambda s: s["robots"],
            )
            for row, (key, label) in enumerate(panels):
                ax = axes[row, col]
                ax.plot([s["robots"] for s in sel], [s[key] for s in sel], "o-", label=method)
                ax.set(xscale="log", xlabel="robots", ylabel=label)
                ax.set_title(f"{objective}, {_set_label(density)}")
                ax.grid(True, which="both", alpha=0.3)
        axes[2, col].set_yscale("log")
    axes[0, 0].legend(fontsize="small")
    save_figure(fig, path)


def _set_label(density: str) -> str:
    """A problem set's name for plot titles."""
    if density == SMALL:
        return "small (training generator, held out)"
    return f"{density} ({DENSITIES[density]:g} conflicts/robot)"


def plot_ablation(summary: Sequence[dict[str, Any]], path: Path) -> None:
    """GNN-VAE ratio and runtime versus samples, one line per (density, robots)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for key in dict.fromkeys((s["objective"], s["density"], s["robots"]) for s in summary):
        sel = [s for s in summary if (s["objective"], s["density"], s["robots"]) == key]
        label = f"{key[1]}, {key[2]} robots"
        axes[0].plot([s["samples"] for s in sel], [s["ratio_mean"] for s in sel], "o-", label=label)
        axes[1].plot(
            [s["samples"] for s in sel], [s["runtime_s_mean"] for s in sel], "o-", label=label
        )
    axes[0].set(
        xscale="log",
        xlabel="samples S",
        ylabel="optimality ratio",
        title="gnn_vae: quality vs samples",
    )
    axes[1].set(
        xscale="log",
        yscale="log",
        xlabel="samples S",
        ylabel="runtime (s)",
        title="gnn_vae: runtime vs samples",
    )
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize="small")
    save_figure(fig, path)


def report(results: dict[str, Any], out: Path) -> str:
    """Write tables, plots and raw files under ``out``; return the tables' text."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(results["rows"], ("objective", "density", "robots", "method"))
    ablation = summarize(results["ablation"], ("objective", "density", "robots", "samples"))
    m = results["machine"]
    text = "\n\n".join(
        [
            f"Run {m['date']} on {m['cpu']} ({m['cpus']} CPUs), commit {m['commit']}; "
            f"time limit {results['config']['time_limit_s']} s per method, reference CP-SAT "
            f"{results['config']['ref_limit_s']} s.",
            comparison_table(summary),
            "GNN-VAE sample-count ablation:\n\n```\n" + ablation_table(ablation) + "\n```",
        ]
    )
    (out / "tables.md").write_text(text + "\n")
    write_json(out / "results.json", results)
    write_csv(out / "results.csv", results["rows"])
    write_csv(out / "ablation.csv", results["ablation"])
    for objective in dict.fromkeys(s["objective"] for s in summary):
        plot_comparison(summary, objective, out / f"compare-{objective}.png")
    if ablation:
        plot_ablation(ablation, out / "ablation.png")
    return text


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a CI smoke run of about 2 minutes")
    p.add_argument("--objectives", nargs="+", choices=OBJECTIVES)
    p.add_argument("--sizes", type=int, nargs="+", help="robot counts")
    p.add_argument("--densities", nargs="+", choices=tuple(DENSITIES))
    p.add_argument("--per-size", type=int, help="problems per robot count and density")
    p.add_argument(
        "--small-sizes", type=int, nargs="*", help="robots of held-out small problems (none: skip)"
    )
    p.add_argument("--small-per-size", type=int, help="held-out small problems per robot count")
    p.add_argument("--methods", nargs="+", choices=METHODS)
    p.add_argument("--time-limit", type=float, dest="time_limit_s", help="seconds per method")
    p.add_argument("--ref-limit", type=float, dest="ref_limit_s", help="reference CP-SAT seconds")
    p.add_argument("--ablation-sizes", type=int, nargs="*")
    p.add_argument("--ablation-samples", type=int, nargs="+")
    add_run_args(p)
    return p.parse_args(argv)


def config_from_args(args: argparse.Namespace) -> Config:
    """The quick or full defaults, overridden by every flag given."""
    return _override(args, Config(), QUICK)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry."""
    args = _parse_args(argv)
    cfg = config_from_args(args)
    results = json.loads((cfg.out / "results.json").read_text()) if args.summarize else run(cfg)
    print(report(results, cfg.out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
