"""Generalization of the learned model to graphs made from robot paths, by world kind (issue 13).

``python -m bench.generalization [--quick]`` derives seeded worlds of every kind of
:data:`service.scenarios.KINDS` (``--kinds``) at 25, 100 and 250 robots (``--sizes``),
``--seeds`` of each, into graph-form requests as the service derives them
(:func:`bench.cases.world_case`: the first of 30 seeds per world whose paths the
service accepts; a world none of whose seeds it accepts is listed as skipped). Seeds
start at ``--seed`` (500,000): the scenario datasets draw their world seeds from
[0, 2^31) with their kind and size, so a training world recurring here is a
one-in-millions chance. Kinds in ``--held-out`` are the held-out group, the others
the trained group (what a model trained with the same hold-out saw).

Every problem is solved through the dispatcher by:

* ``gnn_vae``: the model alone with ``--samples`` (100) samples, the issue's measure;
* ``fcfs``, the floor it must never fall below, and ``gnn_vae_refined`` for context;
* with ``--candidate`` (a model store or one model's folder), ``gnn_vae`` and
  ``gnn_vae_refined`` again with that model: the shipped model and a retrained one
  side by side on the same problems, to decide which to keep.

Each answer is timed twice: the solve alone (the answer's ``solver.runtime_s``, on
the case's problem and cliques) and a request end to end (:func:`dispatch` from the
validated request: problem, cliques, solve, check, rendering). The reference of a
problem is the exact portfolio's best: the cheaper of ``auto`` and ``tabu`` with
``--ref-budget`` seconds each (``auto`` alone is not monotone in its budget at 250
robots), or of any measured method if cheaper. References are cached under
``--cache`` by the request's hash, objective and budget: they are most of the run's
time. Under ``--out`` it writes:

* ``tables.md``: mean cost ratio (reference / cost) and delay ratio
  ((reference - free) / (cost - free), free = the cost with no delay) per group and
  size and per kind and size, methods side by side; solve and end-to-end latency
  p50 / p95; the held-out problems where the model alone is worse than FCFS; issue
  13's targets, met or missed; the skipped worlds and where references came from;
* ``generalization-cost.png`` / ``generalization-delay.png``: the mean ratios by
  size, one line per method, trained and held-out kinds side by side;
* ``results.json`` / ``results.csv``: every run, every problem's reference.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench.cases import (
    REL_TOL,
    WORLD_TRIES,
    Case,
    measured,
    request_key,
    run_cli,
    service_policy,
    solve_case,
    summarize,
    with_options,
    world_case,
)
from bench.report import (
    MODEL_STORE,
    PERCENTILES,
    JsonCache,
    add_run_args,
    fmt,
    git_commit,
    jsonable,
    machine_info,
    markdown_table,
    nanmean,
    plot_lines,
    reference_cache,
    write_results,
)
from service.core.schemas import OBJECTIVES
from service.learning.store import METADATA, ModelLoadError, StoredModel, load_model, load_model_dir
from service.memory import settle
from service.scenarios import HELD_OUT, KINDS
from service.solvers.dispatch import DispatchPolicy, dispatch

__all__ = ["QUICK", "Config", "main", "run"]

TRAINED, HELD = "trained", "held-out"
MODEL_SOLVERS = ("gnn_vae", "gnn_vae_refined")  # run once per model
CANDIDATE = "candidate"  # the label of the candidate model's methods
REFERENCE_SOLVERS = ("auto", "tabu")
# Issue 13's targets for the model alone on held-out kinds at TARGET_ROBOTS robots: mean cost
# ratio, mean delay ratio, the slowest request end to end; and never worse than FCFS.
TARGET_ROBOTS = 250
TARGET_RATIO, TARGET_DELAY, TARGET_MS = 0.98, 0.8, 100.0


@dataclass(frozen=True)
class Config:
    """What to run; the defaults are the full run documented in docs/benchmarks.md."""

    kinds: tuple[str, ...] = tuple(KINDS)
    held_out: tuple[str, ...] = HELD_OUT
    sizes: tuple[int, ...] = (25, 100, 250)
    seeds: int = 2  # worlds per kind and size
    samples: int = 100  # the model's samples per request (the service's default)
    # Per measured request: long enough that no sample is cut (the measure is the best of
    # all of them; at 250 robots under a load of 3, 5 s cut the model alone to 73 of 100).
    time_limit_s: float = 30.0
    ref_budget_s: float = 10.0  # auto and tabu each, for the reference
    objective: str = "avg_completion"
    base_seed: int = 500_000
    store: Path = MODEL_STORE
    candidate: Path | None = None  # a store (its default model) or one model's folder
    out: Path = Path("docs/results/generalization")
    cache: Path = Path("bench/cache")
    # A committed run's results.json whose references (same worlds, objective and budget)
    # seed the cache: a fresh machine measures against the yardstick of that run instead of
    # spending 20 s per problem making its own.
    references: Path | None = None


QUICK = Config(
    kinds=("wh_two_way", "wh_two_lane"),
    sizes=(10, 15),
    seeds=1,
    ref_budget_s=1.0,
    out=Path("bench/out/generalization-quick"),
)


@dataclass(frozen=True, eq=False)
class World:
    """One derived world: its kind, group (trained or held-out), size and problem."""

    kind: str
    group: str
    robots: int  # the world's robots (the graph holds those that interfere)
    case: Case

    def record(self) -> dict[str, Any]:
        """What every row of the world names: kind, group, size, seed, problem, conflicts."""
        return {
            "kind": self.kind,
            "group": self.group,
            "robots": self.robots,
            "seed": int(self.case.name.rsplit("/", 1)[1]),  # the name is kind/robots/seed
            "name": self.case.name,
            "conflicts": self.case.problem.n_conflicts,
        }


def derive_worlds(cfg: Config, progress: bool) -> tuple[list[World], list[dict[str, Any]]]:
    """Every kind, size and seed index's world, derived (or read from the cache); and the
    skipped ones with the reason."""
    jobs = [(k, n, i) for k in cfg.kinds for n in cfg.sizes for i in range(cfg.seeds)]
    worlds, skipped = [], []
    for kind, robots, index in tqdm(jobs, desc="worlds", unit="world", disable=not progress):
        first = cfg.base_seed + index * WORLD_TRIES
        reason = f"seeds {first}-{first + WORLD_TRIES - 1} refused (422, 413) or conflict-free"
        case = world_case(kind, robots, index, cfg.cache, cfg.base_seed, cfg.objective)
        if case is None:
            skipped.append({"kind": kind, "robots": robots, "index": index, "reason": reason})
        else:
            group = HELD if kind in cfg.held_out else TRAINED
            worlds.append(World(kind, group, robots, case))
    return worlds, skipped


def load_candidate(path: Path, objective: str) -> StoredModel:
    """The candidate model: ``path`` is one model's folder (it holds ``model.json``) or a
    store (its default model for ``objective``).

    Raises:
        SystemExit: the model does not load, or is for another objective.
    """
    try:
        stored = load_model_dir(path) if (path / METADATA).exists() else load_model(path, objective)
    except ModelLoadError as exc:
        raise SystemExit(f"--candidate {path}: {exc}") from exc
    if stored.objective != objective:
        raise SystemExit(f"--candidate {path}: a model for {stored.objective}, not {objective}")
    return stored


def policies(cfg: Config) -> dict[str | None, DispatchPolicy]:
    """The service's policy with the shipped models (key None) and, with a candidate, the
    same with the candidate for the objective (key CANDIDATE)."""
    shipped = service_policy(cfg.store)
    if cfg.candidate is None:
        return {None: shipped}
    candidate = load_candidate(cfg.candidate, cfg.objective)
    return {
        None: shipped,
        CANDIDATE: replace(shipped, models={**shipped.models, cfg.objective: candidate}),
    }


def methods_of(models: Sequence[str | None]) -> list[tuple[str, str, str | None]]:
    """(label, solver, model key) of every measured method, in table order."""
    out: list[tuple[str, str, str | None]] = [("fcfs", "fcfs", None)]
    for solver in MODEL_SOLVERS:
        out += [(solver if m is None else f"{solver} [{m}]", solver, m) for m in models]
    return out


def reference_runs(case: Case, cfg: Config, policy: DispatchPolicy) -> list[dict[str, Any]]:
    """``auto`` and ``tabu`` with the reference budget each: cost, proof, who answered, time,
    and the commit that ran them (the cache is keyed by request, objective and budget, not
    by code: an old commit says the reference may be stale)."""
    runs, commit = [], git_commit()
    for solver in REFERENCE_SOLVERS:
        options = {"solver": solver, "time_limit_s": cfg.ref_budget_s, "seed": 0}
        answer, seconds = solve_case(case, policy, options)
        runs.append(
            {
                "method": f"{solver} {cfg.ref_budget_s:g} s",
                "cost": answer.cost,
                "optimal": answer.solver.optimal,
                "solver_used": answer.solver.name,
                "runtime_s": seconds,
                "commit": commit,
            }
        )
    return runs


def run_method(
    label: str, solver: str, world: World, cfg: Config, policy: DispatchPolicy
) -> dict[str, Any]:
    """One method on one world: its answer's cost and who gave it, the solve's time, and a
    second request's time end to end."""
    options = {
        "solver": solver,
        "time_limit_s": cfg.time_limit_s,
        "seed": 0,
        "samples": cfg.samples,
    }
    answer, _ = solve_case(world.case, policy, options)
    request = with_options(world.case.request, options)
    start = time.perf_counter()
    dispatch(request, policy)
    e2e = time.perf_counter() - start
    return {
        "method": label,
        "solver": solver,
        **world.record(),
        "cost": answer.cost,
        "optimal": answer.solver.optimal,
        "solver_used": answer.solver.name,
        "model": answer.solver.model,
        "samples": answer.solver.samples,
        "runtime_s": answer.solver.runtime_s,
        "e2e_s": e2e,
        "free": world.case.free,
    }


def problem_record(
    world: World, refs: list[dict[str, Any]], rows: list[dict[str, Any]]
) -> dict[str, Any]:
    """What the run keeps of one problem: where it came from and its reference."""
    best = min(r["cost"] for r in (*refs, *rows))
    source = next(r["method"] for r in (*refs, *rows) if r["cost"] <= best * (1 + REL_TOL))
    return {
        **world.record(),
        "free": world.case.free,
        "ref_cost": best,
        "ref_source": source,
        "ref_proven": any(r["optimal"] and r["cost"] <= best * (1 + REL_TOL) for r in refs),
        "references": refs,
    }


def model_info(policy: DispatchPolicy, cfg: Config) -> dict[str, Any]:
    """The name of a policy's model for the objective, and the kinds its data held."""
    stored = policy.models[cfg.objective]
    kinds = {
        kind
        for dataset in stored.metadata.get("datasets", [])
        for kind in (dataset.get("config", {}).get("scenario") or {}).get("kinds", [])
    }
    return {"name": stored.name, "trained_kinds": sorted(kinds)}


def seed_references(cache: JsonCache, worlds: Sequence[World], cfg: Config) -> None:
    """Store in ``cache`` the references that ``cfg.references`` (a results.json of this
    bench) holds for ``worlds`` by name, where the cache has none and that run's objective
    and reference budget are ``cfg``'s.

    Raises:
        SystemExit: the file is not such a run, or is for another objective or budget.
    """
    try:
        earlier = json.loads(cfg.references.read_text())
        config, problems = earlier["config"], earlier["problems"]
        same = (config["objective"], config["ref_budget_s"]) == (cfg.objective, cfg.ref_budget_s)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise SystemExit(f"--references {cfg.references}: not a results.json ({exc})") from exc
    if not same:
        raise SystemExit(
            f"--references {cfg.references}: {config['objective']} at {config['ref_budget_s']:g} s,"
            f" not {cfg.objective} at {cfg.ref_budget_s:g} s"
        )
    by_name = {p["name"]: p["references"] for p in problems}
    cache.seed(
        {
            request_key(w.case, cfg.objective, cfg.ref_budget_s): by_name[w.case.name]
            for w in worlds
            if w.case.name in by_name
        }
    )


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Derive the worlds, solve the references (cached) and every method; return everything
    that gets written."""
    machine = {**machine_info(), "load_avg_1min_start": os.getloadavg()[0]}
    worlds, skipped = derive_worlds(cfg, progress)
    if not worlds:
        raise SystemExit(f"no world could be derived: {skipped}")
    by_model = policies(cfg)
    methods = methods_of(list(by_model))
    cache = reference_cache(cfg.cache, "generalization-ref")
    if cfg.references is not None:
        seed_references(cache, worlds, cfg)
    refs = [
        cache.get(
            request_key(w.case, cfg.objective, cfg.ref_budget_s),
            lambda w=w: reference_runs(w.case, cfg, by_model[None]),
        )
        for w in tqdm(worlds, desc="references", unit="problem", disable=not progress)
    ]
    smallest = min(worlds, key=lambda w: w.case.problem.n_conflicts)
    for label, solver, model in methods:  # compiling and first calls are not timed
        run_method(label, solver, smallest, cfg, by_model[model])
    settle()  # the service's collector policy once warm: the cases held escape full collections
    rows, problems = [], []
    for world, ref in tqdm(
        list(zip(worlds, refs, strict=True)), desc="methods", unit="problem", disable=not progress
    ):
        found = [run_method(lb, solver, world, cfg, by_model[m]) for lb, solver, m in methods]
        rows += measured(world.case, [*ref, *found])[len(ref) :]
        problems.append(problem_record(world, ref, found))
    machine["load_avg_1min_end"] = os.getloadavg()[0]
    return {
        "machine": machine,
        "config": jsonable(asdict(cfg)),
        "models": {m or "shipped": model_info(p, cfg) for m, p in by_model.items()},
        "methods": [label for label, _, _ in methods],
        "problems": problems,
        "skipped": skipped,
        "rows": rows,
    }


def latency(members: list[dict[str, Any]]) -> dict[str, Any]:
    """Solve and end-to-end milliseconds at PERCENTILES, the slowest request, the fewest
    samples decoded (below the asked count: a time limit cut the sampling)."""
    solve = np.percentile([1e3 * m["runtime_s"] for m in members], PERCENTILES)
    e2e = np.percentile([1e3 * m["e2e_s"] for m in members], PERCENTILES)
    samples = [m["samples"] for m in members if m["samples"] is not None]
    return {
        **{f"solve_p{p}_ms": float(v) for p, v in zip(PERCENTILES, solve, strict=True)},
        **{f"e2e_p{p}_ms": float(v) for p, v in zip(PERCENTILES, e2e, strict=True)},
        "e2e_max_ms": 1e3 * max(m["e2e_s"] for m in members),
        "samples_min": min(samples, default=None),
    }


def ordered(rows: Sequence[dict[str, Any]], by: Sequence[str]) -> list[dict[str, Any]]:
    """``rows`` sorted by ``by``, the group trained before held-out (stable otherwise)."""
    rank = {TRAINED: 0, HELD: 1}
    return sorted(rows, key=lambda r: tuple(rank.get(r[k], r[k]) for k in by))


def side_by_side(summary: Sequence[dict[str, Any]], keys: Sequence[str], methods: list[str]) -> str:
    """Markdown: a row per value of ``keys``, a ``cost ratio / delay ratio`` cell per method."""
    by = {(tuple(s[k] for k in keys), s["method"]): s for s in summary}
    table = []
    for key in dict.fromkeys(tuple(s[k] for k in keys) for s in summary):
        cells = [
            "-"
            if (s := by.get((key, m))) is None
            else f"{fmt(s['ratio_mean'], 4)} / {fmt(s['delay_ratio_mean'])}"
            for m in methods
        ]
        table.append([*key, by[(key, methods[0])]["problems"], *cells])
    return markdown_table([*keys, "n", *(f"`{m}`" for m in methods)], table)


def latency_table(summary: Sequence[dict[str, Any]]) -> str:
    """Markdown: solve and end-to-end p50 / p95 and the slowest request per group, size and
    method."""
    return markdown_table(
        ["group", "robots", "method", "n", "solve p50 / p95 ms", "request p50 / p95 ms",
         "slowest request ms", "fewest samples"],
        [
            [s["group"], s["robots"], f"`{s['method']}`", s["problems"],
             f"{s['solve_p50_ms']:.1f} / {s['solve_p95_ms']:.1f}",
             f"{s['e2e_p50_ms']:.1f} / {s['e2e_p95_ms']:.1f}", f"{s['e2e_max_ms']:.1f}",
             "-" if s["samples_min"] is None else s["samples_min"]]
            for s in summary
        ],
    )  # fmt: skip


def worse_than_fcfs(rows: Sequence[dict[str, Any]], method: str) -> list[dict[str, Any]]:
    """The held-out problems where ``method``'s cost exceeds FCFS's."""
    fcfs = {r["name"]: r["cost"] for r in rows if r["method"] == "fcfs"}
    return [
        r
        for r in rows
        if r["method"] == method
        and r["group"] == HELD
        and r["cost"] > fcfs[r["name"]] * (1 + REL_TOL)
    ]


def fallback_text(rows: Sequence[dict[str, Any]]) -> str:
    """The runs another solver answered (the dispatcher's fallback when a method has no
    answer in time): they measure the fallback, not the method."""
    fell = [r for r in rows if r["solver_used"] != r["solver"]]
    if not fell:
        return "Every method answered every problem itself (no fallback)."
    runs = ", ".join(f"`{r['method']}` on {r['name']} ({r['solver_used']})" for r in fell)
    return f"Answered by a fallback, not the method: {runs}."


def fcfs_text(rows: Sequence[dict[str, Any]], methods: Sequence[str]) -> str:
    """Per model-alone method, how many held-out problems it answers worse than FCFS, which."""
    lines = []
    held = len({r["name"] for r in rows if r["group"] == HELD})
    for method in methods:
        worse = worse_than_fcfs(rows, method)
        names = ", ".join(f"{r['name']} ({r['ratio']:.4f})" for r in worse)
        lines.append(f"- `{method}`: {len(worse)} of {held}" + (f": {names}" if worse else ""))
    return "\n".join(lines)


def target_table(rows: Sequence[dict[str, Any]], methods: Sequence[str]) -> str:
    """Markdown: every model-alone method against issue 13's targets on the held-out worlds of
    TARGET_ROBOTS robots (of the largest size run, if smaller, and said so)."""
    held = [r for r in rows if r["group"] == HELD]
    if not held:
        return "(no held-out world in this run)"
    size = max(r["robots"] for r in held)
    table = []
    for method in methods:
        sel = [r for r in held if r["method"] == method and r["robots"] == size]
        ratio = float(np.mean([r["ratio"] for r in sel]))
        delay = nanmean([r["delay_ratio"] for r in sel])
        slowest = 1e3 * max(r["e2e_s"] for r in sel)
        worse = len(worse_than_fcfs(rows, method))
        missed = [
            name
            for name, ok in (
                ("cost ratio", ratio >= TARGET_RATIO),
                ("delay ratio", delay >= TARGET_DELAY),
                ("time", slowest <= TARGET_MS),
                ("FCFS", worse == 0),
            )
            if not ok
        ]
        table.append(
            [f"`{method}`", len(sel), f"{ratio:.4f} (>= {TARGET_RATIO})",
             f"{fmt(delay)} (>= {TARGET_DELAY})", f"{slowest:.0f} (<= {TARGET_MS:.0f})",
             f"{worse} (0)", "met" if not missed else "missed: " + ", ".join(missed)]
        )  # fmt: skip
    note = "" if size == TARGET_ROBOTS else f"\n\nAt {size} robots: the targets are at 250."
    return (
        markdown_table(
            [
                "model alone",
                f"n ({size} robots)",
                "cost ratio",
                "delay ratio",
                "slowest request ms",
                "held-out problems worse than FCFS",
                "verdict",
            ],
            table,
        )  # fmt: skip
        + note
    )


def reference_text(problems: Sequence[dict[str, Any]]) -> str:
    """Where the references came from, and how many were proven optimal."""
    sources: dict[str, int] = {}
    for p in problems:
        sources[p["ref_source"]] = sources.get(p["ref_source"], 0) + 1
    counts = ", ".join(f"`{source}` on {n}" for source, n in sources.items())
    proven = sum(p["ref_proven"] for p in problems)
    commits: dict[str, int] = {}
    for p in problems:
        for run in p["references"]:
            commit = run.get("commit") or "unrecorded (cached before session 45)"
            commits[commit] = commits.get(commit, 0) + 1
    computed = ", ".join(f"{commit} ({n})" for commit, n in commits.items())
    return (
        f"References (the first run to reach each problem's best): {counts}; "
        f"proven optimal: {proven} of {len(problems)}. Reference runs computed at commit: "
        f"{computed}."
    )


def skipped_table(skipped: Sequence[dict[str, Any]]) -> str:
    """Markdown: the worlds that could not be derived ("(none)" if every one was)."""
    if not skipped:
        return "(none)"
    return markdown_table(
        ["kind", "robots", "world", "reason"],
        [[s["kind"], s["robots"], s["index"], s["reason"]] for s in skipped],
    )


def model_text(results: dict[str, Any]) -> str:
    """The models compared, the kinds their data held, and where that disagrees with the split:
    a held-out kind trained on (a warning), a trained-group kind the model never saw."""
    held = set(results["config"]["held_out"])
    kinds = {r["kind"] for r in results["rows"]}
    lines = []
    for label, info in results["models"].items():
        seen = set(info["trained_kinds"])
        text = (
            f"- {label}: `{info['name']}` (data: {', '.join(sorted(seen)) or 'no scenario kinds'})"
        )
        if leak := sorted(held & seen):
            text += f". **Trained on held-out kinds {leak}: the split does not hold.**"
        if seen and (unseen := sorted(kinds - held - seen)):
            text += f"; in the trained group but not in its data: {', '.join(unseen)}"
        lines.append(text + ".")
    return "\n".join(lines)


def report(results: dict[str, Any], out: Path) -> str:
    """Write tables, plots and raw files under ``out``; return the tables' text."""
    out.mkdir(parents=True, exist_ok=True)
    rows, m, cfg = results["rows"], results["machine"], results["config"]
    methods = results["methods"]
    alone = [label for label in methods if label.startswith("gnn_vae") and "refined" not in label]
    by_group = summarize(ordered(rows, ("group", "robots")), ("group", "robots", "method"), latency)
    by_kind = summarize(
        ordered(rows, ("group", "kind", "robots")), ("kind", "group", "robots", "method")
    )
    text = "\n\n".join(
        [
            f"Run {m['date']} on {m['cpu']} ({m['cpus']} CPUs), commit {m['commit']}; "
            f"objective {cfg['objective']}; {len(results['problems'])} problems "
            f"({len(results['skipped'])} worlds skipped), seeds from {cfg['base_seed']}; "
            f"held out: {', '.join(cfg['held_out'])}; the model alone with "
            f"{cfg['samples']} samples, time limit {cfg['time_limit_s']:g} s per request "
            "(`gnn_vae_refined` takes at most 1 s); "
            f"reference: the best of `auto` and `tabu` with {cfg['ref_budget_s']:g} s each "
            "and of every method below. 1-minute load average "
            f"{m['load_avg_1min_start']:.1f} at the start, {m['load_avg_1min_end']:.1f} at the "
            "end (the machine is shared: latency rises with the load).",
            "Models:\n\n" + model_text(results),
            "Cells: mean cost ratio / mean delay ratio. By group:",
            side_by_side(by_group, ("group", "robots"), methods),
            "By kind:",
            side_by_side(by_kind, ("kind", "group", "robots"), methods),
            "Latency (solve: the solver and its check on a prepared problem; request: "
            "`dispatch` end to end):",
            latency_table(by_group),
            "Held-out problems where the model alone is worse than FCFS (its cost ratio):",
            fcfs_text(rows, alone),
            "Issue 13's targets (held-out kinds, the model alone):",
            target_table(rows, alone),
            reference_text(results["problems"]),
            fallback_text(rows),
            "Skipped worlds:",
            skipped_table(results["skipped"]),
        ]
    )
    write_results(out, text, results, rows)
    plot_opts = {"x": "robots", "xlabel": "robots", "panel": "group"}
    plot_lines(
        by_group, "ratio_mean", "mean cost ratio", out / "generalization-cost.png", **plot_opts
    )
    plot_lines(
        by_group,
        "delay_ratio_mean",
        "mean delay ratio",
        out / "generalization-delay.png",
        **plot_opts,
    )
    return text


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a CI smoke run of under a minute")
    p.add_argument("--kinds", nargs="+", choices=tuple(KINDS))
    p.add_argument("--held-out", nargs="+", choices=tuple(KINDS))
    p.add_argument("--sizes", type=int, nargs="+", help="robots per world")
    p.add_argument("--seeds", type=int, help="worlds per kind and size")
    p.add_argument("--samples", type=int, help="the model's samples per request")
    p.add_argument("--time-limit", type=float, dest="time_limit_s", help="seconds per request")
    p.add_argument("--ref-budget", type=float, dest="ref_budget_s", help="reference seconds")
    p.add_argument("--objective", choices=OBJECTIVES)
    p.add_argument("--candidate", type=Path, help="a model store or one model's folder")
    p.add_argument("--references", type=Path, help="a results.json whose references seed the cache")
    add_run_args(p)
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry."""
    return run_cli(_parse_args(argv), Config(), QUICK, run, report)


if __name__ == "__main__":
    raise SystemExit(main())
