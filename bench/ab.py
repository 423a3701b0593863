"""Two variants of ``auto`` (or ``auto_2cores``: ``--method``) side by side, interleaved run
by run.

The 2-vCPU benchmark machines drift: measured in blocks a few minutes apart, a variant
read 0.8171 -> 0.8615 on the 250-robot generated warehouses at 1 s, and 0.8197 -> 0.8237
(better on 13 of 24 runs, worse on 11) with the two run back to back (session 40,
docs/benchmarks.md "Priority search in short turns: a drift, not a gain"). Here every
world and solver seed runs variant A and variant B back to back in one process, their
order alternating, so that the drift falls on both.

A variant is a list of module attributes to set, ``module.NAME=value`` (the value a
Python literal), e.g. ``service.solvers.portfolio.MID_LNS_SHARE=0.8``, or fields of a
module's dataclass, ``module.Class.field=value`` (e.g.
``service.solvers.turns.TurnsConfig.turn_s=0.25``: the module's name then makes instances
with that default, which reaches code that builds its configuration at call time, as
``take_turns`` and ``reinsert_search`` do by default); before each run, every attribute
either variant sets is put back to its value at start, then the run's variant applied.
Ratios are against the best known: the committed 30-s references where they hold the
world (``bench.anytime.REFERENCES``), and every run of the comparison.

``python -m bench.ab --a service.solvers.portfolio.MID_LNS_SHARE=0.8 --b
service.solvers.portfolio.MID_LNS_SHARE=0.5 --worlds wh_two_way:25 --budget 1`` prints
per family the mean cost ratio and delay ratio of each variant, B's gain over A (with a 95 %
interval where there are five worlds or more: an interval that holds 0 is no evidence either
way), how many runs A won and lost and how many each proved optimal, then how many runs
at their spread would bound a gain of RESOLVE_GAIN (0.003), and writes
``rows.json`` and ``tables.md`` under ``--out``. ``--sets wh_25 geo_dense_25`` adds
conformance sets, measured against their proven optima (``--worlds`` with no kind: the sets
alone).
"""

from __future__ import annotations

import argparse
import ast
import importlib
import json
import math
from collections import defaultdict
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields, is_dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from bench import anytime
from bench.cases import (
    Case,
    conformance_cases,
    measured,
    request_key,
    service_policy,
    world_cases,
)
from bench.report import MODEL_STORE, cost_ratio, delay_ratio, jsonable, machine_info, nanmean
from service.memory import settle

__all__ = [
    "Config",
    "Setting",
    "main",
    "paired_interval",
    "parse_setting",
    "run",
    "runs_to_resolve",
    "table",
]

VARIANTS = ("A", "B")
INTERVAL_LEVEL = 0.95  # of the paired bootstrap interval of B - A (see paired_interval)
RESAMPLES = 4000  # its bootstrap resamples
MIN_WORLDS = 5  # ... and the worlds it takes at least (see paired_interval)
# The gain the table's last line says how many runs it would take to bound (see
# runs_to_resolve): the size of most changes measured since session 60. Pairs' cost ratios
# differ by 0.040 (sd) at 250 robots and 1 s, 0.020-0.026 at 100 robots and at 5 s (session
# 72), so a 24-run comparison bounds only gains of ~0.016 at 250 robots.
RESOLVE_GAIN = 0.003


@dataclass(frozen=True)
class Setting:
    """One module attribute, or one field of a module's dataclass, and the value a variant
    gives it."""

    module: str
    name: str  # NAME, or Class.field
    value: Any


def parse_setting(text: str) -> Setting:
    """``module.NAME=value`` or ``module.Class.field=value`` -> Setting (value a Python
    literal).

    Raises:
        ValueError: not of that form, the value not a literal, or the module, its
            attribute or the dataclass field missing (a typo would otherwise compare a
            variant with itself).
    """
    target, sep, literal = text.partition("=")
    module, dot, name = target.strip().rpartition(".")
    if not sep or not dot or not module or not name:
        raise ValueError(f"{text!r}: expected module.NAME=value")
    try:
        value = ast.literal_eval(literal.strip())
    except (ValueError, SyntaxError) as e:
        raise ValueError(f"{text!r}: the value is not a Python literal") from e
    try:
        found = importlib.import_module(module)
    except ModuleNotFoundError:  # module.Class.field
        module, _, owner = module.rpartition(".")
        found = getattr(importlib.import_module(module), owner, None)
        if not is_dataclass(found) or name not in {f.name for f in fields(found)}:
            raise ValueError(f"{text!r}: {module}.{owner} is no dataclass with {name}") from None
        return Setting(module, f"{owner}.{name}", value)
    if not hasattr(found, name):
        raise ValueError(f"{text!r}: {module} has no attribute {name}")
    return Setting(module, name, value)


@contextmanager
def applied(settings: Sequence[Setting]) -> Iterator[None]:
    """``settings`` set for the duration, each attribute restored after; the fields of a
    dataclass by putting in its place a factory of instances with those defaults."""
    values: dict[tuple[str, str], Any] = {}
    overrides: dict[tuple[str, str], dict[str, Any]] = defaultdict(dict)
    for s in settings:
        owner, _, field = s.name.partition(".")
        if field:
            overrides[(s.module, owner)][field] = s.value
        else:
            values[(s.module, owner)] = s.value
    saved = {key: getattr(importlib.import_module(key[0]), key[1]) for key in {*values, *overrides}}
    values |= {key: partial(saved[key], **given) for key, given in overrides.items()}
    try:
        for (module, name), value in values.items():
            setattr(importlib.import_module(module), name, value)
        yield
    finally:
        for (module, name), value in saved.items():
            setattr(importlib.import_module(module), name, value)


@dataclass(frozen=True)
class Config:
    """What to compare and on what."""

    # Variant A's settings, ``module.NAME=value`` or ``module.Class.field=value``.
    a: tuple[str, ...] = ()
    b: tuple[str, ...] = ()  # variant B's
    worlds: tuple[str, ...] = ("wh_two_way:100", "wh_two_lane:100")
    # Conformance sets (``bench.cases.LARGE_SETS``, ...): ratios against their proven optima.
    sets: tuple[str, ...] = ()
    per_world: int = 3
    budget: float = 1.0
    solver_seeds: int = 2
    objective: str = "avg_completion"
    base_seed: int = 0  # the worlds' first seed; solver seeds count from 0
    # The portfolio compared: ``auto``, or ``auto_2cores`` (both cores for one solve, as a
    # service running one fleet is set up; ``bench.anytime.METHODS``).
    method: str = "auto"
    store: Path = MODEL_STORE
    cache: Path = Path("bench/cache")
    references: Path | None = anytime.REFERENCES
    out: Path = Path("bench/out/ab")


def run(cfg: Config, progress: bool = True) -> dict[str, Any]:
    """Both variants on every world and solver seed, back to back, order alternating."""
    variants = {"A": [parse_setting(t) for t in cfg.a], "B": [parse_setting(t) for t in cfg.b]}
    cases = conformance_cases(cfg.sets, objective=cfg.objective) + world_cases(
        cfg.worlds, cfg.per_world, cfg.cache, cfg.base_seed, cfg.objective
    )
    policy = service_policy(cfg.store)
    runner = anytime.Config(methods=(cfg.method,), objective=cfg.objective, base_seed=cfg.base_seed)
    for tag in VARIANTS:  # what a variant compiles is not timed either
        with applied(variants[tag]):
            anytime.warm_up(runner, cases, policy)
    settle()
    refs = _references(cfg)
    rows: list[dict[str, Any]] = []
    jobs = [(case, seed) for seed in range(cfg.solver_seeds) for case in cases]
    for k, (case, seed) in enumerate(tqdm(jobs, desc="ab", unit="pair", disable=not progress)):
        pair = []
        for tag in VARIANTS if k % 2 == 0 else VARIANTS[::-1]:
            with applied(variants[tag]):
                row = anytime.run_method(cfg.method, case, cfg.budget, runner, policy, seed)
            pair.append({**row, "variant": tag})
        rows += measured(case, [*_known(refs, case, cfg), *pair])[-2:]
    return {"machine": machine_info(), "config": jsonable(asdict(cfg)), "rows": rows}


def _references(cfg: Config) -> dict[str, list[dict[str, Any]]]:
    """The committed references by request key (none where ``cfg.references`` is None)."""
    return {} if cfg.references is None else json.loads(cfg.references.read_text())


def _known(refs: dict[str, list[dict[str, Any]]], case: Case, cfg: Config) -> list[dict[str, Any]]:
    """The committed reference runs of ``case`` (none where the world is not among them)."""
    return refs.get(request_key(case, cfg.objective, anytime.Config().reference_budget), [])


def table(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown: per family (and all), runs, each variant's mean cost / delay ratio against
    the best known at the end (every run of the comparison included; a conformance
    problem's proven optimum), B's mean cost ratio minus A's over their runs with its
    bootstrap interval (:func:`paired_interval`), the runs where A cost less or more than
    B, and each variant's runs proven optimal; then, where all runs bound an interval, how
    many runs at their spread would bound a gain of RESOLVE_GAIN (:func:`runs_to_resolve`)."""
    best: dict[str, float] = {}
    for r in rows:
        best[r["name"]] = min(best.get(r["name"], r["ref_cost"]), r["ref_cost"], r["cost"])
    ratios: dict[str, dict[str, list[tuple[float, float]]]] = defaultdict(lambda: defaultdict(list))
    costs: dict[str, dict[tuple[str, int], dict[str, float]]] = defaultdict(
        lambda: defaultdict(dict)
    )
    proven: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    for r in rows:
        ref = best[r["name"]]
        for family in (r["family"], "all"):
            ratios[family][r["variant"]].append(
                (cost_ratio(ref, r["cost"]), delay_ratio(ref, r["cost"], r["free"]))
            )
            costs[family][(r["name"], r["seed"])][r["variant"]] = r["cost"]
            proven[family][r["variant"]] += bool(r.get("optimal"))
    lines = [
        "| family | runs | A | B | B - A (95 % interval) | A cheaper / dearer | proven A / B |",
        "|---|---|---|---|---|---|---|",
    ]
    needed = math.nan
    for family, of in ratios.items():
        cells = [
            f"{nanmean([c for c, _ in of[v]]):.4f} / {nanmean([d for _, d in of[v]]):.3f}"
            for v in VARIANTS
        ]
        pairs = {run: c for run, c in costs[family].items() if len(c) == 2}
        wins = sum(c["A"] < c["B"] for c in pairs.values())
        losses = sum(c["A"] > c["B"] for c in pairs.values())
        gains: dict[str, list[float]] = defaultdict(list)  # by world
        for (name, _), c in pairs.items():
            gains[name].append(cost_ratio(best[name], c["B"]) - cost_ratio(best[name], c["A"]))
        every = [g for of_world in gains.values() for g in of_world]
        mean, (low, high) = nanmean(every), paired_interval(list(gains.values()))
        if family == "all":
            needed = runs_to_resolve(list(gains.values()))
        shift = f"{mean:+.4f}" + (f" ({low:+.4f}, {high:+.4f})" if math.isfinite(low) else "")
        found = f"{proven[family]['A']} / {proven[family]['B']}"
        lines.append(
            f"| {family} | {len(of['A'])} | {cells[0]} | {cells[1]} | {shift} | {wins} / {losses}"
            f" | {found} |"
        )
    if math.isfinite(needed):
        lines.append(
            f"\nTo bound a gain of {RESOLVE_GAIN} ({INTERVAL_LEVEL:.0%} interval of that"
            f" half-width) at these runs' spread: ~{math.ceil(needed)} runs."
        )
    return "\n".join(lines)


def runs_to_resolve(gains: Sequence[Sequence[float]], gain: float = RESOLVE_GAIN) -> float:
    """How many runs (B - A per run, ``gains`` grouped by world as :func:`paired_interval`)
    an interval of half-width ``gain`` would take at the spread these runs show: the runs
    times the square of (their interval's half-width / ``gain``), as an interval narrows
    with the square root of the worlds (nan where these runs bound none). It tells a
    comparison whose interval holds 0 how far it is from telling the variants apart."""
    low, high = paired_interval(gains)
    if not math.isfinite(low):
        return math.nan
    runs = sum(len(g) for g in gains)
    return runs * ((high - low) / 2 / gain) ** 2


def paired_interval(
    gains: Sequence[Sequence[float]], level: float = INTERVAL_LEVEL, resamples: int = RESAMPLES
) -> tuple[float, float]:
    """The percentile bootstrap interval of the mean gain over runs, ``gains`` grouped by
    world (each run B's cost ratio minus A's on the same world and solver seed). Worlds,
    not runs, are resampled (with all their runs): a world's seeds share its difficulty,
    so resampling runs would read them as independent and narrow the interval. The
    resampling seed is fixed, so that a table re-rendered from its rows reads the same;
    (nan, nan) with fewer than ``MIN_WORLDS`` worlds, which resample into too few distinct
    means to bound anything (two worlds: three). An interval holding 0 says the runs cannot tell the
    variants apart: on the 2-vCPU machines the same variant's mean read 0.966-0.987 on one
    set across runs (session 66)."""
    groups = [np.asarray(g, dtype=float) for g in gains if len(g)]
    if len(groups) < MIN_WORLDS:
        return math.nan, math.nan
    sums = np.array([g.sum() for g in groups])  # (W,)
    sizes = np.array([g.size for g in groups])  # (W,)
    drawn = np.random.default_rng(0).integers(0, len(groups), (resamples, len(groups)))
    means = sums[drawn].sum(axis=1) / sizes[drawn].sum(axis=1)  # (resamples,)
    tail = (1 - level) / 2
    return float(np.quantile(means, tail)), float(np.quantile(means, 1 - tail))


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--a",
        nargs="*",
        default=[],
        help="variant A: module.NAME=value or module.Class.field=value ...",
    )
    p.add_argument("--b", nargs="*", default=[], help="variant B: module.NAME=value ...")
    p.add_argument("--worlds", nargs="*", help="generated worlds as kind:robots")
    p.add_argument("--sets", nargs="*", help="conformance sets (proven optima)")
    p.add_argument("--per-world", type=int, help="worlds of each kind and size")
    p.add_argument("--budget", type=float, help="seconds per solve")
    p.add_argument("--solver-seeds", type=int, help="solver seeds per world (0, 1, ...)")
    p.add_argument("--objective")
    p.add_argument("--seed", type=int, dest="base_seed", help="the worlds' first seed")
    p.add_argument("--method", choices=anytime.PORTFOLIOS, help="the portfolio compared")
    p.add_argument("--out", type=Path)
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry: run, print the table, write it and the rows under ``--out``."""
    args = _parse_args(argv)
    given = {k: tuple(v) if isinstance(v, list) else v for k, v in vars(args).items()}
    cfg = Config(**{k: v for k, v in given.items() if v is not None})
    results = run(cfg)
    text = table(results["rows"])
    cfg.out.mkdir(parents=True, exist_ok=True)
    (cfg.out / "rows.json").write_text(json.dumps(results, indent=1))
    (cfg.out / "tables.md").write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
