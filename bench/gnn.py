"""GNN-VAE benchmark: quality and time against the exact optimum, small and large.

``python -m bench.gnn [--quick]`` runs, with the shipped models:

1. held-out small problems (generator seed differs from the training data's),
   per objective: mean optimality ratio with S = 1, 10, 100 samples, mean delay
   ratio, and runtime per problem; FCFS beside it; and the independent
   conformance sets (another generator, and geometric problems) as a
   generalization check;
2. stitched problems of 25 to 250 robots, sparse and dense: the GNN-VAE's cost
   and time against CP-SAT with a generous time limit, side by side: the ratio
   against the best known cost, and how long CP-SAT needs to reach the
   GNN-VAE's cost.

``--store`` and ``--objectives`` measure candidates where they were trained
(``--store runs/candidates --objectives avg_completion --sizes``: small problems
only, one objective); the problems depend on ``--small`` alone, so two stores'
runs are compared problem by problem: ``--baseline OUT`` pairs the small problems
against another run's ``--out`` (mean difference and its standard error per set,
objective and sample count).

Figures: optimality ratio = opt / cost (the published one); delay ratio =
(opt - free) / (cost - free), free = the cost with zero delay (1 when
cost = opt): the share of the achievable delay reduction; for avg_delay, whose
optimum is often 0, the mean absolute gap is reported instead.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.report import cost_ratio, delay_ratio, save_figure
from service.core.cliques import find_cliques
from service.core.decode import Decoder
from service.core.evaluate import Evaluator
from service.core.problem import Problem, problem_from_request
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.features import graph_tensors
from service.learning.generate import small_problem, stitched_problem
from service.learning.infer import sample_best
from service.learning.store import StoredModel, load_all
from service.solvers.exact import solve
from service.solvers.fcfs import fcfs
from service.solvers.refine import gnn_vae_refined
from service.solvers.registry import SolveContext

HELDOUT_SEED = 1  # training data uses seed 0
CONFORMANCE = Path(__file__).resolve().parents[1] / "tests" / "data" / "conformance"
SAMPLE_COUNTS = (1, 10, 100)


@dataclass(frozen=True)
class Prepared:
    """A problem with the structures every method needs."""

    problem: Problem
    request: ScheduleRequest

    @classmethod
    def of(cls, request: dict[str, Any]) -> Prepared:
        req = ScheduleRequest.model_validate(request)
        return cls(problem_from_request(req), req)


def run_gnn(
    stored: StoredModel, prep: Prepared, objective: str, samples: int
) -> tuple[float, float]:
    """(cost, seconds) of the GNN-VAE on one problem, request overhead included."""
    start = time.perf_counter()
    cliques = find_cliques(prep.problem)
    evaluator = Evaluator(prep.problem)
    graph = graph_tensors(prep.problem, cliques)
    best = sample_best(
        stored.model, graph, Decoder(prep.problem, cliques), evaluator, objective, samples, seed=0
    )
    return best.cost, time.perf_counter() - start


def run_refined(
    models: dict[str, StoredModel], prep: Prepared, objective: str, limit: float
) -> tuple[float, float]:
    """(cost, seconds) of gnn_vae_refined on one problem, request overhead included."""
    start = time.perf_counter()
    ctx = SolveContext(prep.problem, objective, time_limit_s=limit, models=models)
    out = gnn_vae_refined(ctx)
    cost = float(ctx.evaluator.evaluate(out.assignment).costs[objective][0])
    return cost, time.perf_counter() - start


def run_fcfs(prep: Prepared, objective: str) -> float:
    """FCFS cost of one problem."""
    ctx = SolveContext(prep.problem, objective, time_limit_s=1.0)
    return float(ctx.evaluator.evaluate(fcfs(ctx).assignment).costs[objective][0])


def small_rows(
    models: dict[str, StoredModel], cases: list[tuple[str, Prepared, float]], label: str
) -> list[dict[str, Any]]:
    """Per-problem results on small problems with known optimum ``ref``."""
    rows = []
    for objective, prep, ref in tqdm(cases, desc=label, unit="problem"):
        free = Evaluator(prep.problem).free_costs()[objective]
        row: dict[str, Any] = {
            "set": label,
            "objective": objective,
            "robots": prep.problem.n_robots,
            "conflicts": prep.problem.n_conflicts,
            "opt": ref,
            "free": free,
            "fcfs": run_fcfs(prep, objective),
        }
        for s in SAMPLE_COUNTS:
            row[f"gnn{s}"], row[f"gnn{s}_s"] = run_gnn(models[objective], prep, objective, s)
        rows.append(row)
    return rows


def held_out_cases(n: int, objectives: tuple[str, ...]) -> list[tuple[str, Prepared, float]]:
    """``n`` fresh generated problems per objective, solved to optimality by CP-SAT."""
    cases = []
    for i in tqdm(range(n), desc="held-out optima", unit="problem"):
        seed = int(np.random.SeedSequence([HELDOUT_SEED, i]).generate_state(1)[0])
        prep = Prepared.of(small_problem(seed))
        cliques = find_cliques(prep.problem)
        for objective in objectives:
            result = solve(prep.problem, cliques, objective, 60.0)
            assert result is not None and result.optimal
            cost = float(Evaluator(prep.problem).evaluate(result.assignment).costs[objective][0])
            cases.append((objective, prep, cost))
    return cases


def conformance_cases(objectives: tuple[str, ...]) -> list[tuple[str, Prepared, float]]:
    """The shipped conformance problems with their independently computed optima."""
    cases = []
    for name in ("small.jsonl", "geo_10.jsonl"):
        for line in (CONFORMANCE / name).read_text().splitlines():
            rec = json.loads(line)
            if rec["request"]["objective"] in objectives:
                cases.append(
                    (rec["request"]["objective"], Prepared.of(rec["request"]), rec["ref_cost"])
                )
    return cases


def large_rows(
    models: dict[str, StoredModel],
    sizes: list[int],
    densities: dict[str, float],
    per_size: int,
    limit: float,
    objective: str,
    samples: int,
) -> list[dict[str, Any]]:
    """GNN-VAE against time-limited CP-SAT on stitched problems, side by side."""
    rows = []
    jobs = [(n, d, k) for n in sizes for d in densities for k in range(per_size)]
    for n, dname, k in tqdm(jobs, desc="large", unit="problem"):
        prep = Prepared.of(stitched_problem(1000 * n + k, n, densities[dname], objective))
        gnn_cost, gnn_s = run_gnn(models[objective], prep, objective, samples)
        refined_cost, refined_s = run_refined(models, prep, objective, limit)
        evaluator = Evaluator(prep.problem)
        trace: list[tuple[float, float]] = []

        def record(t: float, assignment: Any, ev: Evaluator = evaluator, out: list = trace) -> None:
            out.append((t, float(ev.evaluate(assignment).costs[objective][0])))

        start = time.perf_counter()
        result = solve(
            prep.problem, find_cliques(prep.problem), objective, limit, on_solution=record
        )
        exact_s = time.perf_counter() - start

        def reach(cost: float, tr: list = trace) -> float | None:
            return next((t for t, c in tr if c <= cost * (1 + 1e-9)), None)

        exact_cost = trace[-1][1] if trace else float("inf")
        rows.append(
            {
                "robots": n,
                "density": dname,
                "conflicts": prep.problem.n_conflicts,
                "objective": objective,
                "free": evaluator.free_costs()[objective],
                "gnn": gnn_cost,
                "gnn_s": gnn_s,
                "refined": refined_cost,
                "refined_s": refined_s,
                "exact": exact_cost,
                "exact_s": exact_s,
                "exact_optimal": bool(result is not None and result.optimal),
                "exact_reach_gnn_s": reach(gnn_cost),
                "exact_reach_refined_s": reach(refined_cost),
                "best": min(gnn_cost, refined_cost, exact_cost),
                "fcfs": run_fcfs(prep, objective),
            }
        )
    return rows


def summarize_small(rows: list[dict[str, Any]]) -> list[str]:
    """Table lines: per set and objective, ratio / delay ratio per method, runtime."""
    out = [
        f"{'set':10} {'objective':16} {'n':>5}  "
        + "  ".join(f"{m:>17}" for m in ("fcfs", *[f"gnn S={s}" for s in SAMPLE_COUNTS]))
        + "  gnn100 ms"
    ]
    keys = sorted({(r["set"], r["objective"]) for r in rows})
    for set_name, objective in keys:
        sel = [r for r in rows if r["set"] == set_name and r["objective"] == objective]
        cells = []
        for m in ("fcfs", *[f"gnn{s}" for s in SAMPLE_COUNTS]):
            if objective == "avg_delay":
                cells.append(f"gap {np.mean([r[m] - r['opt'] for r in sel]):9.4f}")
            else:
                ratio = np.mean([cost_ratio(r["opt"], r[m]) for r in sel])
                dr = np.nanmean([delay_ratio(r["opt"], r[m], r["free"]) for r in sel])
                cells.append(f"{ratio:.4f} / {dr:.3f}")
        ms = 1e3 * np.mean([r["gnn100_s"] for r in sel])
        out.append(
            f"{set_name:10} {objective:16} {len(sel):5d}  "
            + "  ".join(f"{c:>17}" for c in cells)
            + f"  {ms:9.1f}"
        )
    out.append(
        "cells: mean optimality ratio / mean delay ratio (avg_delay: mean gap to the optimum)"
    )
    return out


def paired_lines(rows: list[dict[str, Any]], base: list[dict[str, Any]]) -> list[str]:
    """Table lines: per set, objective and sample count, the mean per-problem difference
    against a baseline run on the same problems, with its standard error (positive: this
    run is better; ratio for the completion objectives, minus the gap for avg_delay).

    Two models' means on 300-1000 random problems differ by about one standard error of
    noise with one sample (~0.0009 at 1000): pairing the problems is what tells a loss
    from noise.

    Raises:
        ValueError: the two runs did not solve the same problems (optima differ).
    """
    out = [
        f"{'set':10} {'objective':16} {'n':>5}  "
        + "  ".join(f"{f'S={s} (base, diff +- se)':>34}" for s in SAMPLE_COUNTS)
    ]
    keys = sorted({(r["set"], r["objective"]) for r in rows})
    for set_name, objective in keys:
        sel = [r for r in rows if r["set"] == set_name and r["objective"] == objective]
        ref = [r for r in base if r["set"] == set_name and r["objective"] == objective]
        if [r["opt"] for r in sel] != [r["opt"] for r in ref]:
            raise ValueError(f"the baseline solved other {set_name} {objective} problems")
        score = _gap_score if objective == "avg_delay" else _ratio_score
        cells = []
        for s in SAMPLE_COUNTS:
            mine = np.array([score(r, f"gnn{s}") for r in sel])  # (n,)
            theirs = np.array([score(r, f"gnn{s}") for r in ref])  # (n,)
            diff = mine - theirs
            se = diff.std(ddof=1) / np.sqrt(diff.size) if diff.size > 1 else np.nan
            cells.append(f"{theirs.mean():.4f}, {diff.mean():+.5f} +- {se:.5f}")
        out.append(
            f"{set_name:10} {objective:16} {len(sel):5d}  " + "  ".join(f"{c:>34}" for c in cells)
        )
    out.append(
        "paired against the baseline: its mean, then this run's mean difference +- its "
        "standard error (positive: better; avg_delay: minus the gap)"
    )
    return out


def _ratio_score(row: dict[str, Any], key: str) -> float:
    return cost_ratio(row["opt"], row[key])


def _gap_score(row: dict[str, Any], key: str) -> float:
    return row["opt"] - row[key]


def _reach_text(sel: list[dict[str, Any]], key: str) -> str:
    """Mean CP-SAT time to reach a method's cost ('+': some never did, counted at the limit)."""
    reach = [r[key] for r in sel]
    never = sum(x is None for x in reach)
    if never == len(sel):
        return "never"
    capped = [r["exact_s"] if x is None else x for x, r in zip(reach, sel, strict=True)]
    return f"{np.mean(capped):.2f}" + "+" * bool(never)


LARGE_METHODS = ("fcfs", "gnn", "refined", "exact")


def summarize_large(rows: list[dict[str, Any]]) -> list[str]:
    """Table lines: per size and density, every method side by side."""
    head = "".join(f" {m + ' ratio/dr':>17}" for m in LARGE_METHODS)
    out = [
        f"{'robots':>6} {'density':8} {'confl':>6}{head} {'gnn s':>6} {'ref s':>6} "
        f"{'exact s':>8} {'proven':>6} {'ex->gnn s':>9} {'ex->ref s':>9}"
    ]
    for n in sorted({r["robots"] for r in rows}):
        for d in sorted({r["density"] for r in rows}):
            sel = [r for r in rows if r["robots"] == n and r["density"] == d]
            if not sel:
                continue
            cells = "".join(
                f" {np.mean([cost_ratio(r['best'], r[m]) for r in sel]):8.4f}/"
                f"{np.nanmean([delay_ratio(r['best'], r[m], r['free']) for r in sel]):<8.3f}"
                for m in LARGE_METHODS
            )
            out.append(
                f"{n:6d} {d:8} {np.mean([r['conflicts'] for r in sel]):6.0f}{cells} "
                f"{np.mean([r['gnn_s'] for r in sel]):6.3f} "
                f"{np.mean([r['refined_s'] for r in sel]):6.3f} "
                f"{np.mean([r['exact_s'] for r in sel]):8.2f} "
                f"{sum(r['exact_optimal'] for r in sel):3d}/{len(sel):<2d} "
                f"{_reach_text(sel, 'exact_reach_gnn_s'):>9} "
                f"{_reach_text(sel, 'exact_reach_refined_s'):>9}"
            )
    out.append(
        "ratio = best known / cost, dr = delay ratio, against the best cost any method found; "
        "ex->X s: CP-SAT time to reach method X's cost ('+': some never did within the limit, "
        "counted at the limit); gnn = gnn_vae (S samples), ref = gnn_vae_refined"
    )
    return out


def plot_large(rows: list[dict[str, Any]], path: Path) -> None:
    """Ratio and runtime versus robots, per density, GNN-VAE and CP-SAT."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for d in sorted({r["density"] for r in rows}):
        sizes = sorted({r["robots"] for r in rows if r["density"] == d})
        for method, style in (("gnn", "-o"), ("refined", "-^"), ("exact", "--s"), ("fcfs", ":x")):
            sel = [[r for r in rows if r["robots"] == n and r["density"] == d] for n in sizes]
            axes[0].plot(
                sizes,
                [
                    np.nanmean([delay_ratio(r["best"], r[method], r["free"]) for r in g])
                    for g in sel
                ],
                style,
                label=f"{method} {d}",
            )
            if method != "fcfs":  # instant; its time is not recorded
                axes[1].plot(
                    sizes,
                    [np.mean([r[f"{method}_s"] for r in g]) for g in sel],
                    style,
                    label=f"{method} {d}",
                )
    axes[0].set(xlabel="robots", ylabel="mean delay ratio", title="quality vs best known")
    axes[1].set(xlabel="robots", ylabel="seconds", yscale="log", title="runtime")
    for ax in axes:
        ax.legend()
        ax.grid(alpha=0.3)
    save_figure(fig, path)


def main(argv: list[str] | None = None) -> None:
    """CLI entry."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a smoke run of about a minute")
    p.add_argument("--store", type=Path, default=Path("model_store"))
    p.add_argument("--small", type=int, default=1000, help="held-out small problems")
    p.add_argument(
        "--sizes", type=int, nargs="*", default=[25, 50, 100, 250], help="none: small only"
    )
    p.add_argument("--per-size", type=int, default=3)
    p.add_argument("--exact-limit", type=float, default=60.0)
    p.add_argument(
        "--objectives",
        nargs="+",
        choices=OBJECTIVES,
        default=list(OBJECTIVES),
        help="small problems' objectives (a store of candidates may hold only some)",
    )
    p.add_argument("--large-objective", choices=OBJECTIVES, default="avg_completion")
    p.add_argument("--samples", type=int, default=100)
    p.add_argument("--out", type=Path, default=Path("bench/out/gnn"))
    p.add_argument(
        "--baseline",
        type=Path,
        help="another run's --out: small problems paired against its (same problems)",
    )
    p.add_argument(
        "--summarize",
        action="store_true",
        help="only re-render tables and plot from the raw results in --out",
    )
    args = p.parse_args(argv)
    if args.summarize:
        rows = json.loads((args.out / "small.json").read_text())
        large = json.loads((args.out / "large.json").read_text())
        report(rows, large, args.out, _baseline(args.baseline))
        return
    if args.quick:
        args.small, args.sizes, args.per_size, args.exact_limit = 20, [25, 50], 1, 5.0
    small = tuple(args.objectives)
    extra = (args.large_objective,) if args.sizes and args.large_objective not in small else ()
    models, errors = load_all(args.store, small + extra)
    if errors:
        raise SystemExit(f"models failed to load: {errors}")
    args.out.mkdir(parents=True, exist_ok=True)
    rows = small_rows(models, held_out_cases(args.small, small), "held-out")
    rows += small_rows(models, conformance_cases(small), "conform")
    large = large_rows(
        models,
        args.sizes,
        {"sparse": 2.0, "dense": 4.0},
        args.per_size,
        args.exact_limit,
        args.large_objective,
        args.samples,
    )
    (args.out / "small.json").write_text(json.dumps(rows, indent=1))
    (args.out / "large.json").write_text(json.dumps(large, indent=1))
    report(rows, large, args.out, _baseline(args.baseline))


def _baseline(out: Path | None) -> list[dict[str, Any]] | None:
    """The small-problem rows of a baseline run (None: no baseline)."""
    return None if out is None else json.loads((out / "small.json").read_text())


def report(
    rows: list[dict[str, Any]],
    large: list[dict[str, Any]],
    out: Path,
    base: list[dict[str, Any]] | None = None,
) -> None:
    """Print the tables (small problems paired against ``base`` too, if given) and write
    them and the plot under ``out``."""
    lines = summarize_small(rows)
    if base is not None:
        lines += [""] + paired_lines(rows, base)
    lines += [""] + summarize_large(large)
    print("\n".join(lines))
    (out / "tables.txt").write_text("\n".join(lines) + "\n")
    if large:
        plot_large(large, out / "large.png")


if __name__ == "__main__":
    main()
