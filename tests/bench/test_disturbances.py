"""bench.disturbances: summaries against b, failures and refusals, flags, a tiny run end to end."""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from bench.disturbances import (
    QUICK,
    Config,
    _parse_args,
    draws_of,
    failures,
    main,
    refusals,
    replan_times,
    summarize,
    verdict,
)
from bench.report import config_from_args
from service.simulation.disturbances import Disturbance


def _row(mode: str, draw: int, mean: float, **extra: Any) -> dict[str, Any]:
    return {
        "kind": "wh_two_way", "robots": 25, "profile": "heavy", "draw": draw, "mode": mode,
        "collided": False, "overlaps": 0, "deadlocked": 0, "mean_completion": mean,
        "max_completion": 2 * mean, "replans": [], "sim_s": 0.1, **extra,
    }  # fmt: skip


def _replan(solve_s: float, error: str | None = None) -> dict[str, Any]:
    return {
        "time": 15.0, "solve_s": solve_s, "total_s": solve_s + 0.01, "changed": error is None,
        "error": error,
    }  # fmt: skip


def test_completion_is_compared_with_b_on_the_same_draw() -> None:
    rows = [
        _row("b", 0, 100.0),
        _row("b", 1, 200.0),
        _row("c", 0, 90.0, replans=[_replan(0.05), _replan(0.15)]),
        _row("c", 1, 210.0, replans=[_replan(0.07)]),
        _row("a", 0, 50.0, collided=True, overlaps=3),
        _row("a", 1, 100.0),
    ]
    by_mode = {s["mode"]: s for s in summarize(rows, ("mode",))}
    c, a = by_mode["c"], by_mode["a"]
    assert c["vs_b"] == pytest.approx((-0.10 + 0.05) / 2)
    assert c["vs_b_sd"] == pytest.approx(0.075)
    assert c["better_than_b"] == 0.5
    assert c["mean_completion"] == 150.0 and c["mean_completion_sd"] == 60.0
    assert (c["replans"], c["replan_changed"], c["replan_errors"]) == (3, 3, 0)
    assert c["solve_max"] == 0.15
    assert c["solve_p50"] == pytest.approx(0.07)
    assert a["vs_b"] == pytest.approx(-0.5) and (a["collided"], a["overlaps"]) == (1, 3)
    assert by_mode["b"]["vs_b"] == 0.0


def test_failures_are_collisions_or_deadlocks_of_b_or_c_and_refusals_are_listed() -> None:
    rows = [
        _row("a", 0, 50.0, collided=True),  # what clock playback costs: not a failure
        _row("b", 0, 100.0, deadlocked=2),
        _row("c", 0, 90.0, collided=True),
        _row("c", 1, 90.0, replans=[_replan(0.05, "robot 'x' passed the entry\nmore")]),
    ]
    assert [(r["mode"], r["draw"]) for r in failures(rows)] == [("b", 0), ("c", 0)]
    (refused,) = refusals(rows)
    assert (refused["draw"], refused["time"]) == (1, 15.0)
    text = verdict(rows)
    assert "2 RUN(S) OF b OR c" in text and "1 re-schedule(s) refused" in text
    assert "robot 'x' passed the entry" in text and "more" not in text
    assert verdict(rows[:1]) == "**No collision and no deadlock in b or c.**"


def test_re_scheduling_times_every_period_or_on_events() -> None:
    periodic = replan_times(Config(period_s=12.0), [])
    assert list(itertools.islice(periodic, 3)) == [12.0, 24.0, 36.0]
    events = [Disturbance("a", 5.0, 3.0), Disturbance("b", 2.0, 1.0, 0.5)]
    assert replan_times(Config(on_events=True), events) == [2.0, 3.0, 5.0, 8.0]


def test_flags_and_draws_per_size() -> None:
    assert config_from_args(_parse_args(["--quick"]), Config(), QUICK) == QUICK
    args = _parse_args(["--sizes", "25", "250", "--draws", "6", "1", "--on-events", "--modes", "c"])
    cfg = config_from_args(args, Config(), QUICK, skip=("quick", "summarize", "cache"))
    assert cfg == replace(Config(), sizes=(25, 250), draws=(6, 1), on_events=True, modes=("c",))
    assert (draws_of(cfg, 25), draws_of(cfg, 250)) == (6, 1)
    assert draws_of(replace(cfg, draws=(3,)), 250) == 3
    with pytest.raises(ValueError, match="one per size"):
        draws_of(replace(cfg, draws=(1, 2, 3)), 25)


def test_a_tiny_run_writes_everything_and_b_and_c_never_collide(tmp_path: Path) -> None:
    out = tmp_path / "out"
    argv = ["--kinds", "wh_two_way", "--sizes", "10", "--draws", "2", "--out", str(out)]
    assert main([*argv, "--period", "10"]) == 0
    for name in ("tables.md", "results.json", "results.csv", "disturbances.png"):
        assert (out / name).stat().st_size > 0
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert len(rows) == (1 + 2 + 2) * 3  # (the control once, 2 draws of 2 profiles) x modes
    assert not failures(rows) and not refusals(rows)
    c_runs = [r for r in rows if r["mode"] == "c"]
    assert all(r["replans"] for r in c_runs)
    assert all(p["time"] % 10.0 == 0.0 for r in c_runs for p in r["replans"])
    undisturbed = rows[0]["undisturbed_mean"]
    assert all(r["mean_completion"] >= undisturbed - 1e-6 for r in rows if r["mode"] == "b")
    control = [r for r in rows if r["profile"] == "none"]
    assert [r["disturbances"] for r in control] == [0, 0, 0]
    assert not any(r["collided"] for r in control)  # undisturbed playback is the plan
    assert "No collision and no deadlock" in (out / "tables.md").read_text()
    assert main([*argv, "--summarize"]) == 0  # re-renders from the raw results
