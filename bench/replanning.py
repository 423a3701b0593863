"""Re-scheduling by budget (issue 12, item 4): latency and quality of one re-schedule.

``python -m bench.replanning [--quick]`` plans one seeded warehouse world per
kind and size as :mod:`bench.disturbances` does, executes it under one heavy
disturbance draw with re-scheduling every ``--period`` s (``auto``, 100 ms)
and records the fleet's state at every re-schedule: the assignment being
executed (wire ``previous``) and the graph-form progress. Up to ``--states`` of
those moments, spread over the run, are then re-scheduled again with every
budget of ``--budgets`` (the budgets of one moment back to back, in a rotating
order, by the same :class:`~service.solvers.rescheduling.Rescheduler`, as a
fleet's loop would call it).

Per budget it reports the call's latency (p50 / p95 / max and the share over
the budget) and the answer's cost against the best any budget found for the
same moment (cost ratio, and delay ratio over the residual problem's
delay-free cost). Under ``--out``: ``tables.md``, ``results.json`` /
``results.csv`` and ``replanning.png``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.cases import run_cli
from bench.disturbances import (
    MODEL_STORE,
    WAREHOUSES,
    draw,
    draw_seed,
    plan_world,
    replan_times,
)
from bench.disturbances import Config as DisturbanceConfig
from bench.report import (
    add_run_args,
    delay_ratio,
    jsonable,
    machine_info,
    markdown_table,
    save_figure,
    write_results,
)
from service.core.evaluate import Evaluator
from service.core.problem import ProblemError
from service.core.progress import previous_from_wire, progress_from_wire, residual_problem
from service.core.schemas import PreviousConflictIn, ProgressIn, ScheduleResponse
from service.learning.store import load_all
from service.motion.replan import execute_rescheduled
from service.simulation.disturbances import rates_of
from service.solvers.dispatch import DispatchPolicy
from service.solvers.rescheduling import Rescheduler

__all__ = ["QUICK", "Config", "main", "run"]


@dataclass(frozen=True)
class Config:
    """What to run; the defaults are the run documented in docs/benchmarks.md."""

    kinds: tuple[str, ...] = ("wh_two_way", "wh_two_lane", "wh_one_way", "wh_mixed")
    sizes: tuple[int, ...] = (250,)
    budgets: tuple[float, ...] = (0.05, 0.1, 0.3, 1.0)
    states: int = 12  # moments re-scheduled again per world
    period_s: float = 15.0
    profile: str = "heavy"
    time_limit_s: float = 2.0  # the initial plan
    capture_budget_s: float = 0.1  # the re-schedules of the run that records the moments
    solver: str = "auto"
    objective: str = "avg_completion"
    base_seed: int = 0
    store: Path = MODEL_STORE
    out: Path = Path("docs/results/replanning")


QUICK = Config(
    kinds=("wh_two_way",),
    sizes=(15,),
    budgets=(0.02, 0.1),
    states=3,
    period_s=10.0,
    out=Path("bench/out/replanning-quick"),
)


@dataclass(frozen=True)
class Moment:
    """The fleet's state at one re-schedule: what it executes and how far it got."""

    previous: list[PreviousConflictIn]
    progress: ProgressIn


def as_disturbances(cfg: Config) -> DisturbanceConfig:
    """The disturbance benchmark's settings this run plans, draws and re-schedules with."""
    return replace(
        DisturbanceConfig(),
        base_seed=cfg.base_seed,
        period_s=cfg.period_s,
        time_limit_s=cfg.time_limit_s,
    )


def capture(planned: Any, cfg: Config, rescheduler: Rescheduler) -> list[Moment]:
    """Every re-schedule's input over one disturbed run of ``planned`` (mode c)."""
    moments: list[Moment] = []

    def solve(previous: list[PreviousConflictIn], progress: ProgressIn) -> ScheduleResponse:
        moments.append(Moment(previous, progress))
        return rescheduler.solve(
            previous, progress, time_limit_s=cfg.capture_budget_s, solver=cfg.solver
        )

    disturbance_cfg = as_disturbances(cfg)
    seed = draw_seed(disturbance_cfg, planned.kind, planned.robots, cfg.profile, 0)
    disturbances = draw(planned, cfg.profile, seed)
    execute_rescheduled(
        planned.graph,
        planned.answer,
        rates_of(planned.ids, disturbances),
        solve,
        replan_times(disturbance_cfg, disturbances),
    )
    return moments


def spread(moments: Sequence[Moment], k: int) -> list[int]:
    """Indices of ``k`` moments evenly spread over the run (all if there are fewer)."""
    if len(moments) <= k:
        return list(range(len(moments)))
    return sorted({int(round(x)) for x in np.linspace(0, len(moments) - 1, k)})


def free_cost(rescheduler: Rescheduler, moment: Moment, objective: str) -> float:
    """The residual problem's cost with no delay caused by anyone (the delay ratio's base)."""
    problem = rescheduler.problem
    warm = previous_from_wire(problem, moment.previous)
    residual = residual_problem(problem, progress_from_wire(problem, moment.progress), warm)
    return float(Evaluator(residual).free_costs()[objective])


def measure_world(
    kind: str, robots: int, cfg: Config, policy: DispatchPolicy, bar: tqdm
) -> list[dict[str, Any]]:
    """Re-schedule the captured moments of one world with every budget: one row per call."""
    planned = plan_world(kind, robots, as_disturbances(cfg), policy)
    rescheduler = Rescheduler(planned.request, policy)
    moments = capture(planned, cfg, rescheduler)
    picked = spread(moments, cfg.states)
    bar.total += len(picked) * len(cfg.budgets)
    rows = []
    for j, i in enumerate(picked):
        moment = moments[i]
        free = free_cost(rescheduler, moment, cfg.objective)
        order = np.roll(np.arange(len(cfg.budgets)), j)  # no budget always runs first
        for b in order.tolist():
            budget = cfg.budgets[b]
            start = time.perf_counter()
            answer = rescheduler.solve(
                moment.previous, moment.progress, time_limit_s=budget, solver=cfg.solver
            )
            rows.append(
                {
                    "kind": kind,
                    "robots": robots,
                    "conflicts": len(planned.answer.assignment),
                    "moment": i,
                    "moments": len(moments),
                    "time": moment.progress.time,
                    "budget_s": budget,
                    "latency_s": time.perf_counter() - start,
                    "cost": answer.cost,
                    "free": free,
                    "detail": answer.solver.detail,
                }
            )
            bar.update()
    best: dict[int, float] = {}
    for row in rows:
        best[row["moment"]] = min(best.get(row["moment"], np.inf), row["cost"])
    for row in rows:
        row["best"] = best[row["moment"]]
        row["cost_ratio"] = row["best"] / row["cost"] if row["cost"] > 0 else 1.0
        row["delay_ratio"] = delay_ratio(row["best"], row["cost"], row["free"])
    return rows


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Plan, capture and re-schedule every world; return everything that gets written."""
    models, errors = load_all(cfg.store, (cfg.objective,))
    if errors:
        raise SystemExit(f"models failed to load: {errors}")
    policy = DispatchPolicy(default_time_limit_s=cfg.time_limit_s, models=models)
    machine = {**machine_info(), "load_avg_1min_start": os.getloadavg()[0]}
    warm_up = replace(cfg, states=1)  # JIT compiling and first calls are not measured
    measure_world("wh_two_way", 10, warm_up, policy, tqdm(total=0, disable=True))
    rows: list[dict[str, Any]] = []
    refused: list[dict[str, Any]] = []
    with tqdm(total=0, desc="re-schedules", unit="call", disable=not progress) as bar:
        for robots in cfg.sizes:
            for kind in cfg.kinds:
                try:
                    rows += measure_world(kind, robots, cfg, policy, bar)
                except ProblemError as exc:
                    refused.append({"kind": kind, "robots": robots, "error": str(exc)})
    machine["load_avg_1min_end"] = os.getloadavg()[0]
    return {"machine": machine, "config": jsonable(asdict(cfg)), "rows": rows, "refused": refused}


def summarize(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per size and budget: latency percentiles, share over budget, mean ratios."""
    out = []
    for robots in sorted({r["robots"] for r in rows}):
        for budget in sorted({r["budget_s"] for r in rows}):
            group = [r for r in rows if r["robots"] == robots and r["budget_s"] == budget]
            ms = 1000 * np.array([r["latency_s"] for r in group])
            out.append(
                {
                    "robots": robots,
                    "budget_s": budget,
                    "calls": len(group),
                    "conflicts": sorted({r["conflicts"] for r in group}),
                    "p50_ms": float(np.percentile(ms, 50)),
                    "p95_ms": float(np.percentile(ms, 95)),
                    "max_ms": float(ms.max()),
                    "over_budget": float(np.mean(ms > 1000 * budget)),
                    "cost_ratio": float(np.mean([r["cost_ratio"] for r in group])),
                    "delay_ratio": float(np.nanmean([r["delay_ratio"] for r in group])),
                    "best_share": float(np.mean([r["cost"] <= r["best"] for r in group])),
                }
            )
    return out


def table(summary: Sequence[dict[str, Any]]) -> str:
    """The per-size, per-budget table."""
    headers = (
        "robots",
        "conflicts",
        "budget ms",
        "calls",
        "latency p50 / p95 / max ms",
        "over budget",
        "cost ratio",
        "delay ratio",
        "best found",
    )
    rows = [
        (
            s["robots"],
            f"{min(s['conflicts']):,}-{max(s['conflicts']):,}",
            f"{1000 * s['budget_s']:g}",
            s["calls"],
            f"{s['p50_ms']:.0f} / {s['p95_ms']:.0f} / {s['max_ms']:.0f}",
            f"{100 * s['over_budget']:.0f} %",
            f"{s['cost_ratio']:.4f}",
            f"{s['delay_ratio']:.3f}",
            f"{100 * s['best_share']:.0f} %",
        )
        for s in summary
    ]
    return markdown_table(headers, rows)


def plot(summary: Sequence[dict[str, Any]], path: Path) -> None:
    """Cost ratio and p95 latency against the budget, one line per size."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for robots in sorted({s["robots"] for s in summary}):
        group = [s for s in summary if s["robots"] == robots]
        budgets = [1000 * s["budget_s"] for s in group]
        axes[0].plot(budgets, [s["cost_ratio"] for s in group], "o-", label=f"{robots} robots")
        axes[1].plot(budgets, [s["p95_ms"] for s in group], "o-", label=f"{robots} robots")
    top = max(1000 * s["budget_s"] for s in summary)
    axes[1].plot([0, top], [0, top], "k:", label="the budget")
    axes[0].set(xscale="log", xlabel="budget (ms)", ylabel="cost ratio (best / cost)")
    axes[1].set(xscale="log", yscale="log", xlabel="budget (ms)", ylabel="latency p95 (ms)")
    axes[0].set_title("re-schedule quality")
    axes[1].set_title("re-schedule latency")
    for ax in axes:
        ax.legend()
        ax.grid(alpha=0.3)
    save_figure(fig, path, dpi=120)


def report(results: dict[str, Any], out: Path) -> str:
    """Write tables, plot and raw files under ``out``; return the tables' text."""
    out.mkdir(parents=True, exist_ok=True)
    m, c, rows = results["machine"], results["config"], results["rows"]
    summary = summarize(rows)
    refused = ", ".join(f"{r['kind']} {r['robots']}" for r in results["refused"]) or "none"
    text = "\n\n".join(
        [
            f"Run {m['date']} on {m['cpu']} ({m['cpus']} CPUs), commit {m['commit']}; "
            f"1-minute load average {m['load_avg_1min_start']:.1f} at the start, "
            f"{m['load_avg_1min_end']:.1f} at the end. Kinds {', '.join(c['kinds'])}, seed "
            f"{c['base_seed']}; one {c['profile']} draw per world, re-scheduled every "
            f"{c['period_s']:g} s with {c['solver']} and {1000 * c['capture_budget_s']:g} ms; "
            f"{c['states']} of its moments per world re-scheduled again with every budget. "
            f"Refused worlds: {refused}.",
            table(summary),
            "Latency: the `Rescheduler.solve` call (residual problem, solve, check, answer "
            "with its dependency plan). Cost ratio: the best cost any budget found for the "
            "moment over the call's (1 = the best); delay ratio: the same over the "
            "residual problem's delay-free cost; best found: share of calls at the best.",
        ]
    )
    write_results(out, text, results, rows)
    plot(summary, out / "replanning.png")
    return text


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a CI smoke run of well under a minute")
    p.add_argument("--kinds", nargs="+", choices=WAREHOUSES)
    p.add_argument("--sizes", type=int, nargs="+", help="robots per world")
    p.add_argument("--budgets", type=float, nargs="+", help="re-schedule budgets, s")
    p.add_argument("--states", type=int, help="moments re-scheduled again per world")
    p.add_argument("--period", type=float, dest="period_s", help="simulated s between calls")
    add_run_args(p)
    return p.parse_args(argv)


def refused(results: dict[str, Any]) -> str | None:
    """Why the run failed: a world the geometry refused (else None)."""
    return f"refused worlds {results['refused']}" if results["refused"] else None


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry: 1 when a world was refused."""
    skip = ("quick", "summarize", "cache")
    return run_cli(_parse_args(argv), Config(), QUICK, run, report, refused, skip)


if __name__ == "__main__":
    raise SystemExit(main())
