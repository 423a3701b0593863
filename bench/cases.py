"""Benchmark cases with a yardstick: the shipped conformance sets and generated worlds.

``tests/data/conformance/<set>.jsonl`` holds problems whose optimum an
independent MILP proved (``ref_cost``), with the time it needed
(``ref_runtime_s``). Generated worlds (:mod:`service.scenarios`) go through the
paths form's geometry once and are cached as graph-form requests; they have no
proven optimum (``ref_cost`` unset: measured against the best cost found).
:class:`Case` carries one problem, validated once, with its cliques and its cost
at zero delay (``free``, the bound of the delay ratio); :func:`measured` turns
raw runs into ratios; :func:`summarize` and :func:`cell` make the tables.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

import service
from bench.report import C, config_from_args, cost_ratio, delay_ratio, fmt, nanmean
from service.core.cliques import CliqueBound, Cliques, clique_budget, find_cliques
from service.core.evaluate import Evaluator
from service.core.problem import Problem, ProblemError, problem_from_request
from service.core.schemas import Objective, ScheduleRequest, ScheduleResponse
from service.motion.plan import world_request
from service.scenarios import generate
from service.settings import MAX_CLIQUE_INCIDENCES, MAX_CLIQUES, Settings
from service.solvers.dispatch import DispatchPolicy, dispatch, solve_problem

__all__ = [
    "CONFORMANCE",
    "add_case_args",
    "LARGE_SETS",
    "Case",
    "case_of",
    "cell",
    "conformance_cases",
    "derivation_digest",
    "measured",
    "run_cli",
    "service_policy",
    "solve_case",
    "summarize",
    "with_options",
    "world_case",
    "world_cases",
]

CONFORMANCE = Path(__file__).resolve().parents[1] / "tests" / "data" / "conformance"
# The sets of issue 11's targets: warehouses of 25-100 robots and dense geometric floors.
LARGE_SETS = ("wh_25", "wh_50", "wh_100", "geo_dense_25")
REL_TOL = 1e-9  # a cost within this relative distance of the reference counts as reaching it
# Seeds tried per generated world before giving up on refused ones: at 10 m^2 per robot,
# floor_dense accepted 7 of 30 seeds at 25 robots and none at 50, floor_sparse 2 at 50,
# until the generator planned routes around later robots' starts (session 55: floor_dense
# 10 of 10 at 25, 9 of 10 at 50, 3 of 8 at 100).
WORLD_TRIES = 30
# The clique work bound of a service with the default settings: above it, 413.
SERVICE_BOUND = CliqueBound(MAX_CLIQUES, MAX_CLIQUE_INCIDENCES)


@dataclass(frozen=True, eq=False)
class Case:
    """One problem under its request's objective, ready to solve, with its yardstick."""

    family: str  # the conformance set, or the generated kind and size
    name: str
    request: ScheduleRequest
    problem: Problem
    cliques: Cliques
    free: float  # the objective's value with every delay zero
    ref_cost: float | None = None  # proven optimum; None: measure against the best found
    ref_runtime_s: float | None = None  # the independent MILP's time to prove ref_cost

    @property
    def objective(self) -> Objective:
        return self.request.objective


def case_of(
    family: str,
    name: str,
    request: ScheduleRequest,
    ref_cost: float | None = None,
    ref_runtime_s: float | None = None,
) -> Case:
    """Validate ``request`` the way the service does and build what every solve reuses.

    Raises:
        ProblemError: the service would answer 422.
        TooManyCliques: its cliques exceed the service's default work bound (413).
    """
    problem = problem_from_request(request)
    free = Evaluator(problem).free_costs()[request.objective]
    with clique_budget(SERVICE_BOUND):
        cliques = find_cliques(problem)
    return Case(family, name, request, problem, cliques, free, ref_cost, ref_runtime_s)


def conformance_cases(
    sets: Sequence[str], per_set: int | None = None, objective: Objective | None = None
) -> list[Case]:
    """The first ``per_set`` problems (all: None) of each named conformance set, in order.

    ``objective`` replaces each request's own; the proven optimum then no longer
    applies (``ref_cost`` None: measure against the best found), and the case's name
    ends in that objective (the sets' names end in the request's own).
    """
    cases = []
    for name in sets:
        lines = (CONFORMANCE / f"{name}.jsonl").read_text().splitlines()[:per_set]
        for line in lines:
            rec = json.loads(line)
            request = ScheduleRequest.model_validate(rec["request"])
            if objective is None or objective == request.objective:
                cases.append(
                    case_of(name, rec["name"], request, rec["ref_cost"], rec["ref_runtime_s"])
                )
            else:
                posed = _posed_name(rec["name"], request.objective, objective)
                request = request.model_copy(update={"objective": objective})
                cases.append(case_of(name, posed, request))
    return cases


def _posed_name(name: str, own: str, objective: str) -> str:
    """A conformance problem's ``name`` for it posed for ``objective``: its last part
    replaced where that is the request's ``own`` objective, else the objective appended."""
    base, _, last = name.rpartition("/")
    return f"{base}/{objective}" if base and last == own else f"{name}/{objective}"


def _derived(kind: str, robots: int, seed: int, objective: str) -> dict[str, Any]:
    """A world's graph-form request (JSON), or the 422 message when its paths are refused."""
    try:
        request = world_request(generate(kind, robots, seed), objective)
    except ProblemError as exc:
        return {"refused": str(exc)}
    if request is None:
        return {"refused": "no two robots interfere"}
    return {"request": request.model_dump(mode="json", by_alias=True)}


# The packages a world's derivation reads (the scenario generator, the paths form's geometry
# and its motion planning): cached worlds are filed under the digest of their sources, so
# that a changed derivation derives its worlds again instead of reading the old graphs
# (session 57's derivation changed every graph; a cache from before measured the old ones).
DERIVATION_PACKAGES = ("scenarios", "geometry", "motion")


@functools.cache
def derivation_digest() -> str:
    """A short digest of the Python sources of DERIVATION_PACKAGES (paths and contents)."""
    root = Path(service.__file__).resolve().parent
    digest = hashlib.sha256()
    for package in DERIVATION_PACKAGES:
        for source in sorted((root / package).rglob("*.py")):
            digest.update(source.relative_to(root).as_posix().encode())
            digest.update(source.read_bytes())
    return digest.hexdigest()[:12]


def world_case(
    kind: str,
    robots: int,
    index: int,
    cache: Path,
    base_seed: int = 0,
    objective: Objective = "avg_completion",
) -> Case | None:
    """The ``index``-th world of ``kind`` and size that the service serves (None if
    WORLD_TRIES seeds fail: paths refused with 422 or no two robots interfering).

    Derivations (seconds at 250 robots) are cached, one file per world, under ``cache``
    in a folder named by :func:`derivation_digest`.
    """
    for seed in range(base_seed + index * WORLD_TRIES, base_seed + (index + 1) * WORLD_TRIES):
        path = cache / "worlds" / derivation_digest() / f"{kind}-{robots}-{seed}-{objective}.json"
        if path.exists():
            data = json.loads(path.read_text())
        else:
            data = _derived(kind, robots, seed, objective)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(data))
        if "request" in data:
            request = ScheduleRequest.model_validate(data["request"])
            return case_of(f"{kind} {robots}", f"{kind}/{robots}/{seed}", request)
    return None


def world_cases(
    worlds: Sequence[str],
    per_world: int,
    cache: Path,
    base_seed: int = 0,
    objective: Objective = "avg_completion",
) -> list[Case]:
    """``per_world`` derivable worlds of each ``"kind:robots"``, in order (fewer if refused)."""
    jobs = [(*world.split(":"), i) for world in worlds for i in range(per_world)]
    cases = []
    for kind, robots, i in tqdm(jobs, desc="worlds", unit="world", disable=not jobs):
        case = world_case(kind, int(robots), i, cache, base_seed, objective)
        if case is not None:
            cases.append(case)
    return cases


def measured(case: Case, rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Every row (each with its ``cost`` and ``optimal``) of one problem, measured against
    its reference: the proven optimum of a conformance problem, else the best cost among
    the rows (``ref_proven`` when a row proved that cost optimal)."""
    best = min(r["cost"] for r in rows)
    ref = case.ref_cost if case.ref_cost is not None else best
    proven = case.ref_cost is not None or any(r["optimal"] and r["cost"] == best for r in rows)
    return [
        {
            **r,
            "ref_cost": ref,
            "ref_proven": proven,
            "ratio": cost_ratio(ref, r["cost"]),
            "delay_ratio": delay_ratio(ref, r["cost"], case.free),
            "reached": r["cost"] <= ref * (1 + REL_TOL),
        }
        for r in rows
    ]


def request_key(case: Case, objective: str, budget_s: float) -> str:
    """A reference cache's key: the request's SHA-256 (options aside), objective, budget."""
    body = case.request.model_dump(mode="json", by_alias=True, exclude={"options"})
    digest = hashlib.sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:20]
    return f"{digest}-{objective}-{budget_s:g}s"


def with_options(request: ScheduleRequest, options: dict[str, Any]) -> ScheduleRequest:
    """``request`` with ``options`` (solver, time_limit_s, seed, samples, ...) replacing its own."""
    return request.model_copy(update={"options": request.options.model_copy(update=options)})


def solve_case(
    case: Case, policy: DispatchPolicy, options: dict[str, Any], *, from_bytes: bool = False
) -> tuple[ScheduleResponse, float]:
    """``case`` through the dispatcher with ``options``, and the seconds it took.

    By default the problem and cliques are the case's, built once: the time is the
    solve, its check and the rendering of its answer, not the request's reading. With
    ``from_bytes`` the solve is timed as the service times a graph-form body: the clock
    and the deadline (its time limit) start before the request's JSON bytes are
    validated, and the problem and cliques are built from them, so the search gets what
    the service would give it (at 250 robots ~0.1-0.2 s less).
    """
    request = with_options(case.request, options)
    if not from_bytes:
        start = time.perf_counter()
        answer = solve_problem(case.problem, request, policy, cliques=case.cliques).response()
        return answer, time.perf_counter() - start
    body = request.model_dump_json(exclude_none=True).encode()
    start, arrival = time.perf_counter(), time.monotonic()
    limit = request.options.time_limit_s or policy.default_time_limit_s
    answer = dispatch(ScheduleRequest.model_validate_json(body), policy, deadline=arrival + limit)
    return answer, time.perf_counter() - start


def service_policy(store: Path) -> DispatchPolicy:
    """The service's dispatch policy with the models of ``store`` loaded, torch's threads
    set as the service sets them (cores / SCHEDULER_SOLVE_CONCURRENCY: 1 on 2 cores), and
    warmed up as the service is before it reports ready (every search's compiled kernels
    loaded: re-insertion search's take ~15 s to compile on a cold cache, which the first
    timed request would otherwise pay).

    Torch's own default (every core) next to another busy process made GNN-VAE sampling
    overrun 0.1 s budgets by 1-1.7 s on the 2-core benchmark machine; with one thread, 0.

    Raises:
        SystemExit: a model failed to load, or the warm-up failed.
    """
    from service.api.runtime import build_runtime, warm_up

    runtime = build_runtime(Settings(model_store=store))
    warm_up(runtime)  # loads the models of runtime.model_store first
    if runtime.model_errors:
        raise SystemExit(f"models failed to load: {runtime.model_errors}")
    if not runtime.ready:
        raise SystemExit(f"warm-up failed: {runtime.detail}")
    return runtime.policy


def summarize(
    rows: Sequence[dict[str, Any]],
    by: Sequence[str],
    extra: Callable[[list[dict[str, Any]]], dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """Per group of ``by`` keys, in first-seen order: the mean cost and delay ratios, the
    shares proven optimal and reaching the reference, the mean runtime, and ``extra``'s
    figures of the group's rows."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in by), []).append(r)
    return [
        {
            **dict(zip(by, key, strict=True)),
            "problems": len(members),
            "ratio_mean": float(np.mean([m["ratio"] for m in members])),
            "delay_ratio_mean": nanmean([m["delay_ratio"] for m in members]),
            "proven": float(np.mean([m["optimal"] for m in members])),
            "reached": float(np.mean([m["reached"] for m in members])),
            "runtime_s_mean": float(np.mean([m["runtime_s"] for m in members])),
            **(extra(members) if extra else {}),
        }
        for key, members in groups.items()
    ]


def cell(s: dict[str, Any] | None) -> str:
    """``cost ratio / delay ratio / proven %`` of one summary row ("-": not run)."""
    if s is None:
        return "-"
    return f"{fmt(s['ratio_mean'], 4)} / {fmt(s['delay_ratio_mean'])} / {100 * s['proven']:.0f} %"


def add_case_args(p: argparse.ArgumentParser) -> None:
    """The flags choosing the cases: conformance sets, problems per set, generated worlds
    and how many of each."""
    p.add_argument("--sets", nargs="*", help="conformance sets (tests/data/conformance)")
    p.add_argument("--per-set", type=int, help="problems per set (default: all)")
    p.add_argument("--worlds", nargs="*", help="generated worlds as kind:robots")
    p.add_argument("--per-world", type=int, help="worlds of each kind and size")


def run_cli(
    args: argparse.Namespace,
    full: C,
    quick: C,
    run: Callable[[C], dict[str, Any]],
    report: Callable[[dict[str, Any], Path], str],
    failed: Callable[[dict[str, Any]], str | None] = lambda results: None,
    skip: Sequence[str] = ("quick", "summarize"),
) -> int:
    """A sweep benchmark's command line: the quick (``--quick``) or full config with every
    flag given (:func:`bench.report.config_from_args`; flags in ``skip`` are not config
    fields), run (or, with ``--summarize``, re-read from ``out/results.json``), reported,
    printed. Exit status 1, with ``failed``'s message, when the results fail the run."""
    cfg = config_from_args(args, full, quick, skip)
    out = cfg.out  # type: ignore[attr-defined]  (every benchmark's Config has one)
    results = json.loads((out / "results.json").read_text()) if args.summarize else run(cfg)
    print(report(results, out))
    message = failed(results)
    if message:
        print(f"\nFAILED: {message}", file=sys.stderr)
        return 1
    return 0
