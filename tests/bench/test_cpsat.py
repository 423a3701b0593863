"""bench.cpsat: summaries, flags, explicit variants, and the quick run end to end."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from bench.cpsat import QUICK, VARIANTS, Config, _parse_args, main, summarize
from bench.report import config_from_args


def _row(variant: str, budget: float, optimal: bool, identical: bool | None, **kw) -> dict:
    return {
        "variant": variant, "budget_s": budget, "ratio": 0.99, "delay_ratio": 0.9,
        "optimal": optimal, "reached": optimal, "repeat_identical": identical,
        "runtime_s": budget, "search_s": budget, "dtime": 0.1 * budget, "found": True,
        "reused": False, "ref_runtime_s": 2.0, **kw,
    }  # fmt: skip


def test_summary_shares_milp_proofs_and_dtime() -> None:
    rows = [
        _row("a", 1.0, True, True),
        _row("a", 1.0, False, False),
        _row("a", 1.0, False, True, ref_runtime_s=0.5),
    ]
    (s,) = summarize(rows, ("variant", "budget_s"))
    assert s["proven"] == pytest.approx(1 / 3)
    assert s["identical"] == pytest.approx(2 / 3)
    assert s["identical_unproven"] == pytest.approx(1 / 2)
    assert s["milp_fast"] == 1 and s["proven_where_milp"] == 0.0
    assert s["dtime_per_s"] == pytest.approx(0.1)  # over the two runs a limit ended


def test_quick_defaults_flags_and_variants() -> None:
    skip = ("quick", "summarize", "cache")
    assert config_from_args(_parse_args(["--quick"]), Config(), QUICK, skip) == QUICK
    cfg = config_from_args(
        _parse_args(["--variants", "lin2", "w2", "--budgets", "2", "--per-set", "1"]),
        Config(),
        QUICK,
        skip,
    )
    assert cfg == replace(Config(), variants=("lin2", "w2"), budgets=(2.0,), per_set=1)
    assert all(v.hint in ("fcfs", "stage", "none") for v in VARIANTS.values())
    assert VARIANTS["default"].linearization == 1  # explicit: the service's default moved
    cfg = config_from_args(_parse_args(["--objective", "max_completion"]), Config(), QUICK, skip)
    assert cfg.objective == "max_completion"


def test_quick_run_writes_everything(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert main(["--quick", "--out", str(out)]) == 0
    for name in ("tables.md", "results.json", "results.csv", "cpsat.png"):
        assert (out / name).stat().st_size > 0
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert {r["variant"] for r in rows} == set(QUICK.variants)
    assert len(rows) == len(QUICK.variants) * 2 * len(QUICK.budgets)  # 2 problems
    assert all(r["ratio"] <= 1 + 1e-9 for r in rows)  # never below the proven optimum
    assert all(r["repeat_identical"] is not None for r in rows if r["budget_s"] == 0.3)
    assert main(["--quick", "--out", str(out), "--summarize"]) == 0  # re-renders from raw
