"""Runs of ``bench.anytime`` (or ``bench.ab``) side by side on one yardstick.

Each run rates its answers against the best cost it knew itself (its own runs, its
references), so the tables of two sessions do not compare: a run that found a better
answer for a world lowers every other run's ratio there, its own included. Here every
problem's yardstick is the least of its proven optimum, every reference and every cost
any of the given runs found, and each run is rated against it again.

``python -m bench.yardstick docs/results/anytime/s53/results.json
docs/results/anytime/s54-last/results.json`` prints, per target group (see
``bench.anytime.target_group``), family and budget, each run's mean cost ratio / mean
delay ratio on the problems every run measured at that budget, and with ``--out`` writes
it to a file. Rows of ``bench.ab`` (``rows.json``) count as one run per variant.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from bench.anytime import target_group
from bench.report import cost_ratio, delay_ratio, markdown_table, nanmean

__all__ = ["load_runs", "main", "problem", "table", "yardsticks"]

Row = dict[str, Any]


def load_runs(paths: Sequence[Path]) -> dict[str, list[Row]]:
    """Each file's rows by run label: its path, and where the file holds several, the
    method (``bench.anytime``'s curves) or the variant (``bench.ab``)."""
    runs: dict[str, list[Row]] = {}
    for path in paths:
        rows = json.loads(path.read_text())["rows"]
        methods = {r["method"] for r in rows}
        for r in rows:
            label = str(path)
            if len(methods) > 1:
                label += f" {r['method']}"
            if "variant" in r:
                label += f" {r['variant']}"
            runs.setdefault(label, []).append(r)
    return runs


def problem(row: Row) -> tuple[str, float]:
    """A row's problem: its name and its free cost (a world that a changed generator made
    anew under the same name is another problem)."""
    return row["name"], round(row["free"], 9)


def yardsticks(runs: dict[str, list[Row]]) -> dict[tuple[str, float], float]:
    """Each problem's (:func:`problem`) least known cost: its reference (a proven optimum
    on the conformance sets) and every cost any run found."""
    best: dict[tuple[str, float], float] = {}
    for rows in runs.values():
        for r in rows:
            known = [r["cost"]] + ([] if r.get("ref_cost") is None else [r["ref_cost"]])
            best[problem(r)] = min([best.get(problem(r), float("inf")), *known])
    return best


def table(runs: dict[str, list[Row]]) -> str:
    """Markdown: per group, family and budget (and each group's "all"), each run's mean
    cost ratio / delay ratio against :func:`yardsticks`, on the problems that every run
    measured at that budget; n counts one run's rows there."""
    best = yardsticks(runs)
    labels = list(runs)
    budgets = {r["budget_s"] for rows in runs.values() for r in rows}
    shared = {  # by budget, the problems every run measured
        b: set.intersection(
            *({problem(r) for r in rows if r["budget_s"] == b} for rows in runs.values())
        )
        for b in budgets
    }
    cells: dict[tuple[str, str, float], dict[str, list[tuple[float, float]]]] = defaultdict(
        lambda: defaultdict(list)
    )
    for label, rows in runs.items():
        for r in rows:
            if problem(r) not in shared[r["budget_s"]]:
                continue
            ref = best[problem(r)]
            rated = (cost_ratio(ref, r["cost"]), delay_ratio(ref, r["cost"], r["free"]))
            group = target_group(r["family"]) or "other"
            source = "conformance" if r["conformance"] else "generated"
            for family in (r["family"], f"all {source}"):
                cells[(group, family, r["budget_s"])][label].append(rated)
    headers = ["group", "family", "budget", "n", *(f"run {k + 1}" for k in range(len(labels)))]

    def order(key: tuple[str, str, float]) -> tuple:  # by budget and group, "all" first
        group, family, budget = key
        return budget, group, not family.startswith("all "), family

    rows = [
        [group, family, f"{budget:g} s", len(of[labels[0]])]
        + [
            f"{nanmean([c for c, _ in of[v]]):.4f} / {nanmean([d for _, d in of[v]]):.3f}"
            for v in labels
        ]
        for (group, family, budget), of in sorted(cells.items(), key=lambda kv: order(kv[0]))
    ]
    legend = "\n".join(f"- run {k + 1}: `{label}`" for k, label in enumerate(labels))
    return f"{legend}\n\n" + markdown_table(headers, rows)


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", type=Path, nargs="+", help="results.json / rows.json files")
    p.add_argument("--out", type=Path, help="also write the table here")
    return p.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry."""
    args = _parse_args(argv)
    text = table(load_runs(args.runs))
    print(text)
    if args.out is not None:
        args.out.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
