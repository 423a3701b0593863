"""Summaries, plain-text tables, raw-result files and the plot of a benchmark run."""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import subprocess
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

__all__ = [
    "MODEL_STORE",
    "PERCENTILES",
    "REFERENCE_VERSION",
    "JsonCache",
    "config_from_args",
    "delay_ratio",
    "fmt",
    "format_table",
    "git_commit",
    "jsonable",
    "machine_info",
    "markdown_table",
    "nanmean",
    "plot_lines",
    "plot_solve_times",
    "reference_cache",
    "save_figure",
    "summarize_solves",
    "write_csv",
    "write_json",
    "write_results",
]

C = TypeVar("C")  # a benchmark's frozen Config dataclass

MODEL_STORE = Path(__file__).resolve().parents[1] / "model_store"  # the shipped models

# Percentiles reported for solve times. With few problems per group p95 interpolates
# between the largest times (numpy's default, "linear"), so read it with the group size.
PERCENTILES = (50, 95)
# Versions worth recording next to the figures: the solver and the JIT dominate them.
_PACKAGES = ("numpy", "numba", "ortools", "pydantic")


def cost_ratio(opt: float, cost: float) -> float:
    """opt / cost, 1 at the optimum; 1 where the cost is 0 (avg_delay with no delay needed:
    then the optimum is 0 too)."""
    return opt / cost if cost > 0 else 1.0


def delay_ratio(opt: float, cost: float, free: float) -> float:
    """(opt - free) / (cost - free), 1 at the optimum; NaN where free is no lower bound."""
    tol = 1e-9 * max(1.0, abs(opt))
    if cost <= opt + tol:
        return 1.0
    if opt < free - tol:  # sync_completion is not monotone: zero delay need not be a bound
        return float("nan")
    return (opt - free) / (cost - free)


def nanmean(values: Sequence[float]) -> float:
    """Mean of the finite values (NaN stands for "none"); NaN if there is none."""
    arr = np.array(values, dtype=float)
    return float(np.nanmean(arr)) if np.isfinite(arr).any() else float("nan")


def fmt(x: float, digits: int = 3) -> str:
    """``x`` with ``digits`` decimals, "-" for NaN."""
    return "-" if x != x else f"{x:.{digits}f}"


def jsonable(d: dict[str, Any]) -> dict[str, Any]:
    """A config's fields as JSON-ready values (paths as strings)."""
    return {k: str(v) if isinstance(v, Path) else v for k, v in d.items()}


def add_run_args(p: argparse.ArgumentParser) -> None:
    """The flags every sweep benchmark shares: seed, model store, output, cache, re-render."""
    p.add_argument("--seed", type=int, dest="base_seed")
    p.add_argument("--store", type=Path, help="model store")
    p.add_argument("--out", type=Path)
    p.add_argument("--cache", type=Path)
    p.add_argument(
        "--summarize", action="store_true", help="re-render from --out/results.json only"
    )


def config_from_args(
    args: argparse.Namespace, full: C, quick: C, skip: Sequence[str] = ("quick", "summarize")
) -> C:
    """The quick (``args.quick``) or full defaults, overridden by every flag given.

    Flags not among the config's fields go in ``skip``; lists become tuples.
    """
    base = quick if args.quick else full
    given = {
        k: tuple(v) if isinstance(v, list) else v
        for k, v in vars(args).items()
        if k not in skip and v is not None
    }
    return replace(base, **given)  # type: ignore[type-var]


class JsonCache:
    """Expensive results by key, kept in one JSON file rewritten after every new entry."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.data: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}

    def seed(self, entries: dict[str, Any]) -> None:
        """Store ``entries`` (key -> value) whose keys the cache does not hold yet."""
        fresh = {k: v for k, v in entries.items() if k not in self.data}
        if fresh:
            self.data.update(fresh)
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.write_text(json.dumps(self.data))

    def get(self, key: str, compute: Callable[[], Any]) -> Any:
        """The stored value of ``key``, or ``compute()``'s, stored first."""
        if key not in self.data:
            self.data[key] = compute()
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.write_text(json.dumps(self.data))
        return self.data[key]


# The version of the solvers that make the cached references (compare, paths,
# generalization). A reference is the best some solvers found, so it goes stale when
# they improve: bumped then, so that caches from before are not reused (2: ``auto``'s
# first stage is robot-priority search, session 12; its 10-s answers on 100-250-robot
# warehouses cost 15-40 % less than the old references; 3: session 24, LNS after priority
# search at 250 robots and its wider step, whose 10-s answers there cost 10-28 % less than
# the r2 references; 4: session 27, re-insertion and LNS delay held robots up to their
# latest delays, whose 5-s answers on 100-250-robot warehouses cost less than r3; 5:
# session 34, re-insertion's repairs no longer thrown away where a robot fixed to pass
# first found no passage, whose 5-s answers on 250-robot warehouses cost 2-2.6 % less
# than r4's 30-s ones; r5 holds r4's runs and new ones of the 100- and 250-robot worlds).
# Session 50 appended to r5's avg_delay rows of the 100- and 250-robot warehouses a 30-s
# run of the code whose re-insertion holds avg_delay's robots by their completions (1-17 %
# cheaper); a world's yardstick is its cheapest row.
REFERENCE_VERSION = 5


def reference_cache(directory: Path, name: str) -> JsonCache:
    """The cache of references ``name`` under ``directory``, of REFERENCE_VERSION."""
    return JsonCache(directory / f"{name}-r{REFERENCE_VERSION}.json")


def summarize_solves(runs: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (family, robots, conflicts per robot, objective), in first-seen order.

    Each row: problems, mean conflicts, p50/p95/max solve seconds, and the
    fractions of solves that found a solution and that proved it optimal.
    """
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for run in runs:
        key = (run["family"], run["robots"], run["conflicts_per_robot"], run["objective"])
        groups.setdefault(key, []).append(run)
    rows = []
    for (family, robots, density, objective), members in groups.items():
        times = np.array([m["time_s"] for m in members])
        p50, p95 = np.percentile(times, PERCENTILES)
        rows.append(
            {
                "family": family,
                "robots": robots,
                "conflicts_per_robot": density,
                "objective": objective,
                "problems": len(members),
                "conflicts_mean": float(np.mean([m["n_conflicts"] for m in members])),
                "p50_s": float(p50),
                "p95_s": float(p95),
                "max_s": float(times.max()),
                "found": float(np.mean([m["found"] for m in members])),
                "optimal": float(np.mean([m["optimal"] for m in members])),
            }
        )
    return rows


def format_table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A plain-text table: first column left-aligned, the others right-aligned."""
    cells = [[str(h) for h in headers], *[[str(c) for c in row] for row in rows]]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]

    def line(row: list[str]) -> str:
        parts = [
            cell.ljust(w) if i == 0 else cell.rjust(w)
            for i, (cell, w) in enumerate(zip(row, widths, strict=True))
        ]
        return "  ".join(parts).rstrip()

    rule = "  ".join("-" * w for w in widths)
    return "\n".join([line(cells[0]), rule, *(line(r) for r in cells[1:])])


def markdown_table(headers: Sequence[str], rows: Iterable[Sequence[Any]]) -> str:
    """A Markdown (pipe) table of the rows' cells as strings."""
    lines = ["| " + " | ".join(map(str, headers)) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in rows]
    return "\n".join(lines)


def _cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo (Linux), else what platform knows."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for text in f:
                if text.startswith("model name"):
                    return text.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def git_commit() -> str | None:
    """The checked-out commit, if this runs inside a git work tree."""
    try:
        out = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).resolve().parent,
        )
    except (OSError, subprocess.CalledProcessError):
        return None
    return out.stdout.strip() or None


def machine_info() -> dict[str, Any]:
    """Where and when the benchmark ran: CPU, core count, Python and key package versions."""
    versions = {}
    for name in _PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "cpu": _cpu_model(),
        "cpus": len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "packages": versions,
        "commit": git_commit(),
    }


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as indented JSON."""
    path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")


def write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """Write dict rows as CSV with the first row's keys as the header."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        if not rows:
            return
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def write_results(
    out: Path, text: str, results: dict[str, Any], rows: Sequence[dict[str, Any]]
) -> None:
    """A run's files under ``out``: its tables (``tables.md``), everything it recorded
    (``results.json``) and its rows (``results.csv``)."""
    (out / "tables.md").write_text(text + "\n")
    write_json(out / "results.json", results)
    write_csv(out / "results.csv", rows)


def save_figure(
    fig: Any, path: Path, dpi: int = 100, rect: tuple[float, float, float, float] | None = None
) -> None:
    """Lay out ``fig`` (within ``rect``, figure fractions, to leave room for a legend
    below), write it to ``path`` and free it (pyplot keeps every open figure)."""
    import matplotlib.pyplot as plt

    fig.tight_layout(rect=rect)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def plot_solve_times(summary: Sequence[dict[str, Any]], time_limit_s: float, path: Path) -> None:
    """Solve-time p50 and p95 against robot count, one panel per objective (log scale).

    Small problems are one line per percentile; stitched problems one line per
    percentile and conflict density. The time limit is drawn dashed.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    objectives = list(dict.fromkeys(row["objective"] for row in summary))
    cols = 2 if len(objectives) > 1 else 1
    nrows = (len(objectives) + cols - 1) // cols
    fig, axes = plt.subplots(
        nrows, cols, figsize=(12.0, 4.0 * nrows), squeeze=False, sharex=True, sharey=True
    )
    series: dict[tuple[str, float | None], str] = {("small", None): "small"}
    for row in summary:
        if row["family"] == "stitched":
            series[("stitched", row["conflicts_per_robot"])] = (
                f"stitched, {row['conflicts_per_robot']:g} conflicts/robot"
            )
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, objective in zip(axes.ravel(), objectives, strict=False):
        for k, ((family, density), label) in enumerate(series.items()):
            rows = [
                r
                for r in summary
                if r["objective"] == objective
                and r["family"] == family
                and r["conflicts_per_robot"] == density
            ]
            if not rows:
                continue
            x = [r["robots"] for r in rows]
            color = colors[k % len(colors)]
            ax.plot(x, [r["p50_s"] for r in rows], "o-", color=color, label=f"{label} p50")
            ax.plot(x, [r["p95_s"] for r in rows], "^--", color=color, label=f"{label} p95")
        ax.axhline(time_limit_s, color="grey", linestyle=":", linewidth=1, label="time limit")
        ax.set_title(objective)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(sorted({r["robots"] for r in summary}))
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(objectives) :]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("robots")
    for ax in axes[:, 0]:
        ax.set_ylabel("exact solve time (s)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize="small", frameon=False)
    fig.suptitle("CP-SAT exact solve time by problem size")
    legend_rows = -(-(2 * len(series) + 1) // 3)  # ceil(entries / 3 columns)
    save_figure(fig, path, dpi=120, rect=(0, (0.045 * legend_rows + 0.02) / nrows, 1, 1))


def plot_lines(
    summary: Sequence[dict[str, Any]],
    key: str,
    label: str,
    path: Path,
    *,
    x: str = "budget_s",
    xlabel: str = "budget (s)",
    panel: str = "family",
    line: str = "method",
) -> None:
    """``key`` against ``x`` (log axis): one panel per value of ``panel``, one line per value
    of ``line``; each panel titled with its problems per point (a range where they differ)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    panels = list(dict.fromkeys(s[panel] for s in summary))
    ticks = sorted({s[x] for s in summary})
    cols = min(5, len(panels))
    nrows = -(-len(panels) // cols)
    fig, axes = plt.subplots(
        nrows, cols, figsize=(3.6 * cols, 3.2 * nrows), squeeze=False, sharex=True
    )
    for ax, name in zip(axes.ravel(), panels, strict=False):
        for member in dict.fromkeys(s[line] for s in summary):
            sel = sorted(
                (s for s in summary if s[panel] == name and s[line] == member),
                key=lambda s: s[x],
            )
            ax.plot([s[x] for s in sel], [s[key] for s in sel], "o-", ms=3, label=member)
        n = sorted({s["problems"] for s in summary if s[panel] == name})
        count = str(n[0]) if n[0] == n[-1] else f"{n[0]}-{n[-1]}"
        ax.set_title(f"{name} (n = {count})", fontsize="medium")
        ax.set_xscale("log")
        ax.set_xticks(ticks, [f"{t:g}" for t in ticks])  # the values run, not powers of ten
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(panels) :]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel(xlabel)
    for ax in axes[:, 0]:
        ax.set_ylabel(label)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    ncol = min(len(labels), 2 * cols)  # about two entries fit beside each other per panel
    fig.legend(handles, labels, loc="lower center", ncol=ncol, frameon=False)
    save_figure(fig, path, rect=(0, 0.06 * -(-len(labels) // ncol) / nrows, 1, 1))
