"""The disturbance benchmark (issue 12): clock playback, dependency execution, re-scheduling.

``python -m bench.disturbances [--quick]`` plans seeded warehouse worlds
(kinds ``wh_*``, 25-250 robots) once each with ``auto`` (the graph is derived
once per world and kept in memory), then disturbs them with seeded draws of the
documented profiles (:data:`service.simulation.disturbances.PROFILES`: late
starts, stops and slow-downs) and runs every draw three ways:

* **a**: every robot plays its original (undisturbed) trajectory back by the
  clock; a disturbed robot falls behind its trajectory, the others keep to theirs;
* **b**: dependency execution of the original plan (the answer's orders);
* **c**: dependency execution re-scheduled every ``--period`` seconds of
  simulated time, or with ``--on-events`` whenever a disturbance starts or ends,
  by :class:`service.solvers.rescheduling.Rescheduler` with ``--replan-budget``
  seconds (:func:`service.motion.replan.execute_rescheduled`).

Per run it records collisions (the one clearance check of the executed
trajectories), deadlocks, mean and max completion and, for c, every
re-schedule's latency (the scheduler's call, and the whole step from reading the
state to swapping the plan in). Under ``--out`` it writes ``tables.md``
(per size, profile and mode: runs, collisions, deadlocks, completion mean and
spread, the change against b on the same draws, re-scheduling latency
p50/p95/max), ``disturbances.png``, and ``results.json`` / ``results.csv``.
A collision or deadlock in b or c, or a refused re-schedule (the run then
keeps its plan), fails the run (exit status 1); a's collisions are what
clock-based execution costs.
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.cases import run_cli
from bench.paths import _service_changes as service_changes  # belongs in bench.report
from bench.report import (
    add_run_args,
    fmt,
    jsonable,
    machine_info,
    save_figure,
    write_csv,
    write_json,
)
from service.core.path_schemas import PathsRequest
from service.core.problem import ErrorItem, ProblemError
from service.core.schemas import PreviousConflictIn, ProgressIn, ScheduleRequest, ScheduleResponse
from service.geometry.graph import CoordinationGraph, GeometrySettings
from service.learning.store import load_all
from service.memory import settle
from service.motion.plan import derive
from service.motion.replan import Solve, execute_rescheduled, plan_of
from service.motion.trajectories import trajectories
from service.scenarios import KINDS, generate
from service.simulation.clearance import Clearance, Trajectory, check_clearance
from service.simulation.disturbances import PROFILES, Disturbance, Rate, played_by_clock, rates_of
from service.simulation.executor import DependencyPlan, Run, execute
from service.solvers.dispatch import DispatchPolicy, dispatch
from service.solvers.rescheduling import Rescheduler

__all__ = ["MODES", "QUICK", "Config", "main", "run"]

MODES = ("a", "b", "c")
MODE_NAMES = {
    "a": "a: clock playback",
    "b": "b: dependencies, original orders",
    "c": "c: dependencies, re-scheduled",
}
WAREHOUSES = tuple(k for k in KINDS if k.startswith("wh_"))
MODEL_STORE = Path(__file__).resolve().parents[1] / "model_store"


@dataclass(frozen=True)
class Config:
    """What to run; the defaults are the full run documented in docs/benchmarks.md."""

    kinds: tuple[str, ...] = ("wh_two_way", "wh_two_lane", "wh_one_way", "wh_mixed")
    sizes: tuple[int, ...] = (25, 50, 100, 250)
    profiles: tuple[str, ...] = ("none", "light", "heavy")  # none: the control, one draw
    draws: tuple[int, ...] = (14, 8, 4, 1)  # per profile of a world: one per size, or one for all
    modes: tuple[str, ...] = MODES
    period_s: float = 15.0  # simulated seconds between re-schedules (mode c)
    on_events: bool = False  # re-schedule when a disturbance starts or ends instead
    time_limit_s: float = 2.0  # the initial plan (auto), as a request would ask
    replan_budget_s: float = 0.1  # time limit of every re-schedule
    replan_solver: str = "auto"
    objective: str = "avg_completion"
    base_seed: int = 0
    store: Path = MODEL_STORE
    out: Path = Path("docs/results/disturbances")


QUICK = Config(
    kinds=("wh_two_way", "wh_two_lane"),
    sizes=(10, 25),
    draws=(3,),
    period_s=10.0,
    out=Path("bench/out/disturbances-quick"),
)


@dataclass(frozen=True, eq=False)
class Planned:
    """One world planned once: its graph, graph-form request, answer and undisturbed run."""

    kind: str
    robots: int
    graph: CoordinationGraph
    request: ScheduleRequest
    answer: ScheduleResponse
    plan: DependencyPlan
    trajectories: list[Trajectory]  # the original trajectories (undisturbed execution)
    completion: np.ndarray  # (R,) undisturbed completion
    plan_s: float  # derive + initial solve

    @property
    def ids(self) -> list[str]:
        return [p.id for p in self.graph.paths]


def plan_world(kind: str, robots: int, cfg: Config, policy: DispatchPolicy) -> Planned:
    """Derive, solve (``auto``) and execute one seeded world undisturbed.

    Raises:
        ProblemError: the world's fixed paths leave no collision-free order (422).
        RuntimeError: the undisturbed plan deadlocks or collides (a bug).
    """
    world = generate(kind, robots, cfg.base_seed)
    options = {"solver": "auto", "time_limit_s": cfg.time_limit_s, "seed": 0}
    paths_request = PathsRequest.model_validate(world.to_request(cfg.objective, options))
    start = time.perf_counter()
    graph = derive(paths_request, GeometrySettings())
    request = graph.to_request(paths_request)
    if request is None:
        raise ProblemError([ErrorItem(("body", "robots"), "no two robots interfere")])
    answer = dispatch(request, policy)
    plan_s = time.perf_counter() - start
    plan = plan_of(graph, answer)
    run0 = execute(graph.paths, plan)
    trajs = trajectories(graph.paths, run0)
    if run0.deadlocked or not check_clearance(trajs).ok:
        raise RuntimeError(f"{kind} {robots}: the undisturbed plan is not clean")
    return Planned(kind, robots, graph, request, answer, plan, trajs, run0.completion, plan_s)


def draws_of(cfg: Config, robots: int) -> int:
    """Disturbance draws per profile of a world of ``robots`` robots.

    Raises:
        ValueError: ``draws`` has neither one entry nor one per size.
    """
    if len(cfg.draws) == 1:
        return cfg.draws[0]
    if len(cfg.draws) != len(cfg.sizes):
        raise ValueError(f"--draws: one number, or one per size ({len(cfg.sizes)})")
    return cfg.draws[cfg.sizes.index(robots)]


def runs_of(cfg: Config, robots: int) -> int:
    """Runs of one world: every profile, draw and mode (one draw of a quiet profile)."""
    draws = [1 if PROFILES[p].quiet else draws_of(cfg, robots) for p in cfg.profiles]
    return sum(draws) * len(cfg.modes)


def draw_seed(cfg: Config, kind: str, robots: int, profile: str, draw: int) -> int:
    """The seed of one disturbance draw: stable across runs, distinct per world, profile, draw."""
    return zlib.crc32(f"{cfg.base_seed}/{kind}/{robots}/{profile}/{draw}".encode())


def draw(planned: Planned, profile: str, seed: int) -> list[Disturbance]:
    """Disturbances of ``profile``, stops and slow-downs inside each robot's original run."""
    windows = [
        (p.id, p.start_time, float(c))
        for p, c in zip(planned.graph.paths, planned.completion, strict=True)
    ]
    return PROFILES[profile].draw(windows, seed)


def replan_times(cfg: Config, disturbances: Sequence[Disturbance]) -> Iterable[float]:
    """When mode c re-schedules: every period, or when a disturbance starts or ends (at the
    start the robot's delay is not yet known; at the end it is)."""
    if not cfg.on_events:
        return itertools.count(cfg.period_s, cfg.period_s)
    return sorted({t for d in disturbances for t in (d.start, d.start + d.duration)})


def run_mode(
    mode: str,
    planned: Planned,
    rates: list[Rate],
    solve: Solve | None,
    times: Iterable[float],
) -> dict[str, Any]:
    """One disturbed run in one mode: collisions, deadlocks, completion, re-schedules (c
    calls ``solve`` at ``times``)."""
    start = time.perf_counter()
    replans: list[dict[str, Any]] = []
    if mode == "a":
        trajs = [played_by_clock(t, r) for t, r in zip(planned.trajectories, rates, strict=True)]
        completion = np.array([t.t[-1] for t in trajs])
        deadlocked: tuple[int, ...] = ()
    else:
        if mode == "b":
            run: Run = execute(planned.graph.paths, planned.plan, rates)
        else:
            assert solve is not None, "mode c needs the re-scheduler"
            out = execute_rescheduled(planned.graph, planned.answer, rates, solve, times)
            run = out.run
            replans = [asdict(r) for r in out.replans]
        trajs = trajectories(planned.graph.paths, run)
        completion, deadlocked = run.completion, run.deadlocked
    clearance = check_clearance(trajs)
    return {
        **_clearance_fields(clearance),
        "deadlocked": len(deadlocked),
        "mean_completion": float(np.nanmean(completion)),
        "max_completion": float(np.nanmax(completion)),
        "replans": replans,
        "sim_s": time.perf_counter() - start,
    }


def _clearance_fields(clearance: Clearance) -> dict[str, Any]:
    """Whether a run collided, how many overlapping pairs, its least gap."""
    return {
        "collided": not clearance.ok,
        "overlaps": len(clearance.overlaps),
        "min_clearance_m": clearance.min_gap,
    }


def rescheduling(planned: Planned, cfg: Config, policy: DispatchPolicy) -> Solve:
    """Mode c's scheduler: one :class:`Rescheduler` per world, ``--replan-budget`` per call."""
    rescheduler = Rescheduler(planned.request, policy)

    def solve(previous: list[PreviousConflictIn], progress: ProgressIn) -> ScheduleResponse:
        return rescheduler.solve(
            previous, progress, time_limit_s=cfg.replan_budget_s, solver=cfg.replan_solver
        )

    return solve


def run_world(
    planned: Planned, cfg: Config, policy: DispatchPolicy, bar: tqdm
) -> list[dict[str, Any]]:
    """Every profile, draw and mode of one planned world: one row per run."""
    solve = rescheduling(planned, cfg, policy) if "c" in cfg.modes else None
    rows = []
    for profile in cfg.profiles:
        draws = 1 if PROFILES[profile].quiet else draws_of(cfg, planned.robots)
        for k in range(draws):
            seed = draw_seed(cfg, planned.kind, planned.robots, profile, k)
            disturbances = draw(planned, profile, seed)
            rates = rates_of(planned.ids, disturbances)
            for mode in cfg.modes:
                result = run_mode(mode, planned, rates, solve, replan_times(cfg, disturbances))
                rows.append(
                    {
                        "kind": planned.kind,
                        "robots": planned.robots,
                        "conflicts": len(planned.answer.assignment),
                        "profile": profile,
                        "draw": k,
                        "seed": seed,
                        "mode": mode,
                        "disturbances": len(disturbances),
                        "undisturbed_mean": float(np.mean(planned.completion)),
                        **result,
                    }
                )
                bar.update()
    return rows


def warm_up(cfg: Config, policy: DispatchPolicy) -> None:
    """A small world through every mode first: JIT compiling and first calls are not timed."""
    small = replace(cfg, base_seed=10_000, profiles=("heavy",), draws=(1,))
    with tqdm(disable=True) as bar:
        run_world(plan_world("wh_two_way", 10, small, policy), small, policy, bar)


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Plan every world and run every draw and mode; return everything that gets written."""
    models, errors = load_all(cfg.store, (cfg.objective,))
    if errors:
        raise SystemExit(f"models failed to load: {errors}")
    policy = DispatchPolicy(default_time_limit_s=cfg.time_limit_s, models=models)
    machine = {
        **machine_info(),
        "service_changes": service_changes(),
        "load_avg_1min_start": os.getloadavg()[0],
    }
    warm_up(cfg, policy)
    settle()  # the service's collector policy once warm (service.memory)
    worlds = [(kind, n) for n in cfg.sizes for kind in cfg.kinds]
    total = sum(runs_of(cfg, n) for _, n in worlds)
    rows: list[dict[str, Any]] = []
    planned_worlds: list[dict[str, Any]] = []
    with tqdm(total=total, desc="runs", unit="run", disable=not progress) as bar:
        for kind, n in worlds:
            try:
                planned = plan_world(kind, n, cfg, policy)
            except ProblemError as exc:
                planned_worlds.append({"kind": kind, "robots": n, "refused": str(exc)})
                bar.total -= runs_of(cfg, n)
                continue
            planned_worlds.append(
                {
                    "kind": kind,
                    "robots": n,
                    "refused": None,
                    "conflicts": len(planned.answer.assignment),
                    "solver": planned.answer.solver.name,
                    "plan_s": planned.plan_s,
                    "undisturbed_mean": float(np.mean(planned.completion)),
                    "undisturbed_max": float(np.max(planned.completion)),
                }
            )
            rows += run_world(planned, cfg, policy, bar)
    machine["load_avg_1min_end"] = os.getloadavg()[0]
    return {
        "machine": machine,
        "config": jsonable(asdict(cfg)),
        "worlds": planned_worlds,
        "rows": rows,
    }


def _spread(values: Sequence[float]) -> tuple[float, float]:
    """Mean and standard deviation of the finite values (NaN, NaN if none)."""
    arr = np.asarray(values, dtype=float)
    arr = arr[np.isfinite(arr)]
    return (float(arr.mean()), float(arr.std())) if arr.size else (np.nan, np.nan)


def _percentiles(values: Sequence[float]) -> tuple[float, float, float]:
    """p50, p95 and max (NaN if none)."""
    if not len(values):
        return np.nan, np.nan, np.nan
    p50, p95 = np.percentile(values, (50, 95))
    return float(p50), float(p95), float(np.max(values))


def against_b(rows: Sequence[dict[str, Any]]) -> dict[int, float]:
    """Per row (by index), its mean completion relative to mode b's on the same draw, minus 1."""
    key = ("kind", "robots", "profile", "draw")
    base = {tuple(r[k] for k in key): r["mean_completion"] for r in rows if r["mode"] == "b"}
    out = {}
    for i, r in enumerate(rows):
        b = base.get(tuple(r[k] for k in key))
        if b is not None:
            out[i] = r["mean_completion"] / b - 1.0
    return out


def summarize(rows: Sequence[dict[str, Any]], by: Sequence[str]) -> list[dict[str, Any]]:
    """Per group of ``by`` keys: runs, collisions, deadlocks, completion mean and spread, the
    change against b on the same draws, and re-scheduling counts and latencies."""
    change = against_b(rows)
    groups: dict[tuple, list[int]] = {}
    for i, r in enumerate(rows):
        groups.setdefault(tuple(r[k] for k in by), []).append(i)
    out = []
    for key, members in groups.items():
        sel = [rows[i] for i in members]
        replans = [p for r in sel for p in r["replans"]]
        mean_c, max_c = (
            _spread([r[f] for r in sel]) for f in ("mean_completion", "max_completion")
        )
        delta = [change[i] for i in members if i in change]
        solve = _percentiles([p["solve_s"] for p in replans if p["error"] is None])
        total = _percentiles([p["total_s"] for p in replans if p["error"] is None])
        out.append(
            {
                **dict(zip(by, key, strict=True)),
                "runs": len(sel),
                "collided": sum(r["collided"] for r in sel),
                "overlaps": sum(r["overlaps"] for r in sel),
                "deadlocked": sum(r["deadlocked"] > 0 for r in sel),
                "mean_completion": mean_c[0],
                "mean_completion_sd": mean_c[1],
                "max_completion": max_c[0],
                "max_completion_sd": max_c[1],
                "vs_b": _spread(delta)[0],
                "vs_b_sd": _spread(delta)[1],
                "better_than_b": float(np.mean([d < 0 for d in delta])) if delta else np.nan,
                "replans": len(replans),
                "replan_changed": sum(p["changed"] for p in replans),
                "replan_errors": sum(p["error"] is not None for p in replans),
                "solve_p50": solve[0],
                "solve_p95": solve[1],
                "solve_max": solve[2],
                "total_p50": total[0],
                "total_p95": total[1],
                "total_max": total[2],
                "sim_s": float(np.sum([r["sim_s"] for r in sel])),
            }
        )
    return out


def failures(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Runs of b or c that collided or deadlocked (never meant to happen)."""
    return [r for r in rows if r["mode"] != "a" and (r["collided"] or r["deadlocked"])]


def refusals(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every refused re-schedule (the run kept its plan), with its run's world and draw."""
    return [
        {"kind": r["kind"], "robots": r["robots"], "profile": r["profile"], "draw": r["draw"], **p}
        for r in rows
        for p in r["replans"]
        if p["error"] is not None
    ]


def verdict(rows: Sequence[dict[str, Any]]) -> str:
    """The loud part: collisions or deadlocks of b or c, and refused re-schedules."""
    bad, refused = failures(rows), refusals(rows)
    lines = [
        f"**{len(bad)} RUN(S) OF b OR c COLLIDED OR DEADLOCKED**"
        if bad
        else "**No collision and no deadlock in b or c.**"
    ]
    if refused:
        runs = {(r["kind"], r["robots"], r["profile"], r["draw"]) for r in refused}
        lines.append(
            f"**{len(refused)} re-schedule(s) refused** in {len(runs)} run(s) (the run kept "
            f"its plan); the first: {refused[0]['kind']} {refused[0]['robots']} robots, "
            f"t = {refused[0]['time']:g} s: {refused[0]['error'].splitlines()[0]}"
        )
    return "\n\n".join(lines)


def _ms(x: float) -> str:
    return "-" if x != x else f"{1000 * x:.0f}"


def _pct(x: float) -> str:
    return "-" if x != x else f"{100 * x:+.1f} %"


def _pm(mean: float, sd: float, digits: int = 1) -> str:
    return "-" if mean != mean else f"{mean:.{digits}f} ± {sd:.{digits}f}"


def run_table(summary: Sequence[dict[str, Any]]) -> str:
    """Markdown table per robots, profile and mode."""
    headers = [
        "robots",
        "profile",
        "mode",
        "runs",
        "collided",
        "deadlocked",
        "mean completion s",
        "max completion s",
        "vs b (same draws)",
        "c better",
        "re-schedules",
        "solve p50/p95/max ms",
        "step p50/p95/max ms",
    ]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for s in summary:
        is_c = s["mode"] == "c"
        cells = [
            s["robots"],
            s["profile"],
            s["mode"],
            s["runs"],
            f"{s['collided']} ({s['overlaps']} pairs)" if s["collided"] else "0",
            s["deadlocked"],
            _pm(s["mean_completion"], s["mean_completion_sd"]),
            _pm(s["max_completion"], s["max_completion_sd"]),
            "" if s["mode"] == "b" else f"{_pct(s['vs_b'])} ± {fmt(100 * s['vs_b_sd'], 1)}",
            f"{100 * s['better_than_b']:.0f} %"
            if is_c and s["better_than_b"] == s["better_than_b"]
            else "",
            f"{s['replans']} ({s['replan_changed']} changed"
            + (f", {s['replan_errors']} refused)" if s["replan_errors"] else ")")
            if is_c
            else "",
            "/".join(_ms(s[f"solve_{p}"]) for p in ("p50", "p95", "max")) if is_c else "",
            "/".join(_ms(s[f"total_{p}"]) for p in ("p50", "p95", "max")) if is_c else "",
        ]
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(lines)


def totals_text(summary: Sequence[dict[str, Any]]) -> str:
    """Per mode over every size and profile: runs, collisions, deadlocks (the targets)."""
    lines = ["| mode | runs | collided | deadlocked | re-schedules | solve p95 ms |"]
    lines.append("|---|---|---|---|---|---|")
    for s in summary:
        solve = _ms(s["solve_p95"]) if s["mode"] == "c" else ""
        lines.append(
            f"| {MODE_NAMES[s['mode']]} | {s['runs']} | {s['collided']} | {s['deadlocked']} | "
            f"{s['replans'] if s['mode'] == 'c' else ''} | {solve} |"
        )
    return "\n".join(lines)


def plot(summary: Sequence[dict[str, Any]], budget_s: float, path: Path) -> None:
    """Three panels against robots: completion change against b (a and c, per profile, with
    the spread), the share of a's runs that collided, and re-scheduling latency."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, axes = plt.subplots(1, 3, figsize=(16, 4.8))
    profiles = list(dict.fromkeys(s["profile"] for s in summary))
    styles = {"light": "o-", "heavy": "s--"}
    for profile in profiles:
        style = styles.get(profile, "^-")
        for mode, color in (("a", "tab:red"), ("c", "tab:green")):
            sel = sorted(
                (s for s in summary if s["profile"] == profile and s["mode"] == mode),
                key=lambda s: s["robots"],
            )
            if not sel:
                continue
            x = [s["robots"] for s in sel]
            axes[0].errorbar(
                x,
                [100 * s["vs_b"] for s in sel],
                yerr=[100 * s["vs_b_sd"] for s in sel],
                fmt=style,
                color=color,
                capsize=3,
                label=f"{mode}, {profile}",
            )
            if mode == "a":
                share = [100 * s["collided"] / s["runs"] for s in sel]
                axes[1].plot(x, share, style, color=color, label=profile)
            else:
                axes[2].plot(
                    x,
                    [1000 * s["solve_p50"] for s in sel],
                    style,
                    color="tab:blue",
                    label=f"p50, {profile}",
                )
                axes[2].plot(
                    x,
                    [1000 * s["solve_p95"] for s in sel],
                    style,
                    color="tab:purple",
                    label=f"p95, {profile}",
                )
    axes[0].axhline(0.0, color="grey", linewidth=1)
    axes[0].set(ylabel="mean completion vs b (%)", title="completion against b, same draws")
    axes[1].set(
        ylabel="runs with a collision (%)", title="a: clock playback collides", ylim=(-5, 105)
    )
    axes[2].axhline(1000 * budget_s, color="grey", linestyle=":", label="budget")
    axes[2].set(ylabel="re-schedule latency (ms)", title="c: re-scheduling latency", ylim=(0, None))
    sizes = sorted({s["robots"] for s in summary})
    for ax in axes:
        ax.set(xscale="log", xlabel="robots")
        ax.set_xticks(sizes, [str(n) for n in sizes])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:  # a panel of a mode not run stays empty
            ax.legend(fontsize="small")
    save_figure(fig, path)


def report(results: dict[str, Any], out: Path) -> str:
    """Write tables, plot and raw files under ``out``; return the tables' text."""
    out.mkdir(parents=True, exist_ok=True)
    rows, m, c = results["rows"], results["machine"], results["config"]
    summary = summarize(rows, ("robots", "profile", "mode"))
    trigger = "on events" if c["on_events"] else f"every {c['period_s']:g} s"
    refused = [w for w in results["worlds"] if w["refused"] is not None]
    text = "\n\n".join(
        [
            f"Run {m['date']} on {m['cpu']} ({m['cpus']} CPUs), commit {m['commit']}"
            + (
                f" plus uncommitted changes to {', '.join(m['service_changes'])}; "
                if m.get("service_changes")
                else "; "
            )
            + f"1-minute load average {m['load_avg_1min_start']:.1f} at the start, "
            f"{m['load_avg_1min_end']:.1f} at the end. Kinds {', '.join(c['kinds'])}, "
            f"seed {c['base_seed']}; initial plan auto {c['time_limit_s']:g} s; "
            f"re-scheduling {trigger} with {c['replan_solver']} and "
            f"{1000 * c['replan_budget_s']:g} ms; draws per world and profile "
            f"{'/'.join(map(str, c['draws']))} (sizes {'/'.join(map(str, c['sizes']))}). "
            "Refused worlds: "
            + (", ".join(f"{w['kind']} {w['robots']}" for w in refused) or "none")
            + ".",
            verdict(rows),
            "Disturbed runs (every profile but the control), per mode:",
            totals_text(
                summarize([r for r in rows if not PROFILES[r["profile"]].quiet], ("mode",))
            ),
            run_table(summary),
            "Completion in simulated seconds (mean ± standard deviation over runs); vs b: the "
            "run's mean completion against b's on the same world and draw; re-schedules: how "
            "many, how many answered another assignment (its plan swapped in); solve: the "
            "re-scheduler's call; step: reading the state, the call, the new dependency plan "
            "and swapping it in.",
        ]
    )
    (out / "tables.md").write_text(text + "\n")
    write_json(out / "results.json", results)
    write_csv(out / "results.csv", [{k: v for k, v in r.items() if k != "replans"} for r in rows])
    plot(summary, c["replan_budget_s"], out / "disturbances.png")
    return text


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a CI smoke run of a minute or two")
    p.add_argument("--kinds", nargs="+", choices=WAREHOUSES)
    p.add_argument("--sizes", type=int, nargs="+", help="robots per world")
    p.add_argument("--profiles", nargs="+", choices=tuple(PROFILES))
    p.add_argument(
        "--draws", type=int, nargs="+", help="draws per world and profile: one, or one per size"
    )
    p.add_argument("--modes", nargs="+", choices=MODES)
    p.add_argument("--period", type=float, dest="period_s", help="simulated s between re-schedules")
    p.add_argument("--on-events", action="store_true", default=None, help="re-schedule on events")
    p.add_argument("--time-limit", type=float, dest="time_limit_s", help="initial plan, s")
    p.add_argument("--replan-budget", type=float, dest="replan_budget_s", help="re-schedule, s")
    p.add_argument("--replan-solver", help="solver of the re-schedules (default auto)")
    p.add_argument("--objective", choices=("avg_completion",))
    add_run_args(p)
    return p.parse_args(argv)


def failed(results: dict[str, Any]) -> str | None:
    """Why the run failed: runs of b or c that collided or deadlocked, or refusals."""
    bad = failures(results["rows"]) + refusals(results["rows"])
    return f"{len(bad)} collided or deadlocked run(s) of b or c, or refusals" if bad else None


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry: 1 when a run of b or c collided or deadlocked, or a re-schedule was refused."""
    skip = ("quick", "summarize", "cache")
    return run_cli(_parse_args(argv), Config(), QUICK, run, report, failed, skip)


if __name__ == "__main__":
    raise SystemExit(main())
