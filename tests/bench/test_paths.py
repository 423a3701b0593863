"""bench.paths: reference choice, per-solver rows, failures, flags, and the quick run end to end."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import get_args

import pytest

from bench.paths import (
    ERROR,
    OK,
    QUICK,
    REFUSED,
    SOLVERS,
    Config,
    WorldCase,
    _parse_args,
    failures,
    finish_rows,
    main,
    model_cost,
    solvers_for,
    summarize,
)
from bench.report import config_from_args
from service.core.path_schemas import PathsRequest
from service.core.schemas import SolverName
from service.geometry.graph import GeometrySettings
from service.motion.plan import plan_paths
from service.scenarios import generate
from service.solvers.dispatch import DispatchPolicy
from tests.motion.scenarios import SCENARIOS
from tests.motion.worlds import request


def _case(ref: dict | None) -> WorldCase:
    world = generate("floor_sparse", 2, 0)
    return WorldCase("floor", "floor_sparse", 2, 0, 0, world, 8.0, ref)


def _ok(cost: float, solver_used: str = "exact", clear: bool = True) -> dict:
    return {
        "status": OK, "message": None, "e2e_s": 0.5, "graph_s": 0.1, "solve_s": 0.3,
        "motion_s": 0.05, "cost": cost, "conflicts": 3, "solver_used": solver_used,
        "fallback_from": None, "optimal": False, "detail": None, "collision_free": clear,
        "min_clearance_m": 0.05 if clear else -0.1, "replay_collision_free": clear,
        "model_cost": 9.5,
    }  # fmt: skip


def test_rows_measure_against_the_best_executed_cost() -> None:
    ref = {**_ok(10.0), "limit_s": 10.0}
    fcfs, tabu = finish_rows(_case(ref), {"fcfs": _ok(12.0), "tabu": _ok(9.0)})
    assert fcfs["ref_cost"] == 9.0 and fcfs["ref_source"] == "tabu"
    assert fcfs["ratio"] == pytest.approx(9.0 / 12.0)
    assert fcfs["delay_ratio"] == pytest.approx((9.0 - 8.0) / (12.0 - 8.0))
    assert fcfs["model_gap"] == pytest.approx(12.0 / 9.5)
    assert tabu["reached_ref"] and not fcfs["reached_ref"]
    assert fcfs["overhead_s"] == pytest.approx(0.15)
    assert fcfs["render_s"] == pytest.approx(0.05)
    (row,) = finish_rows(_case(ref), {"fcfs": _ok(11.0)})
    assert row["ref_source"] == "exact 10 s" and row["ref_cost"] == 10.0
    fell_back = {**_ok(10.0, solver_used="fcfs"), "limit_s": 10.0}
    (row,) = finish_rows(_case(fell_back), {"fcfs": _ok(11.0)})
    assert row["ref_source"] == "exact 10 s (answered by its fallback fcfs)"


def test_refused_worlds_and_failures_are_counted_not_hidden() -> None:
    refused = {"status": REFUSED, "message": "robots a and b park in each other's way"}
    case = _case({**refused, "e2e_s": 0.01, "limit_s": 10.0})
    assert case.refused == refused["message"]
    rows = finish_rows(case, {"fcfs": {**refused, "e2e_s": float("nan")}})
    rows += finish_rows(
        _case({**_ok(10.0), "limit_s": 10.0}),
        {"fcfs": _ok(12.0, clear=False), "tabu": {"status": ERROR, "message": "boom", "e2e_s": 1}},
    )
    (s,) = summarize(rows, ("family",))
    counts = [s[k] for k in ("worlds", "answered", "refused", "errors", "collisions")]
    assert counts == [3, 1, 1, 1, 1]
    bad = failures({"rows": rows, "references": []})
    assert [r["solver"] for r in bad] == ["fcfs", "tabu"]
    colliding_ref = {**_ok(10.0, clear=False), "kind": "wh_one_way", "robots": 10, "seed": 0}
    assert failures({"rows": [], "references": [colliding_ref]})[0]["solver"] == "exact (reference)"


def test_quick_defaults_flags_and_fast_solvers_at_scale() -> None:
    assert config_from_args(_parse_args(["--quick"]), Config(), QUICK) == QUICK
    cfg = config_from_args(
        _parse_args(["--worlds", "2", "--solvers", "fcfs", "cmaes", "--warehouse-sizes"]),
        Config(),
        QUICK,
    )
    assert cfg == replace(Config(), worlds=2, solvers=("fcfs", "cmaes"), warehouse_sizes=())
    assert solvers_for(cfg, 100) == ("fcfs", "cmaes") and solvers_for(cfg, 250) == ("fcfs",)
    assert Config().kinds[0].startswith("floor_")  # tables list floors first


def test_quick_run_writes_everything_and_never_collides(tmp_path: Path) -> None:
    out, cache = tmp_path / "out", tmp_path / "cache"
    assert main(["--quick", "--out", str(out), "--cache", str(cache)]) == 0
    for name in ("tables.md", "results.json", "results.csv", "paths.png"):
        assert (out / name).stat().st_size > 0
    results = json.loads((out / "results.json").read_text())
    rows = results["rows"]
    assert {r["family"] for r in rows} == {"floor", "warehouse"}
    assert {r["solver"] for r in rows} == set(QUICK.solvers)
    answered = [r for r in rows if r["status"] == OK]
    assert answered and all(r["status"] in (OK, REFUSED) for r in rows)
    assert all(r["collision_free"] and r["replay_collision_free"] for r in answered)
    assert all(r["ratio"] <= 1.0 + 1e-9 and r["cost"] >= r["free"] - 1e-6 for r in answered)
    assert "collision free" in (out / "tables.md").read_text()
    assert main(["--quick", "--out", str(out), "--summarize"]) == 0  # re-renders from raw


def test_every_solver_runs_once_by_default() -> None:
    """The default run lists every solver the service has, ``auto`` among them, once."""
    assert sorted(SOLVERS) == sorted(set(get_args(SolverName)))


def test_the_model_cost_is_the_executed_one_where_every_conflict_is_a_crossing() -> None:
    """Crossings are exclusive with one meeting place each: execution then reproduces the
    evaluator's times exactly (docs/paths.md), so the model's cost is the executed one."""
    req: PathsRequest = request(SCENARIOS["intersection"](), solver="exact", time_limit_s=5.0)
    answer = plan_paths(req, DispatchPolicy(), GeometrySettings()).response
    assert answer.assignment and all(row["type"] == "exclusive" for row in answer.assignment)
    assert model_cost(req, answer) == pytest.approx(answer.cost, rel=1e-9)
