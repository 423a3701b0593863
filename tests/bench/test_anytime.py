"""bench.anytime: references, re-use of proven answers, targets, flags, and the quick run."""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import pytest

import bench.anytime as anytime
import bench.cases as cases
import service.solvers.dispatch as dispatch_module
from bench.anytime import (
    QUICK,
    Config,
    _parse_args,
    budgets_of,
    main,
    reference_rows,
    run_budgets,
    target_group,
    target_table,
)
from bench.cases import conformance_cases, derivation_digest, measured, world_case
from bench.report import JsonCache, config_from_args
from service.core.problem import problem_from_request
from service.solvers.exact import solve
from service.solvers.registry import SolveContext


def _raw(method: str, cost: float, budget: float = 1.0, optimal: bool = False) -> dict:
    return {"method": method, "cost": cost, "budget_s": budget, "optimal": optimal,
            "runtime_s": budget, "reused": False}  # fmt: skip


def test_generated_worlds_measure_against_the_best_found_conformance_against_the_optimum() -> None:
    (case,) = conformance_cases(("wh_25",), per_set=1)
    rows = measured(case, [_raw("tabu", case.ref_cost * 1.1)])
    assert rows[0]["ref_cost"] == case.ref_cost and rows[0]["ref_proven"]
    assert rows[0]["ratio"] == pytest.approx(1 / 1.1)
    (other,) = conformance_cases(("wh_25",), per_set=1, objective="max_completion")
    assert other.objective == "max_completion" and other.ref_cost is None
    assert case.name.endswith("/avg_completion")  # the set's own objective, then the posed one
    assert other.name == case.name.removesuffix("avg_completion") + "max_completion"
    generated = replace(case, ref_cost=None, ref_runtime_s=None)
    rows = measured(generated, [_raw("tabu", 12.0), _raw("exact", 10.0, optimal=True)])
    assert [r["ref_cost"] for r in rows] == [10.0, 10.0]
    assert rows[0]["ref_proven"] and rows[1]["reached"] and not rows[0]["reached"]


def test_proven_or_early_answers_stand_for_larger_budgets(monkeypatch) -> None:
    calls = []

    def fake(method, case, budget, cfg, policy, seed=None):
        calls.append(budget)
        runtime = 0.05 if budget >= 3 else budget  # stops on its own from 3 s on
        return {**_raw(method, 10.0 / budget, budget, optimal=False), "runtime_s": runtime}

    monkeypatch.setattr(anytime, "run_method", fake)
    rows = run_budgets("tabu", None, (10.0, 0.1, 1.0, 3.0), Config(), None)
    assert calls == [0.1, 1.0, 3.0]
    assert [r["budget_s"] for r in rows] == [0.1, 1.0, 3.0, 10.0]
    assert rows[-1]["reused"] and rows[-1]["cost"] == rows[-2]["cost"]
    assert budgets_of("auto", Config()) == (0.1, 0.3, 1.0, 3.0, 5.0, 10.0)
    assert budgets_of("tabu", Config()) == Config().budgets


def test_a_long_reference_run_joins_the_yardstick_of_generated_worlds_once(
    monkeypatch, tmp_path: Path
) -> None:
    calls = []

    def fake(method, case, budget, cfg, policy, seed=None):
        calls.append((method, budget))
        return _raw(method, 9.0, budget)

    monkeypatch.setattr(anytime, "run_method", fake)
    (case,) = conformance_cases(("wh_25",), per_set=1)
    generated = replace(case, ref_cost=None, ref_runtime_s=None)
    cfg = replace(Config(), reference_budget=30.0)
    cache = JsonCache(tmp_path / "refs.json")
    assert reference_rows(case, cfg, None, cache) == []  # a proven optimum needs none
    refs = reference_rows(generated, cfg, None, cache)
    assert reference_rows(generated, cfg, None, JsonCache(tmp_path / "refs.json")) == refs
    assert calls == [(anytime.REFERENCE_METHOD, 30.0)]
    rows = measured(generated, [*refs, _raw("auto", 10.0)])[len(refs) :]
    assert [r["method"] for r in rows] == ["auto"] and rows[0]["ref_cost"] == 9.0
    assert reference_rows(generated, replace(cfg, reference_budget=None), None, cache) == []


def test_committed_references_seed_a_cache_without_overwriting_it(tmp_path: Path) -> None:
    """The committed yardstick is keyed as the cache is: (request, objective, 30 s, or the
    reference budget of now) holding REFERENCE_METHOD's runs (avg_completion and avg_delay),
    or (request, objective, the MILP's seconds, "milp") holding the MILP backend's row;
    seeding adds what a cache lacks and keeps what it has."""
    committed = json.loads(anytime.REFERENCES.read_text())
    now = f"-{Config().reference_budget:g}s"
    runs = {k: v for k, v in committed.items() if k.endswith(("-30s", now))}
    milp_key = f"-{anytime.MILP_REFERENCE_S:g}s-milp"
    milp = {k: v for k, v in committed.items() if k.endswith(milp_key)}
    assert len(runs) + len(milp) == len(committed)
    assert sum(k.endswith(now) for k in runs) >= 20  # the yardstick of today's runs
    assert {key.split("-")[1] for key in runs} == {"avg_completion", "avg_delay"}
    assert {r["method"] for rows in runs.values() for r in rows} == {anytime.REFERENCE_METHOD}
    assert {row["backend"] for row in milp.values()} == {"milp"}
    cache = JsonCache(tmp_path / "refs.json")
    mine = next(iter(committed))
    cache.get(mine, lambda: [{"cost": 1.0}])
    cache.seed(committed)
    again = JsonCache(tmp_path / "refs.json")  # written through
    assert again.data[mine] == [{"cost": 1.0}] and again.data.keys() == committed.keys()


def test_targets_group_warehouses_and_dense_floors() -> None:
    assert target_group("wh_25") == target_group("wh_two_way 250") == "warehouse"
    assert target_group("geo_dense_25") == target_group("floor_dense 50") == "dense geometric"
    assert target_group("geo_10") is None
    row = {"method": "auto", "family": "wh_25", "ratio": 0.995, "delay_ratio": 0.95,
           "optimal": False, "name": "wh_25/0", "ref_runtime_s": 1.0,
           "conformance": True}  # fmt: skip
    text = target_table([{**row, "budget_s": 1.0}, {**row, "budget_s": 5.0}])
    assert "| 1 s | warehouse | conformance | 1 | 0.9950 (>= 0.99) | 0.950 (>= 0.9) | met |" in text
    assert "| 5 s | warehouse | both | 1 | 0.9950 (>= 0.999) | 0.950 (>= 0.98) | missed |" in text
    assert "generated" not in text
    assert "0 of 1 (wh_25/0 unproven)" in text
    proven = target_table([{**row, "budget_s": 5.0, "optimal": True}])
    assert "1 of 1 (none unproven)" in proven


def test_quick_defaults_and_flags() -> None:
    assert config_from_args(_parse_args(["--quick"]), Config(), QUICK) == QUICK
    cfg = config_from_args(
        _parse_args(["--methods", "auto", "--budgets", "1", "--worlds", "wh_mixed:50"]),
        Config(),
        QUICK,
    )
    assert cfg == replace(Config(), methods=("auto",), budgets=(1.0,), worlds=("wh_mixed:50",))
    assert Config().from_bytes
    assert not config_from_args(_parse_args(["--prepared"]), Config(), QUICK).from_bytes


def test_a_solve_from_the_requests_bytes_answers_as_the_prepared_one_within_its_limit(
    monkeypatch,
) -> None:
    """Timed from its bytes, a case reads its request as the service does (validated from
    JSON, its problem built again) and answers as the prepared case does; its clock and
    deadline cover the reading."""
    (case,) = conformance_cases(("wh_100",), per_set=1)  # unproven in 0.5 s: uses its time
    policy = cases.DispatchPolicy()
    options = {"solver": "fcfs", "time_limit_s": 1.0, "seed": 0}
    prepared, _ = cases.solve_case(case, policy, options)
    built = []

    def counted(request):
        built.append(request)
        return problem_from_request(request)

    monkeypatch.setattr(dispatch_module, "problem_from_request", counted)
    answer, seconds = cases.solve_case(case, policy, options, from_bytes=True)
    assert len(built) == 1 and built[0] is not case.request
    assert answer.cost == prepared.cost and answer.assignment == prepared.assignment
    assert 0 < seconds < 1.0

    validate = cases.ScheduleRequest.model_validate_json

    def slow_reading(raw: bytes):
        time.sleep(0.4)
        return validate(raw)

    monkeypatch.setattr(cases.ScheduleRequest, "model_validate_json", slow_reading)
    limited = {**options, "solver": "auto", "time_limit_s": 0.5}
    answer, seconds = cases.solve_case(case, policy, limited, from_bytes=True)
    assert seconds < 0.5 * 1.1 + 0.05, "the reading counts against the time limit"


def test_each_solver_seed_runs_every_method_and_budget(monkeypatch, tmp_path: Path) -> None:
    """With solver_seeds 2 every method runs every budget with seed base_seed and the
    next; the rows carry their seed, one yardstick spans them, the report names the range."""
    calls = []

    def fake(method, case, budget, cfg, policy, seed=None):
        calls.append((method, budget, seed))
        return {**_raw(method, case.ref_cost * (1 + seed / 10), budget), "seed": seed,
                "name": case.name, "family": case.family, "conformance": True,
                "ref_runtime_s": None}  # fmt: skip

    cases = conformance_cases(("wh_25",), per_set=1)
    monkeypatch.setattr(anytime, "run_method", fake)
    monkeypatch.setattr(anytime, "cases_of", lambda cfg: cases)
    monkeypatch.setattr(anytime, "service_policy", lambda store: None)
    monkeypatch.setattr(anytime, "warm_up", lambda cfg, cases, policy: None)
    args = ["--solver-seeds", "2", "--seed", "1", "--methods", "auto", "tabu", "--budgets", "1"]
    cfg = config_from_args(_parse_args(args), Config(), QUICK)
    assert cfg == replace(Config(), base_seed=1, solver_seeds=2, methods=("auto", "tabu"),
                          budgets=(1.0,))  # fmt: skip
    cfg = replace(cfg, target_budget=None, references=None, cache=tmp_path)
    results = anytime.run(cfg, progress=False)
    assert calls == [("auto", 1.0, 1), ("auto", 1.0, 2), ("tabu", 1.0, 1), ("tabu", 1.0, 2)]
    assert [r["seed"] for r in results["rows"]] == [1, 2, 1, 2]
    assert [r["ratio"] for r in results["rows"]] == pytest.approx([1 / 1.1, 1 / 1.2] * 2)
    assert anytime.seeds_text(results["config"]).startswith("solver seeds 1-2")
    assert anytime.seeds_text({"base_seed": 0}) == "seed 0"  # runs from before the option


def test_worlds_are_derived_once_and_cached(tmp_path: Path) -> None:
    case = world_case("wh_two_lane", 10, 0, tmp_path)
    assert case is not None and case.ref_cost is None and case.problem.n_conflicts > 0
    (cached,) = (tmp_path / "worlds" / derivation_digest()).iterdir()
    again = world_case("wh_two_lane", 10, 0, tmp_path)
    assert again is not None and again.request == case.request
    assert json.loads(cached.read_text())["request"]["objective"] == "avg_completion"


def test_worlds_of_another_derivation_are_derived_again(tmp_path: Path) -> None:
    """A world cached by another derivation (another digest's folder, or the folder's
    layout before digests) is not read: its graph may be one the code no longer makes."""
    name = "wh_two_lane-10-0-avg_completion.json"
    stale = {"refused": "derived by older code"}
    for folder in (tmp_path / "worlds", tmp_path / "worlds" / "0123456789ab"):
        folder.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(json.dumps(stale))
    case = world_case("wh_two_lane", 10, 0, tmp_path)
    assert case is not None and case.name == "wh_two_lane/10/0"
    assert (tmp_path / "worlds" / derivation_digest() / name).exists()


def test_the_derivation_digest_follows_the_derivations_sources(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    digest = derivation_digest()
    assert len(digest) == 12 and derivation_digest.__wrapped__() == digest
    monkeypatch.setattr(cases, "DERIVATION_PACKAGES", ("scenarios", "geometry"))
    assert derivation_digest.__wrapped__() != digest


def test_quick_run_writes_everything(tmp_path: Path) -> None:
    out, cache = tmp_path / "out", tmp_path / "cache"
    assert main(["--quick", "--out", str(out), "--cache", str(cache)]) == 0
    for name in ("tables.md", "results.json", "results.csv", "anytime.png", "anytime-cost.png"):
        assert (out / name).stat().st_size > 0
    rows = json.loads((out / "results.json").read_text())["rows"]
    assert {r["method"] for r in rows} == set(QUICK.methods)
    assert {r["budget_s"] for r in rows} == set(QUICK.budgets)
    assert all(r["ratio"] <= 1 + 1e-9 for r in rows)
    assert any(not r["conformance"] for r in rows) and any(r["conformance"] for r in rows)
    tables = (out / "tables.md").read_text()
    assert all(f"`{m}` against issue 11's targets" in tables for m in ("auto", "auto_2cores"))
    assert main(["--quick", "--out", str(out), "--summarize"]) == 0  # re-renders from raw


def test_sets_posed_for_another_objective_take_the_milps_proof_as_reference(
    monkeypatch, tmp_path: Path
) -> None:
    """With --objective avg_delay a set's problem (an avg_completion one) is judged against
    the MILP backend's proven optimum (CP-SAT proves the same), its proof time the MILP's,
    cached by request; its own objective, or one the MILP does not model, leaves it as is."""
    cfg = replace(Config(), sets=("wh_25",), per_set=1, worlds=(), objective="avg_delay")
    (case,) = anytime.cases_of(cfg)
    assert case.objective == "avg_delay" and case.ref_cost is None
    cache = JsonCache(tmp_path / "refs.json")
    judged = anytime.with_milp_reference(case, cfg, cache)
    assert 0 < judged.ref_runtime_s <= anytime.MILP_REFERENCE_S
    ctx = SolveContext(case.problem, "avg_delay", 30.0)
    proven = solve(case.problem, case.cliques, "avg_delay", 30.0)
    assert proven is not None and proven.optimal
    assert judged.ref_cost == pytest.approx(ctx.cost(proven.assignment), rel=1e-6)
    monkeypatch.setattr(anytime, "solve_once", lambda *args: pytest.fail("not cached"))
    again = anytime.with_milp_reference(case, cfg, cache)
    assert (again.ref_cost, again.ref_runtime_s) == (judged.ref_cost, judged.ref_runtime_s)
    (own,) = anytime.cases_of(replace(cfg, objective=None))
    assert anytime.with_milp_reference(own, cfg, cache) is own and own.ref_cost is not None
    (sync,) = anytime.cases_of(replace(cfg, objective="sync_completion"))
    assert anytime.with_milp_reference(sync, cfg, cache).ref_cost is None
