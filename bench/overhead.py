"""What the paths form adds to a solve (issue 10, section 3): geometry, motion, wire.

``python -m bench.overhead [--quick]`` generates warehouse worlds (one per kind,
size and seed), resamples every path to about ``--points`` points (the issue's
"100-point paths"; corners kept), and plans each through
:func:`~service.motion.plan.plan_paths` ``--repeats`` times, after a warm-up and
the service's garbage-collection policy (:func:`service.memory.settle`). Per run
it records the answer's own timings: ``graph_s`` (paths to the graph request),
``solve_s`` (the dispatcher) and ``motion_s`` (dependency plan, execution,
clearance check, the answer built); the **overhead** is ``graph_s + motion_s``
(the issue's target: at most 0.5 s at 250 robots; paths to graph alone "well under
a second"). Around it, the wire: parsing the JSON body into a request and
serializing the answer, timed too but not part of the overhead.

It also says whether the service's default work bounds would refuse the world
(413, ``SCHEDULER_MAX_CLIQUES`` / ``SCHEDULER_MAX_CLIQUE_INCIDENCES``): such worlds
are planned without the bounds so that their timings are still measured. Under
``--out``: ``tables.md``, ``results.json`` / ``results.csv`` and ``overhead.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.cases import run_cli
from bench.report import (
    jsonable,
    machine_info,
    markdown_table,
    plot_lines,
    write_results,
)
from service.core.cliques import CliqueBound, TooManyCliques, clique_budget
from service.core.path_schemas import PathsRequest, PathsScheduleResponse
from service.geometry.graph import GeometrySettings
from service.memory import settle
from service.motion.plan import plan_paths
from service.scenarios import generate
from service.settings import Settings
from service.solvers.dispatch import DispatchPolicy

__all__ = ["QUICK", "Config", "main", "resampled", "run"]

TARGET_S = 0.5  # the bound on graph + motion at 250 robots


@dataclass(frozen=True)
class Config:
    """What to run; the defaults are the run documented in docs/benchmarks.md."""

    kinds: tuple[str, ...] = ("wh_one_way", "wh_two_way", "wh_two_lane", "wh_mixed")
    sizes: tuple[int, ...] = (25, 100, 250)
    worlds: int = 2  # seeds per kind and size
    points: int = 100  # points per path after resampling (corners kept on top)
    repeats: int = 3  # plans per world (the table shows medians over them)
    solver: str = "fcfs"  # the solve is not part of the overhead: the fastest one
    time_limit_s: float = 5.0
    objective: str = "avg_completion"
    base_seed: int = 0
    out: Path = Path("docs/results/overhead")


QUICK = Config(
    kinds=("wh_two_way",),
    sizes=(10,),
    worlds=1,
    points=30,
    repeats=2,
    out=Path("bench/out/overhead-quick"),
)


def resampled(body: dict[str, Any], points: int) -> dict[str, Any]:
    """``body`` with every path resampled to ``points`` evenly spaced points plus its
    corners (same route, same timing: ``times`` interpolated where given)."""
    robots = []
    for robot in body["robots"]:
        xy = np.asarray(robot["path"], dtype=np.float64)  # (N, 2)
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
        s = np.unique(np.concatenate([np.linspace(0.0, arc[-1], points), arc]))  # (N',)
        path = np.column_stack([np.interp(s, arc, xy[:, k]) for k in (0, 1)])  # (N', 2)
        new = dict(robot, path=path.tolist())
        if robot.get("times") is not None:
            new["times"] = np.interp(s, arc, np.asarray(robot["times"])).tolist()
        robots.append(new)
    return dict(body, robots=robots)


def plan_once(
    wire: str, policy: DispatchPolicy, geometry: GeometrySettings, cap: CliqueBound
) -> tuple[PathsScheduleResponse, float, float]:
    """Parse ``wire`` and plan it under the clique bound ``cap``; the answer, the seconds
    spent parsing, and the seconds spent serializing the answer.

    Raises:
        TooManyCliques: the bound is exceeded (the service would answer 413).
    """
    start = time.perf_counter()
    request = PathsRequest.model_validate_json(wire)
    parse_s = time.perf_counter() - start
    with clique_budget(cap):
        answer = plan_paths(request, policy, geometry)
    return answer.response, parse_s, answer.encode_s


def measure_world(
    kind: str, robots: int, seed: int, cfg: Config, policy: DispatchPolicy
) -> dict[str, Any]:
    """One world planned ``cfg.repeats`` times: medians and maxima of every timing."""
    body = resampled(
        generate(kind, robots, seed).to_request(
            cfg.objective,
            {"solver": cfg.solver, "time_limit_s": cfg.time_limit_s, "seed": 0},
        ),
        cfg.points,
    )
    wire = json.dumps(body)
    settings = Settings()
    geometry = GeometrySettings()
    cap = CliqueBound(settings.max_cliques, settings.max_clique_incidences)
    try:
        plan_once(wire, policy, geometry, cap)
        refused = False
    except TooManyCliques:
        refused, cap = True, CliqueBound()
    runs = [plan_once(wire, policy, geometry, cap) for _ in range(cfg.repeats)]
    timings = {
        "graph_s": [a.timings.graph_s for a, _, _ in runs],
        "solve_s": [a.timings.solve_s for a, _, _ in runs],
        "motion_s": [a.timings.motion_s for a, _, _ in runs],
        "overhead_s": [a.timings.graph_s + a.timings.motion_s for a, _, _ in runs],
        "parse_s": [p for _, p, _ in runs],
        "dump_s": [d for _, _, d in runs],
    }
    answer = runs[-1][0]
    row: dict[str, Any] = {
        "kind": kind,
        "robots": robots,
        "seed": seed,
        "points": int(np.mean([len(r["path"]) for r in body["robots"]])),
        "conflicts": len(answer.assignment),
        "waypoints": sum(len(t.points) for t in answer.trajectories),
        "collision_free": answer.checks.collision_free,
        "refused_by_default_bounds": refused,
    }
    for key, values in timings.items():
        row[key] = float(np.median(values))
        row[key.replace("_s", "_max_s")] = float(np.max(values))
    return row


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Measure every world; return everything that gets written."""
    policy = DispatchPolicy()
    warm = resampled(generate("wh_two_way", 10, 10_000).to_request(cfg.objective), cfg.points)
    plan_once(json.dumps(warm), policy, GeometrySettings(), CliqueBound())  # not timed: compiling
    settle()  # as the service does once it has warmed up
    cases = [
        (kind, n, cfg.base_seed + i)
        for kind in cfg.kinds
        for n in cfg.sizes
        for i in range(cfg.worlds)
    ]
    rows = [
        measure_world(kind, n, seed, cfg, policy)
        for kind, n, seed in tqdm(cases, desc="worlds", disable=not progress)
    ]
    return {
        "config": jsonable(asdict(cfg)),
        "machine": machine_info(),
        "load_after": os.getloadavg(),
        "rows": rows,
    }


def summarize(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per kind and size: medians over its worlds, and the worst world."""
    out = []
    for kind in dict.fromkeys(r["kind"] for r in rows):
        for n in sorted({r["robots"] for r in rows if r["kind"] == kind}):
            sel = [r for r in rows if r["kind"] == kind and r["robots"] == n]
            summary: dict[str, Any] = {"kind": kind, "robots": n, "problems": len(sel)}
            for key in ("conflicts", "points", "waypoints"):
                summary[key] = int(np.median([r[key] for r in sel]))
            for key in ("graph_s", "motion_s", "overhead_s", "solve_s", "parse_s", "dump_s"):
                summary[key] = float(np.median([r[key] for r in sel]))
                summary[key.replace("_s", "_max_s")] = max(
                    r[key.replace("_s", "_max_s")] for r in sel
                )
            summary["refused"] = sum(r["refused_by_default_bounds"] for r in sel)
            summary["collision_free"] = all(r["collision_free"] for r in sel)
            out.append(summary)
    return out


def _ms(summary: dict[str, Any], key: str) -> str:
    """``median (max)`` of a timing in milliseconds."""
    return f"{1000 * summary[key]:.0f} ({1000 * summary[key.replace('_s', '_max_s')]:.0f})"


def report(results: dict[str, Any], out: Path) -> str:
    """Write the tables, raw rows and plot under ``out``; return the tables' text."""
    out.mkdir(parents=True, exist_ok=True)
    summary = summarize(results["rows"])
    cfg, machine = results["config"], results["machine"]
    headers = [
        "kind", "robots", "conflicts", "graph ms", "motion ms", "overhead ms",
        "solve ms", "parse ms", "dump ms", "413 by default", "collision free",
    ]  # fmt: skip
    table = markdown_table(
        headers,
        (
            [
                s["kind"],
                s["robots"],
                s["conflicts"],
                _ms(s, "graph_s"),
                _ms(s, "motion_s"),
                _ms(s, "overhead_s"),
                _ms(s, "solve_s"),
                _ms(s, "parse_s"),
                _ms(s, "dump_s"),
                f"{s['refused']}/{s['problems']}",
                "yes" if s["collision_free"] else "NO",
            ]  # fmt: skip
            for s in summary
        ),
    )
    text = "\n".join(
        [
            f"Run {machine['date']} on {machine['cpu']} ({machine['cpus']} CPUs), commit "
            f"{machine['commit']}, load average after {results['load_after'][0]:.1f}; "
            f"{cfg['worlds']} world(s) per cell, "
            f"paths resampled to ~{cfg['points']} points, {cfg['repeats']} plans each, "
            f"solver {cfg['solver']}. Median over worlds of each world's median (max: worst "
            f"plan). Overhead = graph + motion (target <= {1000 * TARGET_S:.0f} ms at 250 "
            "robots); parse / dump: the JSON body in, the answer out.",
            "",
            table,
        ]
    )
    write_results(out, text, results, results["rows"])
    plot_lines(
        [dict(s, method=s["kind"], family="overhead (graph + motion)") for s in summary],
        "overhead_s",
        "seconds (median)",
        out / "overhead.png",
        x="robots",
        xlabel="robots",
    )
    return text


def failed(results: dict[str, Any]) -> str | None:
    """A colliding answer fails the run (it never should)."""
    bad = [r for r in results["rows"] if not r["collision_free"]]
    return f"{len(bad)} colliding answer(s)" if bad else None


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="a CI smoke run of a few seconds")
    p.add_argument("--kinds", nargs="+")
    p.add_argument("--sizes", type=int, nargs="+")
    p.add_argument("--worlds", type=int)
    p.add_argument("--points", type=int)
    p.add_argument("--repeats", type=int)
    p.add_argument("--solver")
    p.add_argument("--seed", type=int, dest="base_seed")
    p.add_argument("--out", type=Path)
    p.add_argument("--summarize", action="store_true", help="re-render from --out/results.json")
    return run_cli(p.parse_args(argv), Config(), QUICK, run, report, failed)


if __name__ == "__main__":
    raise SystemExit(main())
