"""The benchmark CLI: deterministic problem sets, summaries, tables, and an end-to-end tiny run."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from bench.exact import QUICK, Config, _parse_args, config_from_args, main
from bench.problems import derive_seed, small_set, stitched_set
from bench.report import format_table, summarize_solves


def test_seeds_are_stable_and_keyed() -> None:
    assert derive_seed(0, 1, 4, 0) == derive_seed(0, 1, 4, 0)
    seeds = {derive_seed(0, 1, r, i) for r in range(2, 9) for i in range(50)}
    assert len(seeds) == 7 * 50
    assert derive_seed(1, 1, 4, 0) != derive_seed(0, 1, 4, 0)


@pytest.mark.parametrize("robots", [2, 5, 8])
def test_small_set_has_the_robot_count_and_is_deterministic(robots: int) -> None:
    first = small_set(robots, 4, base_seed=3)
    again = small_set(robots, 6, base_seed=3)
    assert [bp.problem.n_robots for bp in first] == [robots] * 4
    # Growing a group keeps the problems it had.
    assert [bp.request for bp in first] == [bp.request for bp in again[:4]]
    assert len({json.dumps(bp.request, sort_keys=True) for bp in again}) == 6


def test_stitched_set_reaches_the_density() -> None:
    (bp,) = stitched_set(25, 4.0, 1)
    assert bp.problem.n_robots == 25
    assert bp.problem.n_conflicts == pytest.approx(100, abs=5)
    assert stitched_set(25, 4.0, 1)[0].request == bp.request
    assert stitched_set(25, 2.0, 1)[0].seed != bp.seed


def _run(family: str, robots: int, objective: str, time_s: float, optimal: bool) -> dict:
    return {
        "family": family,
        "robots": robots,
        "conflicts_per_robot": None if family == "small" else 2.0,
        "objective": objective,
        "n_conflicts": 10,
        "time_s": time_s,
        "found": True,
        "optimal": optimal,
    }


def test_summary_percentiles_and_fractions() -> None:
    times = np.arange(1, 21) / 100  # 0.01 .. 0.20 s
    runs = [_run("small", 3, "avg_delay", t, i % 4 != 0) for i, t in enumerate(times)]
    runs.append(_run("stitched", 10, "avg_delay", 5.0, False))
    small, large = summarize_solves(runs)
    assert (small["family"], small["robots"], small["problems"]) == ("small", 3, 20)
    assert small["p50_s"] == pytest.approx(np.percentile(times, 50))
    assert small["p95_s"] == pytest.approx(np.percentile(times, 95))
    assert small["max_s"] == pytest.approx(0.20)
    assert small["optimal"] == pytest.approx(0.75)
    assert (large["family"], large["conflicts_per_robot"]) == ("stitched", 2.0)
    assert large["optimal"] == 0.0


def test_table_aligns_columns() -> None:
    text = format_table(["name", "ms"], [["a", "1.5"], ["longer", "12.25"]])
    lines = text.splitlines()
    assert lines[0] == "name       ms"
    assert lines[1] == "------  -----"
    assert lines[2] == "a         1.5"
    assert lines[3] == "longer  12.25"


def test_quick_defaults_and_flags_override() -> None:
    assert config_from_args(_parse_args([])) == Config()
    assert config_from_args(_parse_args(["--quick"])) == QUICK
    flags = ["--quick", "--time-limit", "3", "--workers", "2", "--objective", "avg_delay"]
    cfg = config_from_args(_parse_args([*flags, "--large-robots", "--no-hint"]))
    assert (cfg.time_limit_s, cfg.workers, cfg.objectives) == (3.0, 2, ("avg_delay",))
    assert cfg.large_robots == () and cfg.hint is False
    assert cfg.small_count == QUICK.small_count
    with pytest.raises(SystemExit):
        config_from_args(_parse_args(["--small-count", "0"]))


def test_tiny_run_prints_tables_and_writes_results(tmp_path, capsys) -> None:
    argv = [
        "--small-robots", "2", "3", "--small-count", "2",
        "--large-robots", "10", "--large-densities", "2", "--large-count", "1",
        "--objective", "max_completion", "--time-limit", "5",
        "--eval-robots", "12", "--eval-samples", "4", "--repeats", "2",
        "--no-progress", "--out", str(tmp_path),
    ]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "Exact solve, small problems" in out and "Exact solve, stitched problems" in out
    assert "evaluate" in out and "decode" in out

    results = json.loads((tmp_path / "results.json").read_text())
    runs = results["exact"]["runs"]
    assert len(runs) == 2 * 2 + 1
    assert all(r["found"] and r["optimal"] for r in runs)  # tiny problems: proven at once
    assert [(s["family"], s["robots"]) for s in results["exact"]["summary"]] == [
        ("small", 2),
        ("small", 3),
        ("stitched", 10),
    ]
    auto = results["auto"]["runs"]  # the small problems only, through auto end to end
    assert [(r["robots"], r["objective"]) for r in auto] == [(2, "max_completion")] * 2 + [
        (3, "max_completion")
    ] * 2
    assert all(r["optimal"] and 0 < r["time_s"] < 5 for r in auto)
    assert "auto end to end" in out
    ev = results["evaluator"]
    assert ev["robots"] == 12
    assert [(t["step"], t["batch"]) for t in ev["timings"]] == [
        ("decode", 4),
        ("evaluate", 1),
        ("evaluate", 4),
    ]
    assert results["machine"]["cpus"] >= 1 and results["config"]["objectives"] == ["max_completion"]

    with open(tmp_path / "exact_runs.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == len(runs)
    assert (tmp_path / "solve_times.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_module_entry_point_help() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "bench.exact", "--help"], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0
    assert "--quick" in done.stdout
