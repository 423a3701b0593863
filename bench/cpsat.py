"""CP-SAT configurations side by side, measured rather than assumed (issue 11, item 3).

``python -m bench.cpsat [--quick]`` solves the conformance sets of issue 11's
targets (warehouses of 25, 50 and 100 robots, dense geometric floors of 25;
optima proven by an independent MILP) with named configurations of the
service's CP-SAT model (:data:`VARIANTS`): worker count, ``interleave_search``
(CP-SAT's deterministic portfolio), linearization level, LNS-only workers,
the hint (FCFS, the portfolio's first stage, none), an objective cutoff from
the incumbent, and a budget in deterministic time instead of wall time. Every
configuration runs on every problem at every budget (the budget counts from
the call: hint, model building and search); a run that proved optimality is
not repeated at larger budgets (its answer would be the same). At the first
budget each configuration runs twice with the same seed, and the table says
how often the two assignments were identical. Under ``--out`` it writes:

* ``tables.md``: per configuration and budget the mean cost ratio (optimum /
  cost), mean delay ratio ((opt - free) / (cost - free), free = the cost with
  no delay), the share proven optimal, and the identical-repeat share; the
  same per set; CP-SAT's deterministic time per wall second;
* ``cpsat.png``: delay ratio and share proven per configuration and budget;
* ``results.json`` / ``results.csv``: every run.
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from ortools.sat.python import cp_model
from tqdm import tqdm

from bench.cases import (
    LARGE_SETS,
    Case,
    add_case_args,
    cell,
    conformance_cases,
    measured,
    run_cli,
    service_policy,
    world_cases,
)
from bench.cases import summarize as summarize_rows
from bench.report import (
    add_run_args,
    fmt,
    jsonable,
    machine_info,
    nanmean,
    save_figure,
    write_csv,
    write_json,
)
from service.core.assignment import Assignments
from service.core.schemas import OBJECTIVES
from service.learning.store import StoredModel
from service.memory import settle
from service.solvers.dispatch import DispatchPolicy  # (importing it registers every solver)
from service.solvers.exact import DTIME_PER_S, MIN_SEARCH_S, ExactModel, build_model, search
from service.solvers.fcfs import fcfs
from service.solvers.portfolio import FIRST_STAGE_SHARE
from service.solvers.registry import SolveContext, get_solver

__all__ = ["QUICK", "VARIANTS", "Config", "Variant", "bound_by", "main", "run", "summarize"]

MODEL_STORE = Path(__file__).resolve().parents[1] / "model_store"
FCFS, STAGE, NO_HINT = "fcfs", "stage", "none"  # where a configuration's hint comes from
STAGE_SOLVER = DispatchPolicy().large_solver  # the portfolio's first stage


@dataclass(frozen=True)
class Variant:
    """A named CP-SAT configuration over the service's model, every parameter explicit (so
    that a change of the service's defaults does not change what a name measures).

    Example::

        Variant("2 workers, interleaved", workers=2, tuning=(("interleave_search", True),))
    """

    label: str
    workers: int = 1
    linearization: int = 1  # CP-SAT's default; the service's before issue 11
    probing: int = 2  # cp_model_probing_level: CP-SAT's default; the service's before 2026-11-24
    tuning: tuple[tuple[str, bool | int | float], ...] = ()  # further SatParameters fields
    hint: str = FCFS
    cutoff: bool = False  # bound the objective by the hint's cost (bound_by)
    # The search limited in deterministic time too: Config.dtime_per_s per budget second.
    deterministic: bool = False


_INTERLEAVE = (("interleave_search", True),)
# CP-SAT's root-level transitive closure of precedences (linear2 bounds), redone at
# every new root bound: most of a sub-problem's search time in a profile (session 19).
_NO_TRANSITIVE = (("transitive_precedences_work_limit", 0),)
VARIANTS: dict[str, Variant] = {
    "default": Variant("1 worker, linearization 1, FCFS hint: the service's exact before"),
    "no_hint": Variant("no hint", hint=NO_HINT),
    "lin0": Variant("linearization 0 (the service's exact until 2026-11-24)", linearization=0),
    "lin0_probe0": Variant(
        "linearization 0, no probing in presolve (the service's exact now)",
        linearization=0,
        probing=0,
    ),
    "lin0_probe0_core": Variant(
        "linearization 0, no probing, core-based search (the service's last 30 % for "
        "avg_completion)",
        linearization=0,
        probing=0,
        tuning=(("optimize_with_core", True),),
    ),
    "lin2": Variant("linearization 2", linearization=2),
    "cutoff": Variant("objective <= the hint's cost", cutoff=True),
    "lin0_cutoff": Variant(
        "linearization 0, objective <= the hint's cost", linearization=0, cutoff=True
    ),
    "stage_hint": Variant(
        f"hint from {STAGE_SOLVER} with 30 % of the budget (auto before)", hint=STAGE
    ),
    "stage_cutoff": Variant("stage hint, objective <= its cost", hint=STAGE, cutoff=True),
    "stage_lin0": Variant(
        "stage hint, linearization 0 (auto's CP-SAT stage until 2026-11-24)",
        linearization=0,
        hint=STAGE,
    ),
    "stage_lin0_cutoff": Variant(
        "stage hint, linearization 0, objective <= its cost",
        linearization=0,
        hint=STAGE,
        cutoff=True,
    ),
    "stage_lin0_probe0": Variant(
        "stage hint, linearization 0, no probing in presolve (auto's CP-SAT stage now)",
        linearization=0,
        probing=0,
        hint=STAGE,
    ),
    "stage_lin0_probe1": Variant(
        "stage hint, linearization 0, light probing in presolve",
        linearization=0,
        probing=1,
        hint=STAGE,
    ),
    "lin0_probe0_trans0": Variant(
        "linearization 0, no probing, no transitive precedences",
        linearization=0,
        probing=0,
        tuning=_NO_TRANSITIVE,
    ),
    "stage_lin0_probe0_trans0": Variant(
        "stage hint, linearization 0, no probing, no transitive precedences",
        linearization=0,
        probing=0,
        hint=STAGE,
        tuning=_NO_TRANSITIVE,
    ),
    "w2": Variant("2 workers", workers=2),
    "w2_lns": Variant("2 workers, LNS only", workers=2, tuning=(("use_lns_only", True),)),
    "w1_interleave": Variant("1 worker, interleave_search", tuning=_INTERLEAVE),
    "w2_interleave": Variant("2 workers, interleave_search", workers=2, tuning=_INTERLEAVE),
    "w1_dtime": Variant(
        "1 worker, linearization 0, deterministic-time budget",
        linearization=0,
        deterministic=True,
    ),
    "w2_interleave_dtime": Variant(
        "2 workers, interleave_search, linearization 0, deterministic-time budget",
        workers=2,
        linearization=0,
        tuning=_INTERLEAVE,
        deterministic=True,
    ),
}


@dataclass(frozen=True)
class Config:
    """What to run; the defaults are the full run documented in docs/benchmarks.md."""

    # w1_interleave is left out for time: in a pilot (8 problems, 1 s) it reached 0.956 /
    # 0.79 against default's 0.986 / 0.89.
    variants: tuple[str, ...] = tuple(v for v in VARIANTS if v != "w1_interleave")
    sets: tuple[str, ...] = LARGE_SETS
    per_set: int | None = None  # problems per set (None: all)
    objective: str | None = None  # replaces the sets' own (then: against the best found)
    # Generated worlds as "kind:robots" (bench.cases.world_case), against the best found.
    worlds: tuple[str, ...] = ()
    per_world: int = 1
    budgets: tuple[float, ...] = (1.0, 3.0)  # seconds; the first is also run twice
    dtime_per_s: float = DTIME_PER_S  # deterministic time per budget second (the service's)
    base_seed: int = 0
    store: Path = MODEL_STORE
    out: Path = Path("docs/results/cpsat")
    cache: Path = Path("bench/cache")


QUICK = Config(
    variants=("default", "stage_cutoff", "w2_interleave_dtime"),
    sets=("wh_25",),
    per_set=2,
    budgets=(0.3, 0.6),
    out=Path("bench/out/cpsat-quick"),
)


def bound_by(em: ExactModel, incumbent: Assignments, time_limit_s: float) -> bool:
    """Require the model's objective to be at most ``incumbent``'s (a cutoff); True if added.

    The incumbent's integer objective is that of its least delays under its own literals:
    a solve of a copy of the model with every literal fixed (no presolve, one worker):
    0.02-0.07 s at 138-262 conflicts, 0.2 s at 901, 0.6 s at 3,898, 11 s at 21,835. Not
    added when that solve does not finish within ``time_limit_s``.
    """
    fixed = em.model.clone()
    values = [*incumbent.a_first[0].tolist(), *incumbent.following[0].tolist()]
    for lit, val in zip([*em.a_first.tolist(), *em.following.tolist()], values, strict=True):
        fixed.add(fixed.get_bool_var_from_proto_index(lit) == int(val))
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = max(time_limit_s, MIN_SEARCH_S)
    solver.parameters.cp_model_presolve = False
    solver.parameters.linearization_level = 0
    if solver.solve(fixed) != cp_model.OPTIMAL:
        return False
    objective = em.model.proto.objective
    terms = [em.model.get_int_var_from_proto_index(v) for v in objective.vars]
    total = cp_model.LinearExpr.weighted_sum(terms, list(objective.coeffs))
    em.model.add(total <= round(solver.objective_value - objective.offset))
    return True


def _context(case: Case, time_limit_s: float, seed: int, models: Mapping[str, Any]) -> SolveContext:
    """A solve context of ``case`` sharing its prebuilt cliques."""
    ctx = SolveContext(case.problem, case.objective, time_limit_s, seed=seed, models=models)
    ctx.__dict__["cliques"] = case.cliques  # the cached property, filled in advance
    return ctx


def _hint(source: str, ctx: SolveContext) -> Assignments | None:
    """The configuration's hint: FCFS, the first stage's answer (FIRST_STAGE_SHARE of the
    budget, as ``auto`` runs it; FCFS if it found nothing), or None."""
    if source == NO_HINT:
        return None
    found = None
    if source == STAGE:
        stage = copy.copy(ctx)  # shares the cached cliques, evaluator and decoder
        stage.time_limit_s = FIRST_STAGE_SHARE * ctx.time_limit_s
        found = get_solver(STAGE_SOLVER)(stage)
    return (found or fcfs(ctx)).assignment


def fingerprint(assignment: Assignments) -> str:
    """A short digest of the directions and types, to compare two runs' answers."""
    data = assignment.a_first[0].tobytes() + assignment.following[0].tobytes()
    return hashlib.sha256(data).hexdigest()[:16]


def run_once(
    name: str, case: Case, budget_s: float, cfg: Config, models: Mapping[str, StoredModel]
) -> dict[str, Any]:
    """One configuration on one problem within ``budget_s`` (hint, model and search)."""
    variant = VARIANTS[name]
    start, deadline = time.perf_counter(), time.monotonic() + budget_s
    ctx = _context(case, budget_s, cfg.base_seed, models)
    hint = _hint(variant.hint, ctx)
    hint_s = time.perf_counter() - start
    em = build_model(case.problem, case.cliques, case.objective)
    bounded = False
    if hint is not None:
        em.add_hint(hint)
        if variant.cutoff:
            bounded = bound_by(em, hint, deadline - time.monotonic())
    left = max(MIN_SEARCH_S, deadline - time.monotonic())
    tuning = {
        "linearization_level": variant.linearization,
        "cp_model_probing_level": variant.probing,
        **dict(variant.tuning),
    }
    if variant.deterministic:  # from the budget alone: a limit from what is left varies
        tuning["max_deterministic_time"] = budget_s * cfg.dtime_per_s
    searched = time.perf_counter()
    result = search(em, left, cfg.base_seed, variant.workers, tuning=tuning)
    end = time.perf_counter()
    # No answer: the service falls back to FCFS (the hint, when there is one, is no worse).
    answer = result.assignment if result else hint if hint is not None else fcfs(ctx).assignment
    cost = float(ctx.evaluator.evaluate(answer).costs[case.objective][0])
    return {
        "variant": name,
        "family": case.family,
        "name": case.name,
        "conflicts": case.problem.n_conflicts,
        "budget_s": budget_s,
        "found": result is not None,
        "optimal": bool(result and result.optimal),
        "cost": cost,
        "ref_runtime_s": case.ref_runtime_s,
        "runtime_s": end - start,
        "hint_s": hint_s,
        "search_s": end - searched,
        "bounded": bounded,
        "dtime": result.deterministic_time if result else float("nan"),
        "dtime_limit": tuning.get("max_deterministic_time"),
        "fingerprint": fingerprint(answer),
        "reused": False,
        "repeat_identical": None,
    }


def run_case(
    name: str, case: Case, cfg: Config, models: Mapping[str, StoredModel]
) -> list[dict[str, Any]]:
    """One configuration on one problem at every budget; the first budget twice, same seed.

    A run that proved optimality stands for the larger budgets too (``reused``).
    """
    budgets = sorted(cfg.budgets)
    first = run_once(name, case, budgets[0], cfg, models)
    again = run_once(name, case, budgets[0], cfg, models)
    first |= {"repeat_identical": again["fingerprint"] == first["fingerprint"],
              "repeat_cost": again["cost"]}  # fmt: skip
    rows, last = [first], first
    for budget in budgets[1:]:
        if last["optimal"]:
            last = {**last, "budget_s": budget, "reused": True, "repeat_identical": None}
        else:
            last = run_once(name, case, budget, cfg, models)
        rows.append(last)
    return rows


def warm_up(cfg: Config, case: Case, models: Mapping[str, StoredModel]) -> None:
    """Every configuration once, briefly: JIT compiling and model loading are not timed."""
    for name in cfg.variants:
        run_once(name, case, 0.2, cfg, models)


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Every configuration on every problem; return everything that gets written."""
    cases = conformance_cases(cfg.sets, cfg.per_set, cfg.objective) + world_cases(
        cfg.worlds, cfg.per_world, cfg.cache, cfg.base_seed, cfg.objective or "avg_completion"
    )
    models = service_policy(cfg.store).models
    warm_up(cfg, min(cases, key=lambda c: c.problem.n_conflicts), models)
    settle()  # the service's collector policy once warm: the cases held escape full collections
    rows: list[dict[str, Any]] = []
    for case in tqdm(cases, desc="cpsat", unit="problem", disable=not progress):
        # Side by side per problem: drifts of the machine's load hit every variant alike.
        rows += measured(
            case, [r for name in cfg.variants for r in run_case(name, case, cfg, models)]
        )
    return {"machine": machine_info(), "config": jsonable(asdict(cfg)), "rows": rows}


def _share(flags: Sequence[bool | None]) -> float:
    """The share of true among the known flags (NaN if none is known)."""
    known = [f for f in flags if f is not None]
    return float(np.mean(known)) if known else float("nan")


def _repeats_and_work(members: list[dict[str, Any]]) -> dict[str, Any]:
    """The figures of one group beyond the shared ones (bench.conformance.summarize).

    ``proven_where_milp``: the share proven among the problems the independent MILP
    proved within the same budget; ``identical``: the share of identical repeats
    (``identical_unproven``: among the runs not proven optimal); ``dtime_per_s``:
    CP-SAT's deterministic time per wall second of search, over the runs a limit ended.
    """
    milp_fast = [
        m for m in members if m["ref_runtime_s"] is not None and m["ref_runtime_s"] <= m["budget_s"]
    ]
    timed = [m for m in members if not m["reused"] and not m["optimal"] and m["found"]]
    return {
        "proven_where_milp": _share([m["optimal"] for m in milp_fast]),
        "milp_fast": len(milp_fast),
        "identical": _share([m["repeat_identical"] for m in members]),
        "identical_unproven": _share([m["repeat_identical"] for m in members if not m["optimal"]]),
        "dtime_per_s": nanmean([m["dtime"] / m["search_s"] for m in timed]),
    }


def summarize(rows: Sequence[dict[str, Any]], by: Sequence[str]) -> list[dict[str, Any]]:
    """The shared figures per group of ``by`` keys, with repeats and CP-SAT's work."""
    return summarize_rows(rows, by, _repeats_and_work)


def _percent(share: float) -> str:
    """A share as a whole percentage ("-" for NaN)."""
    return "-" if share != share else f"{100 * share:.0f} %"


def main_table(summary: Sequence[dict[str, Any]], budgets: Sequence[float]) -> str:
    """Markdown: per configuration, every budget's cell, identical repeats and dtime per s."""
    by = {(s["variant"], s["budget_s"]): s for s in summary}
    headers = [
        "configuration",
        *(f"{b:g} s" for b in budgets),
        "identical repeats (unproven)",
        "dtime/s",
    ]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for name in dict.fromkeys(s["variant"] for s in summary):
        first = by[(name, budgets[0])]
        cells = [
            f"`{name}`",
            *(cell(by[(name, b)]) for b in budgets),
            f"{_percent(first['identical'])} ({_percent(first['identical_unproven'])})",
            fmt(first["dtime_per_s"], 3),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def set_table(summary: Sequence[dict[str, Any]], sets: Sequence[str]) -> str:
    """Markdown: per configuration and budget, one ``ratio / delay / proven`` cell per set."""
    by = {(s["variant"], s["budget_s"], s["family"]): s for s in summary}
    headers = ["configuration", "budget", *sets]
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    for name, budget in dict.fromkeys((s["variant"], s["budget_s"]) for s in summary):
        cells = [f"`{name}`", f"{budget:g} s", *(cell(by[(name, budget, f)]) for f in sets)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def plot(summary: Sequence[dict[str, Any]], budgets: Sequence[float], path: Path) -> None:
    """Delay ratio and share proven per configuration, one bar per budget."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(s["variant"] for s in summary))
    by = {(s["variant"], s["budget_s"]): s for s in summary}
    y = np.arange(len(names))
    height = 0.8 / len(budgets)
    fig, axes = plt.subplots(1, 2, figsize=(12, 0.45 * len(names) + 1.5), sharey=True)
    for k, budget in enumerate(budgets):
        offset = y + (k - (len(budgets) - 1) / 2) * height
        for ax, key in zip(axes, ("delay_ratio_mean", "proven"), strict=True):
            values = [by[(n, budget)][key] for n in names]
            ax.barh(offset, values, height, label=f"{budget:g} s")
    axes[0].set(yticks=y, yticklabels=names, xlabel="mean delay ratio", xlim=(0, 1))
    axes[1].set(xlabel="share proven optimal", xlim=(0, 1))
    axes[0].invert_yaxis()
    for ax in axes:
        ax.grid(True, axis="x", alpha=0.3)
    axes[1].legend(title="budget", fontsize="small")
    fig.suptitle("CP-SAT configurations on the conformance sets (wh 25-100, geo dense 25)")
    save_figure(fig, path)


def _yardstick(objective: str | None) -> str:
    """What the ratios are measured against."""
    if objective is None:
        return "Ratios against the optimum the independent MILP proved."
    return (
        f"Objective {objective} instead of the sets' own: ratios against the best cost any "
        "configuration found."
    )


def report(results: dict[str, Any], out: Path) -> str:
    """Write tables, plot and raw files under ``out``; return the tables' text."""
    out.mkdir(parents=True, exist_ok=True)
    rows, cfg, m = results["rows"], results["config"], results["machine"]
    budgets = sorted(cfg["budgets"])
    overall = summarize(rows, ("variant", "budget_s"))
    per_set = summarize(rows, ("variant", "budget_s", "family"))
    descriptions = "\n".join(f"- `{n}`: {VARIANTS[n].label}" for n in cfg["variants"])
    problems = len({r["name"] for r in rows})
    families = list(dict.fromkeys(r["family"] for r in rows))
    text = "\n\n".join(
        [
            f"Run {m['date']} on {m['cpu']} ({m['cpus']} CPUs), OR-Tools "
            f"{m['packages'].get('ortools')}, commit {m['commit']}; {problems} problems"
            f" ({', '.join(families)}), seed {cfg['base_seed']}, deterministic-time "
            f"budgets at {cfg['dtime_per_s']:g} per second. " + _yardstick(cfg.get("objective")),
            descriptions,
            "Cells: mean cost ratio / mean delay ratio / share proven optimal. Identical "
            f"repeats: two runs at {budgets[0]:g} s with the same seed gave the same "
            "assignment (in brackets: among the runs not proven optimal, whose search the "
            "limit cut). dtime/s: CP-SAT's deterministic time per wall second of search "
            "(runs not ended by a proof).",
            main_table(overall, budgets),
            "Per set or world:",
            set_table(per_set, families),
        ]
    )
    (out / "tables.md").write_text(text + "\n")
    write_json(out / "results.json", results)
    write_csv(out / "results.csv", rows)
    plot(overall, budgets, out / "cpsat.png")
    return text


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="a CI smoke run of about 20 seconds")
    p.add_argument("--variants", nargs="+", choices=tuple(VARIANTS))
    add_case_args(p)
    p.add_argument("--objective", choices=OBJECTIVES, help="instead of the sets' own")
    p.add_argument("--budgets", type=float, nargs="+", help="seconds per solve")
    p.add_argument("--dtime-per-s", type=float, help="deterministic time per budget second")
    add_run_args(p)
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry."""
    return run_cli(_parse_args(argv), Config(), QUICK, run, report)


if __name__ == "__main__":
    raise SystemExit(main())
