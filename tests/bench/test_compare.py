"""bench.compare: references, per-method rows, summaries, flags, and a tiny end-to-end run."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bench.compare import (
    QUICK,
    SMALL_FLEET,
    Case,
    Config,
    _parse_args,
    config_from_args,
    finish_rows,
    main,
    summarize,
)
from bench.problems import stitched_set


def _case(ref_cost: float = 10.0, optimal: bool = True) -> Case:
    bp = stitched_set(5, 2.0, 1, cfg=SMALL_FLEET)[0]
    trace = [(0.1, 12.0), (0.5, ref_cost)]
    return Case(bp, "sparse", "avg_completion", 8.0, ref_cost, optimal, trace)


def _result(method: str, cost: float, valid: bool = True, trace=None) -> dict:
    return {"method": method, "cost": cost, "runtime_s": 0.2, "valid": valid, "trace": trace}


def test_rows_measure_against_the_best_anyone_found() -> None:
    rows = finish_rows(
        _case(10.0),
        [_result("fcfs", 12.0), _result("tabu", 9.0), _result("gnn_vae", 5.0, valid=False)],
    )
    fcfs, tabu, invalid = rows
    assert fcfs["ref_cost"] == 9.0 and fcfs["ref_source"] == "tabu"
    assert fcfs["ratio"] == pytest.approx(9.0 / 12.0)
    assert fcfs["delay_ratio"] == pytest.approx((9.0 - 8.0) / (12.0 - 8.0))
    assert fcfs["cpsat_time_to_cost_s"] == 0.1
    assert tabu["reached_ref"] and tabu["time_to_ref_s"] == 0.2
    assert tabu["cpsat_time_to_cost_s"] is None  # CP-SAT never got down to 9
    assert not invalid["reached_ref"]


def test_earlier_results_count_for_the_reference_without_rows() -> None:
    rows = finish_rows(_case(10.0), [_result("gnn_vae", 9.5)], [_result("tabu", 9.0)])
    assert len(rows) == 1
    assert rows[0]["ref_cost"] == 9.0 and rows[0]["ref_source"] == "tabu"
    assert not rows[0]["reached_ref"]


def test_reference_source_and_trace_times() -> None:
    rows = finish_rows(
        _case(10.0, optimal=True),
        [_result("exact", 10.0, trace=[(0.05, 11.0), (0.3, 10.0)]), _result("fcfs", 11.0)],
    )
    assert rows[0]["ref_source"] == "cp-sat optimal"
    assert rows[0]["time_to_ref_s"] == 0.3
    assert rows[1]["time_to_ref_s"] is None
    assert (
        finish_rows(_case(10.0, optimal=False), [_result("fcfs", 11.0)])[0]["ref_source"]
        == "cp-sat best"
    )


def test_summary_mean_p10_and_unanswered() -> None:
    rows = [
        {"m": "a", "valid": True, "ratio": r, "delay_ratio": r, "gap": 1 - r, "runtime_s": 1.0,
         "reached_ref": r == 1.0, "time_to_ref_s": 0.5 if r == 1.0 else None,
         "cpsat_time_to_cost_s": None}
        for r in np.linspace(0.5, 1.0, 11)
    ]  # fmt: skip
    rows.append({**rows[0], "valid": False, "runtime_s": 2.0})
    (s,) = summarize(rows, ("m",))
    assert s["problems"] == 12 and s["answered"] == 11
    assert s["ratio_mean"] == pytest.approx(0.75)
    assert s["ratio_p10"] == pytest.approx(0.55)
    assert s["runtime_s_mean"] == pytest.approx(13.0 / 12.0)
    assert s["cpsat_reached"] == 0 and np.isnan(s["cpsat_time_s_mean"])
    assert s["time_to_ref_s_mean"] == pytest.approx(0.5)


def test_quick_defaults_and_flags_override() -> None:
    assert config_from_args(_parse_args(["--quick"])) == QUICK
    cfg = config_from_args(_parse_args(["--sizes", "5", "250", "--methods", "fcfs", "tabu"]))
    assert cfg == replace(Config(), sizes=(5, 250), methods=("fcfs", "tabu"))
    assert config_from_args(_parse_args(["--small-sizes"])).small_sizes == ()


def test_tiny_end_to_end_run_writes_everything(tmp_path: Path) -> None:
    args = ["--sizes", "5", "--densities", "dense", "--per-size", "2", "--time-limit", "0.5",
            "--ref-limit", "1", "--methods", "fcfs", "bbts", "gnn_vae", "gnn_vae_exact",
            "--ablation-sizes", "5", "--ablation-samples", "1", "4",
            "--small-sizes", "3", "--small-per-size", "1",
            "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache")]  # fmt: skip
    assert main(args) == 0
    out = tmp_path / "out"
    for name in ("tables.md", "results.json", "results.csv", "ablation.csv"):
        assert (out / name).stat().st_size > 0
    assert (out / "compare-avg_completion.png").stat().st_size > 0
    assert (out / "ablation.png").stat().st_size > 0
    results = json.loads((out / "results.json").read_text())
    assert len(results["rows"]) == (2 + 1) * 4 and len(results["ablation"]) == 2 * 2
    assert {r["density"] for r in results["rows"]} == {"dense", "small"}
    assert all(r["valid"] and r["ratio"] <= 1.0 + 1e-12 for r in results["rows"])
    assert len(json.loads(next((tmp_path / "cache").iterdir()).read_text())) == 3
    assert main([*args, "--summarize"]) == 0  # re-renders from the raw results alone
