"""The paths form end to end: every solver on seeded obstacle floors and warehouses.

``python -m bench.paths [--quick]`` is the published out-of-distribution test
and more. Worlds come from the scenario generator (:mod:`service.scenarios`):
planner-made obstacle floors (kinds ``floor_*``) with 2-20 robots and
warehouses (kinds ``wh_*``) with 10-250 robots, ``--worlds`` per kind and
size. Each world goes through :func:`service.motion.plan.plan_paths` (what
``POST /v1/schedules`` runs for a paths-form body) once per solver of the
registry and ``auto``, each with the same time limit; at ``--fast-only-from``
robots and above only the fast solvers run. Per world and solver it records
the graph-building, solve, motion and end-to-end times, the executed cost,
the cost ratio (reference / cost), the delay ratio ((reference - free) /
(cost - free), free = the mean planned completion with no delay), the
minimum clearance and the collision-free flag (the service's, and a replay of
the wire trajectories through the clearance check). Worlds whose fixed paths
leave no collision-free order are refused with a 422 (``ProblemError``) and
counted per kind and size. Under ``--out`` it writes:

* ``tables.md``: per family and size, for every solver the mean cost ratio,
  delay ratio, executed cost over the graph evaluator's cost of the same assignment
  (how optimistic the model the solvers optimize is), minimum clearance,
  graph/solve/motion/end-to-end times and the refused count; the refusals per kind and
  size; every failed check;
* ``paths.png``: cost ratio and end-to-end time versus robots, one line per
  solver, one panel per family;
* ``results.json`` / ``results.csv``: every per-world result.

The reference of a world is the best executed cost of the ``exact`` solver
with ``--ref-limit`` seconds and of every solver (``ref_source`` records
which); reference runs are cached under ``--cache`` by world content, so a
re-run does not repeat them. A collision, a failed replay or an error other
than a 422 fails the run (exit status 1).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.report import (
    add_run_args,
    config_from_args,
    delay_ratio,
    fmt,
    jsonable,
    machine_info,
    nanmean,
    reference_cache,
    save_figure,
    write_csv,
    write_json,
)
from service.core.assignment import Assignments
from service.core.evaluate import Evaluator, costs_from_completion
from service.core.path_schemas import PathsRequest, PathsScheduleResponse
from service.core.problem import ProblemError
from service.core.schemas import OBJECTIVES
from service.geometry.graph import GeometrySettings
from service.geometry.paths import RobotPath
from service.learning.store import load_all
from service.memory import settle
from service.motion.plan import derive, plan_paths
from service.motion.replan import decision
from service.scenarios import KINDS, World, generate
from service.simulation.clearance import Trajectory, check_clearance
from service.solvers.dispatch import DispatchPolicy
from service.solvers.registry import solver_names

__all__ = ["QUICK", "SOLVERS", "Config", "WorldCase", "main", "run"]

# Every registered solver (the dispatcher registers them all, ``auto`` included), in
# registry order. (Until session 28 ``auto`` was appended once more, and ran twice.)
SOLVERS = tuple(n for n in solver_names() if n != "none")
FAST_SOLVERS = ("fcfs", "gnn_vae", "gnn_vae_refined", "tabu", "auto")
REFERENCE_SOLVER = "exact"
FLOOR, WAREHOUSE = "floor", "warehouse"
FAMILY_PREFIX = {FLOOR: "floor_", WAREHOUSE: "wh_"}
REL_TOL = 1e-9  # a cost within this relative distance of the reference counts as reaching it
MODEL_STORE = Path(__file__).resolve().parents[1] / "model_store"
# Status of one (world, solver) run.
OK, REFUSED, ERROR = "ok", "refused", "error"
# plan_paths's note when the solver's plan did not execute cleanly and ran all-exclusive.
ALL_EXCLUSIVE = "executed with every conflict exclusive"
TIMINGS = ("graph_s", "solve_s", "motion_s")  # the answer's own timings; the rest is rendering


@dataclass(frozen=True)
class Config:
    """What to run; the defaults are the full run documented in docs/benchmarks.md."""

    kinds: tuple[str, ...] = tuple(sorted(KINDS, key=lambda k: not k.startswith("floor_")))
    floor_sizes: tuple[int, ...] = (2, 5, 10, 20)
    warehouse_sizes: tuple[int, ...] = (10, 25, 50, 100, 250)
    worlds: int = 3  # per kind and size
    solvers: tuple[str, ...] = SOLVERS
    fast_solvers: tuple[str, ...] = FAST_SOLVERS
    fast_only_from: int = 250  # robots from which only the fast solvers run
    objective: str = "avg_completion"
    time_limit_s: float = 2.0
    ref_limit_s: float = 10.0
    base_seed: int = 0
    store: Path = MODEL_STORE
    out: Path = Path("docs/results/paths")
    cache: Path = Path("bench/cache")


QUICK = Config(
    floor_sizes=(2, 5),
    warehouse_sizes=(10,),
    worlds=1,
    solvers=("fcfs", "exact", "gnn_vae"),
    time_limit_s=0.5,
    ref_limit_s=1.0,
    out=Path("bench/out/paths-quick"),
)


@dataclass
class WorldCase:
    """One seeded world with its reference (``ref`` is None when the world is refused)."""

    family: str
    kind: str
    robots: int
    index: int
    seed: int
    world: World
    free: float  # mean planned completion with no delay
    ref: dict[str, Any] | None = None  # the reference run: status, cost, message, ...

    @property
    def refused(self) -> str | None:
        """The 422 message when the world's fixed paths leave no collision-free order."""
        return self.ref["message"] if self.ref and self.ref["status"] == REFUSED else None


def family_of(kind: str) -> str:
    """``floor`` or ``warehouse``, from the kind's name."""
    for family, prefix in FAMILY_PREFIX.items():
        if kind.startswith(prefix):
            return family
    raise ValueError(f"kind {kind!r} is neither a floor nor a warehouse")


def free_cost(world: World) -> float:
    """Mean planned completion with no delay: each robot's own finish time, averaged."""
    req = PathsRequest.model_validate(world.to_request())
    return float(np.mean([RobotPath.from_wire(r).finish_time for r in req.robots]))


def world_cases(cfg: Config) -> list[WorldCase]:
    """Every world of the run, deterministic from the base seed (seed = base + index)."""
    cases = []
    for kind in cfg.kinds:
        family = family_of(kind)
        for n in cfg.floor_sizes if family == FLOOR else cfg.warehouse_sizes:
            for index in range(cfg.worlds):
                seed = cfg.base_seed + index
                world = generate(kind, n, seed)
                cases.append(WorldCase(family, kind, n, index, seed, world, free_cost(world)))
    return cases


def solvers_for(cfg: Config, robots: int) -> tuple[str, ...]:
    """The solvers that run on worlds of ``robots`` robots (only the fast ones on the largest)."""
    if robots < cfg.fast_only_from:
        return cfg.solvers
    return tuple(s for s in cfg.solvers if s in cfg.fast_solvers)


def solve_world(
    world: World, solver: str, objective: str, time_limit_s: float, policy: DispatchPolicy
) -> dict[str, Any]:
    """One paths-form solve of ``world``, timed, with its answer replayed and checked.

    Status ``refused`` is the service's 422 (``ProblemError``), ``error`` anything
    else raised (a bug: no answer at all).
    """
    request = PathsRequest.model_validate(
        world.to_request(objective, {"solver": solver, "time_limit_s": time_limit_s, "seed": 0})
    )
    start = time.perf_counter()
    try:
        answer = plan_paths(request, policy, GeometrySettings()).response
    except ProblemError as exc:
        return {"status": REFUSED, "message": str(exc), "e2e_s": time.perf_counter() - start}
    except Exception as exc:  # a bug in the service: reported as an error, never hidden
        return {
            "status": ERROR,
            "message": f"{type(exc).__name__}: {exc}",
            "e2e_s": time.perf_counter() - start,
        }
    e2e = time.perf_counter() - start
    return {
        "status": OK,
        "message": None,
        "e2e_s": e2e,
        "graph_s": answer.timings.graph_s,
        "solve_s": answer.timings.solve_s,
        "motion_s": answer.timings.motion_s,
        "cost": answer.cost,
        "conflicts": len(answer.assignment),
        "solver_used": answer.solver.name,
        "fallback_from": answer.solver.fallback_from,
        "optimal": answer.solver.optimal,
        "detail": answer.solver.detail,
        "collision_free": answer.checks.collision_free,
        "min_clearance_m": answer.checks.min_clearance_m,
        "replay_collision_free": replay_ok(request, answer),
        "model_cost": model_cost(request, answer),
    }


def model_cost(request: PathsRequest, answer: PathsScheduleResponse) -> float:
    """What the graph's evaluator says the answer's assignment costs, robots outside the
    graph at their planned completion: the cost the solvers optimize, which the executed
    cost exceeds where following is chosen (docs/paths.md, "Known limits"). NaN for
    avg_delay (the evaluator's delays are per time point of the graph's robots only)."""
    graph = derive(request, GeometrySettings())
    completion = np.array([p.finish_time for p in graph.paths])  # (R,)
    problem = graph.problem()
    if problem is not None:
        decided = decision(graph, answer)
        evaluation = Evaluator(problem).evaluate(
            Assignments.single(decided.a_first, decided.following)
        )
        completion[graph.robots_in_graph()] = evaluation.completion[0]
    costs = costs_from_completion(completion[None, :])
    return float(costs[request.objective][0]) if request.objective in costs else float("nan")


def replay_ok(request: PathsRequest, answer: PathsScheduleResponse) -> bool:
    """The wire trajectories, replayed through the clearance check with the robots' radii."""
    radius = {r.id: r.radius for r in request.robots}
    trajs = []
    for tr in answer.trajectories:
        points = np.asarray(tr.points, dtype=float)
        trajs.append(Trajectory(points[:, 0], points[:, 1:], radius[tr.robot]))
    return len(trajs) == len(request.robots) and check_clearance(trajs).ok


def world_key(case: WorldCase, objective: str) -> str:
    """Cache key of a world's reference: kind, size, seed and a hash of the robots."""
    digest = hashlib.sha256(json.dumps(case.world.robots, sort_keys=True).encode()).hexdigest()
    return f"{case.kind}-{case.robots}-{case.seed}-{objective}-{digest[:16]}"


def references(
    cases: Sequence[WorldCase], cfg: Config, policy: DispatchPolicy, progress: bool
) -> None:
    """Fill every case's reference run (``exact`` with the long limit), cached by world."""
    cache = reference_cache(cfg.cache, f"paths-ref-{cfg.ref_limit_s:g}s")
    for case in tqdm(cases, desc="references", unit="world", disable=not progress):
        case.ref = cache.get(
            world_key(case, cfg.objective),
            lambda c=case: {
                **solve_world(c.world, REFERENCE_SOLVER, cfg.objective, cfg.ref_limit_s, policy),
                "limit_s": cfg.ref_limit_s,
            },
        )


def finish_rows(case: WorldCase, results: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """Per-solver rows of one world, measured against the best executed cost anyone found."""
    ref = case.ref or {}
    known = {s: r["cost"] for s, r in results.items() if r["status"] == OK}
    ref_cost = ref.get("cost") if ref.get("status") == OK else None
    best = min(known.values(), default=float("inf"))
    if ref_cost is not None and ref_cost <= best * (1 + REL_TOL):
        source, best = f"{REFERENCE_SOLVER} {ref['limit_s']:g} s", ref_cost
        if ref.get("solver_used") not in (REFERENCE_SOLVER, "none"):  # none: nothing to solve
            source += f" (answered by its fallback {ref.get('solver_used')})"
    else:
        source = min(known, key=known.__getitem__) if known else None
    rows = []
    for solver, r in results.items():
        ok = r["status"] == OK
        cost = r.get("cost", float("nan"))
        rows.append(
            {
                "family": case.family,
                "kind": case.kind,
                "robots": case.robots,
                "index": case.index,
                "seed": case.seed,
                "solver": solver,
                "status": r["status"],
                "message": r["message"],
                "solver_used": r.get("solver_used"),
                "fallback_from": r.get("fallback_from"),
                "detail": r.get("detail"),
                "conflicts": r.get("conflicts"),
                "graph_s": r.get("graph_s", float("nan")),
                "solve_s": r.get("solve_s", float("nan")),
                "motion_s": r.get("motion_s", float("nan")),
                "overhead_s": r.get("graph_s", np.nan) + r.get("motion_s", np.nan),
                "render_s": r["e2e_s"] - sum(r.get(k, np.nan) for k in TIMINGS),
                "e2e_s": r["e2e_s"],
                "cost": cost,
                "free": case.free,
                "ref_cost": best if ok else float("nan"),
                "ref_source": source,
                "ratio": best / cost if ok else float("nan"),
                "model_gap": cost / r["model_cost"] if ok else float("nan"),
                "delay_ratio": delay_ratio(best, cost, case.free) if ok else float("nan"),
                "reached_ref": ok and cost <= best * (1 + REL_TOL),
                "all_exclusive": ok and ALL_EXCLUSIVE in (r.get("detail") or ""),
                "min_clearance_m": r.get("min_clearance_m"),
                "collision_free": r.get("collision_free"),
                "replay_collision_free": r.get("replay_collision_free"),
            }
        )
    return rows


def warm_up(cfg: Config, policy: DispatchPolicy) -> None:
    """Run every solver once on a small floor and warehouse: JIT compiling is not timed."""
    for kind, n in (("floor_sparse", 5), ("wh_two_way", 10)):
        world = generate(kind, n, 10_000)
        for solver in dict.fromkeys((*cfg.solvers, REFERENCE_SOLVER)):
            solve_world(world, solver, cfg.objective, 0.2, policy)


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Run every solver on every world; return everything that gets written."""
    models, errors = load_all(cfg.store, (cfg.objective,))
    if errors:
        raise SystemExit(f"models failed to load: {errors}")
    policy = DispatchPolicy(default_time_limit_s=cfg.time_limit_s, models=models)
    machine = machine_info()  # the commit the run starts from (others may commit meanwhile)
    changes = _service_changes()
    load_start = os.getloadavg()[0]  # the machine is shared: other work inflates every time
    warm_up(cfg, policy)
    settle()  # the service's collector policy once warm (service.memory)
    cases = world_cases(cfg)
    references(cases, cfg, policy, progress)
    rows: list[dict[str, Any]] = []
    for case in tqdm(cases, desc="solvers", unit="world", disable=not progress):
        results = {}
        for solver in solvers_for(cfg, case.robots):
            if case.refused is not None:  # the geometry refuses it whatever the solver
                results[solver] = {"status": REFUSED, "message": case.refused, "e2e_s": np.nan}
            else:
                results[solver] = solve_world(
                    case.world, solver, cfg.objective, cfg.time_limit_s, policy
                )
        rows += finish_rows(case, results)
    references_out = [
        {"kind": c.kind, "robots": c.robots, "seed": c.seed, **(c.ref or {})} for c in cases
    ]
    return {
        "machine": {
            **machine,
            "service_changes": changes,
            "load_avg_1min": {"start": load_start, "end": os.getloadavg()[0]},
        },
        "config": jsonable(asdict(cfg)),
        "rows": rows,
        "references": references_out,
    }


def _service_changes() -> list[str]:
    """Files under service/ that differ from the recorded commit (uncommitted work)."""
    try:
        out = subprocess.run(
            ["git", "status", "--porcelain", "--", "service"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).resolve().parents[1],
        )
    except (OSError, subprocess.CalledProcessError):
        return []
    return [line[3:] for line in out.stdout.splitlines()]


def summarize(rows: Sequence[dict[str, Any]], by: Sequence[str]) -> list[dict[str, Any]]:
    """Means of the answered runs and the refused/failed counts per group of ``by`` keys."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in by), []).append(r)
    out = []
    for key, members in groups.items():
        answered = [m for m in members if m["status"] == OK]
        clearance = _column(answered, "min_clearance_m")
        out.append(
            {
                **dict(zip(by, key, strict=True)),
                "worlds": len(members),
                "answered": len(answered),
                "refused": sum(m["status"] == REFUSED for m in members),
                "errors": sum(m["status"] == ERROR for m in members),
                "collisions": sum(not _clear(m) for m in answered),
                "conflicts_mean": nanmean(_column(answered, "conflicts")),
                "ratio_mean": nanmean(_column(answered, "ratio")),
                "delay_ratio_mean": nanmean(_column(answered, "delay_ratio")),
                "model_gap_mean": nanmean(_column(answered, "model_gap")),
                "reached_ref": nanmean(_column(answered, "reached_ref")),
                "all_exclusive": sum(m["all_exclusive"] for m in answered),
                "min_clearance_mean": nanmean(clearance),
                "min_clearance_min": _nanmax(-clearance) * -1.0,
                "graph_s_mean": nanmean(_column(answered, "graph_s")),
                "graph_s_max": _nanmax(_column(answered, "graph_s")),
                "solve_s_mean": nanmean(_column(answered, "solve_s")),
                "motion_s_mean": nanmean(_column(answered, "motion_s")),
                "overhead_s_mean": nanmean(_column(answered, "overhead_s")),
                "overhead_s_max": _nanmax(_column(answered, "overhead_s")),
                "render_s_mean": nanmean(_column(answered, "render_s")),
                "e2e_s_mean": nanmean(_column(answered, "e2e_s")),
            }
        )
    return out


def _column(rows: Sequence[dict[str, Any]], field: str) -> np.ndarray:
    """One field of every row as floats (None becomes NaN)."""
    return np.array([np.nan if r[field] is None else r[field] for r in rows], dtype=float)


def _nanmax(values: np.ndarray) -> float:
    """Largest finite value, NaN if none."""
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else float("nan")


def _clear(row: dict[str, Any]) -> bool:
    """An answered run passed both the service's clearance check and the replay."""
    return bool(row["collision_free"]) and bool(row["replay_collision_free"])


def failures(results: dict[str, Any]) -> list[dict[str, Any]]:
    """Runs that must never happen: a colliding answer, a failed replay, or an error.

    Both the solver rows and the reference runs (solver ``exact (reference)``) count.
    """
    refs = [{**r, "solver": f"{REFERENCE_SOLVER} (reference)"} for r in results["references"]]
    return [
        r
        for r in (*results["rows"], *refs)
        if r["status"] == ERROR or (r["status"] == OK and not _clear(r))
    ]


def _seconds(x: float) -> str:
    """Seconds as ms below one second."""
    if x != x:
        return "-"
    return f"{1000 * x:.0f} ms" if x < 1.0 else f"{x:.2f} s"


def solver_table(summary: Sequence[dict[str, Any]]) -> str:
    """Markdown table of the per-(family, robots, solver) summary."""
    headers = [
        "family",
        "robots",
        "solver",
        "answered",
        "refused",
        "conflicts",
        "cost ratio",
        "delay ratio",
        "executed / model",
        "reached ref",
        "all-exclusive",
        "min clearance m",
        "graph",
        "solve",
        "motion",
        "render",
        "end to end",
    ]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for s in summary:
        cells = [
            s["family"],
            s["robots"],
            s["solver"],
            s["answered"],
            s["refused"],
            fmt(s["conflicts_mean"], 0),
            fmt(s["ratio_mean"], 4),
            fmt(s["delay_ratio_mean"], 2),
            fmt(s["model_gap_mean"], 2),
            "-" if s["answered"] == 0 else f"{100 * s['reached_ref']:.0f} %",
            s["all_exclusive"],
            fmt(s["min_clearance_mean"], 3),
            _seconds(s["graph_s_mean"]),
            _seconds(s["solve_s_mean"]),
            _seconds(s["motion_s_mean"]),
            _seconds(s["render_s_mean"]),
            _seconds(s["e2e_s_mean"]),
        ]
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(lines)


def refusal_table(cases: Sequence[dict[str, Any]]) -> str:
    """Markdown table of 422 refusals per kind and size (from the reference runs)."""
    groups: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for c in cases:
        groups.setdefault((c["kind"], c["robots"]), []).append(c)
    lines = ["| kind | robots | worlds | refused (422) | first reason |", "|---|---|---|---|---|"]
    for (kind, robots), members in groups.items():
        refused = [m for m in members if m.get("status") == REFUSED]
        reason = refused[0]["message"].splitlines()[0][:120] if refused else ""
        lines.append(f"| {kind} | {robots} | {len(members)} | {len(refused)} | {reason} |")
    return "\n".join(lines)


def failure_text(bad: Sequence[dict[str, Any]]) -> str:
    """The loud part: every colliding answer, failed replay and error, or that there were none."""
    if not bad:
        return "Every answer was collision free (service check and replay of the trajectories)."
    lines = [f"**{len(bad)} FAILED RUN(S): collisions, failed replays or errors**", ""]
    for r in bad:
        what = (
            r["message"]
            if r["status"] == ERROR
            else f"collision_free={r['collision_free']} replay={r['replay_collision_free']} "
            f"min clearance {r['min_clearance_m']}"
        )
        lines.append(f"- {r['kind']} {r['robots']} robots seed {r['seed']} {r['solver']}: {what}")
    return "\n".join(lines)


def plot_paths(summary: Sequence[dict[str, Any]], path: Path) -> None:
    """Cost ratio and end-to-end time versus robots: one line per solver, one column per family."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    families = list(dict.fromkeys(s["family"] for s in summary))
    solvers = list(dict.fromkeys(s["solver"] for s in summary))
    panels = (("ratio_mean", "cost ratio (reference / cost)"), ("e2e_s_mean", "end to end (s)"))
    fig, axes = plt.subplots(2, len(families), figsize=(6.5 * len(families), 8.5), squeeze=False)
    for col, family in enumerate(families):
        sizes = sorted({s["robots"] for s in summary if s["family"] == family})
        for solver in solvers:
            sel = sorted(
                (
                    s
                    for s in summary
                    if s["family"] == family and s["solver"] == solver and s["answered"]
                ),
                key=lambda s: s["robots"],
            )
            for row, (key, label) in enumerate(panels):
                ax = axes[row, col]
                ax.plot([s["robots"] for s in sel], [s[key] for s in sel], "o-", label=solver)
                ax.set(xscale="log", xlabel="robots", ylabel=label)
                ax.set_xticks(sizes)
                ax.xaxis.set_major_formatter(ScalarFormatter())
                ax.xaxis.set_minor_formatter(NullFormatter())
                ax.set_title(f"{family} worlds")
                ax.grid(True, which="both", alpha=0.3)
        axes[1, col].set_yscale("log")
    axes[0, 0].legend(fontsize="small")
    save_figure(fig, path)


def _load(machine: dict[str, Any]) -> str:
    """The recorded load averages, start to end."""
    load = machine.get("load_avg_1min")
    return f"{load['start']:.1f} at the start, {load['end']:.1f} at the end" if load else "unknown"


def report(results: dict[str, Any], out: Path) -> str:
    """Write tables, plot and raw files under ``out``; return the tables' text."""
    out.mkdir(parents=True, exist_ok=True)
    rows = results["rows"]
    summary = summarize(rows, ("family", "robots", "solver"))
    m, c = results["machine"], results["config"]
    dirty = ""
    if m.get("service_changes") and not m.get("commit_note"):
        dirty = f" plus uncommitted changes to {len(m['service_changes'])} service/ file(s)"
    text = "\n\n".join(
        [
            f"Run {m['date']} on {m['cpu']} ({m['cpus']} CPUs), commit {m['commit']}"
            f"{dirty}; objective {c['objective']}, "
            f"time limit {c['time_limit_s']:g} s per solve, reference {REFERENCE_SOLVER} "
            f"{c['ref_limit_s']:g} s; {c['worlds']} world(s) per kind and size; from "
            f"{c['fast_only_from']} robots only {', '.join(c['fast_solvers'])}; "
            f"1-minute load average {_load(m)} (the machine is shared)."
            + (f" {m['commit_note']}" if m.get("commit_note") else ""),
            failure_text(failures(results)),
            solver_table(summary),
            "Refused with 422 (fixed paths leave no collision-free order), per kind and size:",
            refusal_table(results["references"]),
        ]
    )
    (out / "tables.md").write_text(text + "\n")
    write_json(out / "results.json", results)
    write_csv(out / "results.csv", rows)
    plot_paths(summary, out / "paths.png")
    return text


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a CI smoke run of a few seconds")
    p.add_argument("--kinds", nargs="+", choices=tuple(KINDS))
    p.add_argument("--floor-sizes", type=int, nargs="*", help="robots of floor worlds")
    p.add_argument("--warehouse-sizes", type=int, nargs="*", help="robots of warehouse worlds")
    p.add_argument("--worlds", type=int, help="worlds per kind and size")
    p.add_argument("--solvers", nargs="+", choices=SOLVERS)
    p.add_argument("--fast-solvers", nargs="+", choices=SOLVERS)
    p.add_argument("--fast-only-from", type=int, help="robots from which only fast solvers run")
    p.add_argument("--objective", choices=OBJECTIVES)
    p.add_argument("--time-limit", type=float, dest="time_limit_s", help="seconds per solve")
    p.add_argument("--ref-limit", type=float, dest="ref_limit_s", help="reference exact seconds")
    add_run_args(p)
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry: 1 when any answer collided, failed its replay or raised an error."""
    args = _parse_args(argv)
    cfg = config_from_args(args, Config(), QUICK)
    results = json.loads((cfg.out / "results.json").read_text()) if args.summarize else run(cfg)
    print(report(results, cfg.out))
    bad = failures(results)
    if bad:
        print(f"\nFAILED: {len(bad)} run(s) collided, failed the replay or raised", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
