"""bench.generalization: the run's files, ratios, the held-out split, the reference cache,
a candidate model beside the shipped one, and the target check."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import bench.generalization as generalization
from bench.generalization import (
    HELD,
    QUICK,
    TRAINED,
    Config,
    _parse_args,
    main,
    model_text,
    target_table,
)
from bench.report import config_from_args, git_commit

SHIPPED_MODEL = Path(__file__).resolve().parents[2] / "model_store" / "avg_completion" / "v4"
# Two kinds, one held out (wh_two_lane, by default), one small world each, short budgets.
TINY = ["--kinds", "wh_two_way", "wh_two_lane", "--sizes", "8", "--seeds", "1",
        "--ref-budget", "0.2", "--time-limit", "0.5"]  # fmt: skip


def _row(method: str, name: str, cost: float, **extra) -> dict:
    return {"method": method, "name": name, "cost": cost, "group": HELD, "robots": 250,
            "ratio": 0.99, "delay_ratio": 0.9, "e2e_s": 0.05, **extra}  # fmt: skip


def test_quick_defaults_and_flags() -> None:
    assert config_from_args(_parse_args(["--quick"]), Config(), QUICK) == QUICK
    cfg = config_from_args(_parse_args([*TINY, "--held-out", "wh_two_way"]), Config(), QUICK)
    assert cfg.kinds == ("wh_two_way", "wh_two_lane") and cfg.held_out == ("wh_two_way",)
    assert cfg.ref_budget_s == 0.2 and cfg.sizes == (8,) and cfg.candidate is None


def test_run_writes_everything_against_the_reference_and_reuses_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out, cache = tmp_path / "out", tmp_path / "cache"
    assert main([*TINY, "--out", str(out), "--cache", str(cache)]) == 0
    for name in ("tables.md", "results.json", "results.csv"):
        assert (out / name).stat().st_size > 0
    for name in ("generalization-cost.png", "generalization-delay.png"):
        assert (out / name).stat().st_size > 0
    first = json.loads((out / "results.json").read_text())
    rows = first["rows"]
    assert {r["method"] for r in rows} == {"fcfs", "gnn_vae", "gnn_vae_refined"}
    assert all(r["ratio"] <= 1 + 1e-9 for r in rows)
    assert all(r["cost"] >= p["ref_cost"] for p in first["problems"] for r in rows
               if r["name"] == p["name"])  # fmt: skip
    assert {(r["kind"], r["group"]) for r in rows} == {
        ("wh_two_way", TRAINED),
        ("wh_two_lane", HELD),
    }
    assert "Issue 13's targets" in (out / "tables.md").read_text()
    # Each reference run records the commit that ran it, and the tables say which.
    commits = {run["commit"] for p in first["problems"] for run in p["references"]}
    assert commits == {git_commit()}
    assert f"computed at commit: {git_commit()} (" in (out / "tables.md").read_text()

    def no_solve(*args, **kwargs):
        raise AssertionError("the reference was solved again")

    monkeypatch.setattr(generalization, "reference_runs", no_solve)
    again = tmp_path / "again"
    flags = ["--candidate", str(SHIPPED_MODEL), "--held-out", "wh_two_way"]
    assert main([*TINY, *flags, "--out", str(again), "--cache", str(cache)]) == 0
    second = json.loads((again / "results.json").read_text())
    assert [p["references"] for p in second["problems"]] == [
        p["references"] for p in first["problems"]
    ]
    rows = second["rows"]
    assert {(r["kind"], r["group"]) for r in rows} == {
        ("wh_two_way", HELD),
        ("wh_two_lane", TRAINED),
    }
    by = {(r["name"], r["method"]): r["cost"] for r in rows}
    for name in {r["name"] for r in rows}:  # the same model twice: the same answers
        assert by[(name, "gnn_vae [candidate]")] == by[(name, "gnn_vae")]
    assert "`gnn_vae [candidate]`" in (again / "tables.md").read_text()

    # A fresh cache seeded from the first run's results.json: its yardstick, nothing solved.
    seeded = tmp_path / "seeded"
    flags = ["--references", str(out / "results.json"), "--cache", str(tmp_path / "fresh")]
    assert main([*TINY, *flags, "--out", str(seeded)]) == 0
    third = json.loads((seeded / "results.json").read_text())
    assert [p["references"] for p in third["problems"]] == [
        p["references"] for p in first["problems"]
    ]
    with pytest.raises(SystemExit, match="at 0.2 s, not avg_completion at 0.3 s"):
        main([*TINY, *flags, "--ref-budget", "0.3", "--out", str(seeded)])


def test_targets_need_every_figure_and_never_worse_than_fcfs() -> None:
    rows = [_row("fcfs", "a", 10.0), _row("gnn_vae", "a", 9.0),
            _row("fcfs", "b", 10.0), _row("gnn_vae", "b", 10.0)]  # fmt: skip
    assert "| met |" in target_table(rows, ["gnn_vae"])
    assert "the targets are at 250" not in target_table(rows, ["gnn_vae"])
    rows[-1] = _row("gnn_vae", "b", 10.5, robots=25, delay_ratio=0.5)
    text = target_table(rows, ["gnn_vae"])  # 25 robots count for FCFS, not for the means
    assert "missed: FCFS |" in text and "| 1 (0) |" in text and "0.900 (>= 0.8)" in text
    slow = [{**r, "e2e_s": 0.2} for r in rows]
    assert "missed: time, FCFS |" in target_table(slow, ["gnn_vae"])


def test_models_say_where_their_data_disagrees_with_the_split() -> None:
    rows = [{"kind": k} for k in ("wh_two_way", "wh_mixed", "wh_two_lane")]
    models = {
        "shipped": {"name": "gnn_vae/avg_completion/v4", "trained_kinds": []},
        "candidate": {"name": "c", "trained_kinds": ["wh_two_lane", "wh_two_way"]},
    }
    text = model_text({"config": {"held_out": ["wh_two_lane"]}, "rows": rows, "models": models})
    shipped, candidate = text.splitlines()
    assert shipped.endswith("(data: no scenario kinds).")
    assert "Trained on held-out kinds ['wh_two_lane']" in candidate
    assert candidate.endswith("in the trained group but not in its data: wh_mixed.")
