"""bench.cpsat: the objective cutoff, summaries, flags, explicit variants, the quick run."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from bench.cases import conformance_cases
from bench.cpsat import QUICK, VARIANTS, Config, _parse_args, bound_by, main, summarize
from bench.report import config_from_args
from service.solvers.exact import build_model, search
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext


def test_the_cutoff_is_the_incumbents_cost_exactly() -> None:
    (case,) = conformance_cases(("wh_50",), per_set=1)
    ctx = SolveContext(case.problem, case.objective, 5.0)
    incumbent = fcfs(ctx).assignment
    em = build_model(case.problem, case.cliques, case.objective)
    assert bound_by(em, incumbent, 5.0)
    found = search(em, 1.0)  # nothing worse than the incumbent
    assert found is not None
    cost, bound = (
        float(ctx.evaluator.evaluate(a).costs[case.objective][0])
        for a in (found.assignment, incumbent)
    )
    assert cost <= bound + 1e-9
    # Tight, not below: the incumbent itself stays feasible.
    values = [*incumbent.a_first[0].tolist(), *incumbent.following[0].tolist()]
    for lit, val in zip([*em.a_first.tolist(), *em.following.tolist()], values, strict=True):
        em.model.add(em.model.get_bool_var_from_proto_index(lit) == int(val))
    pinned = search(em, 5.0)
    assert pinned is not None and pinned.optimal
    assert np.array_equal(pinned.assignment.a_first, incumbent.a_first)


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
    assert config_from_args(_parse_args(["--quick"]), Config(), QUICK) == QUICK
    cfg = config_from_args(
        _parse_args(["--variants", "lin2", "w2", "--budgets", "2", "--per-set", "1"]),
        Config(),
        QUICK,
    )
    assert cfg == replace(Config(), variants=("lin2", "w2"), budgets=(2.0,), per_set=1)
    assert all(v.hint in ("fcfs", "stage", "none") for v in VARIANTS.values())
    assert VARIANTS["default"].linearization == 1  # explicit: the service's default moved
    assert VARIANTS["default"].probing == 2 and VARIANTS["stage_lin0_probe0"].probing == 0
    cfg = config_from_args(
        _parse_args(
            ["--objective", "max_completion", "--worlds", "wh_two_way:25", "--per-world", "2"]
        ),
        Config(),
        QUICK,
    )
    assert cfg.objective == "max_completion" and cfg.worlds == ("wh_two_way:25",)
    assert cfg.per_world == 2


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
