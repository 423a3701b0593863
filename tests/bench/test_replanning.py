"""bench.replanning: moments spread over a run, ratios against the best budget, a tiny run."""

from __future__ import annotations

import json
from pathlib import Path

from bench.replanning import main, refused, spread, summarize


def test_spread_picks_evenly_and_keeps_short_runs_whole() -> None:
    moments = list(range(10))
    assert spread(moments, 20) == list(range(10))
    assert spread(moments, 3) == [0, 4, 9] or spread(moments, 3) == [0, 5, 9]
    assert spread([], 3) == []


def test_summary_per_size_and_budget() -> None:
    rows = [
        {"robots": 25, "budget_s": b, "latency_s": lat, "conflicts": 100, "cost": c,
         "best": 10.0, "cost_ratio": 10.0 / c, "delay_ratio": 1.0 if c == 10.0 else 0.5}
        for b, lat, c in [(0.1, 0.09, 12.0), (0.1, 0.12, 10.0), (1.0, 0.5, 10.0)]
    ]  # fmt: skip
    fast, slow = summarize(rows)
    assert (fast["budget_s"], fast["calls"], slow["calls"]) == (0.1, 2, 1)
    assert fast["over_budget"] == 0.5 and fast["best_share"] == 0.5
    assert abs(fast["cost_ratio"] - (10 / 12 + 1) / 2) < 1e-12
    assert slow["cost_ratio"] == 1.0 and slow["max_ms"] == 500.0


def test_quick_run_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "out"
    argv = ["--quick", "--out", str(out), "--states", "2", "--budgets", "0.02", "0.2"]
    assert main(argv) == 0
    for name in ("tables.md", "results.json", "results.csv", "replanning.png"):
        assert (out / name).stat().st_size > 0
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert len(rows) == 2 * 2 and {r["budget_s"] for r in rows} == {0.02, 0.2}
    assert all(r["cost"] >= r["best"] - 1e-9 and r["cost_ratio"] <= 1 + 1e-12 for r in rows)
    assert all(r["free"] <= r["cost"] + 1e-9 for r in rows)
    assert main([*argv, "--summarize"]) == 0  # re-renders from the raw results


def test_a_refused_world_fails_the_run() -> None:
    assert refused({"refused": []}) is None
    assert "wh_two_way 250" in str(refused({"refused": [{"kind": "wh_two_way 250"}]}))
