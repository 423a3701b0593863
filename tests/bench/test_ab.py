"""bench.ab: settings parsed and applied, variants warmed and interleaved, the table's counts."""

from __future__ import annotations

import math

import pytest

import bench.ab as ab
from bench.ab import (
    Config,
    Setting,
    applied,
    paired_interval,
    parse_setting,
    runs_to_resolve,
    table,
)
from service.solvers import portfolio, turns
from service.solvers.turns import TurnsConfig


def test_a_setting_names_a_module_attribute_and_a_literal() -> None:
    s = parse_setting("service.solvers.portfolio.MID_LNS_SHARE = 0.8")
    assert s == Setting("service.solvers.portfolio", "MID_LNS_SHARE", 0.8)
    assert parse_setting("service.solvers.portfolio.PLANNED_ORDERS=(1, 2)").value == (1, 2)
    for bad in ("MID_LNS_SHARE=0.8", "service.solvers.portfolio.MID_LNS_SHARE",
                "service.solvers.portfolio.MID_LNS_SHARE=share",
                "service.solvers.portfolio.NO_SUCH_NAME=1"):  # fmt: skip
        with pytest.raises(ValueError, match="expected|literal|no attribute"):
            parse_setting(bad)


def test_settings_hold_for_the_run_and_are_restored_even_on_error() -> None:
    before = portfolio.MID_LNS_SHARE
    with applied([parse_setting("service.solvers.portfolio.MID_LNS_SHARE=0.123")]):
        assert portfolio.MID_LNS_SHARE == 0.123
    assert before == portfolio.MID_LNS_SHARE
    with pytest.raises(RuntimeError), applied([Setting(portfolio.__name__, "MID_LNS_SHARE", 7)]):
        raise RuntimeError
    assert before == portfolio.MID_LNS_SHARE


def test_a_dataclass_field_is_a_default_of_the_instances_made_while_it_holds() -> None:
    s = parse_setting("service.solvers.turns.TurnsConfig.turn_s=0.25")
    assert s == Setting("service.solvers.turns", "TurnsConfig.turn_s", 0.25)
    for bad in ("service.solvers.turns.TurnsConfig.no_such_field=1",
                "service.solvers.turns.take_turns.turn_s=1"):  # fmt: skip
        with pytest.raises(ValueError, match="no dataclass"):
            parse_setting(bad)
    before = (TurnsConfig().turn_s, turns.COOLED_SHARE)
    settings = [s, parse_setting("service.solvers.turns.TurnsConfig.turn_share=0.2"),
                parse_setting("service.solvers.turns.COOLED_SHARE=0.9")]  # fmt: skip
    with applied(settings):
        made = turns.TurnsConfig()
        assert (made.turn_s, made.turn_share) == (0.25, 0.2)
        assert turns.TurnsConfig(turn_s=1.0).turn_s == 1.0  # an explicit value still wins
        assert turns.COOLED_SHARE == 0.9
    assert turns.TurnsConfig is TurnsConfig
    assert (turns.TurnsConfig().turn_s, turns.COOLED_SHARE) == before


def _row(
    name: str, seed: int, variant: str, cost: float, ref: float = 10.0, optimal: bool = False
) -> dict:
    return {"name": name, "family": name.split("/")[0], "seed": seed, "variant": variant,
            "cost": cost, "free": 5.0, "ref_cost": ref, "optimal": optimal}  # fmt: skip


def test_the_table_counts_wins_and_measures_against_the_best_at_the_end() -> None:
    rows = [_row("w/0", 0, "A", 10.0, optimal=True), _row("w/0", 0, "B", 20.0, ref=20.0),
            _row("w/1", 0, "A", 30.0, ref=12.0), _row("w/1", 0, "B", 24.0, ref=12.0)]  # fmt: skip
    lines = table(rows).splitlines()
    (w,) = [line for line in lines if line.startswith("| w |")]
    # w/0: best 10 (A's run): A 1.0, B 0.5; delay (10 - 5) / (cost - 5): 1.0, 0.333. w/1:
    # best 12: A 0.4, B 0.5; delay 0.28, 0.368.
    # B - A: w/0 0.5 - 1.0, w/1 0.5 - 0.4: mean -0.2; two worlds bound no interval.
    assert w == "| w | 2 | 0.7000 / 0.640 | 0.5000 / 0.351 | -0.2000 | 1 / 1 | 1 / 0 |"
    assert any(line.startswith("| all | 2 |") for line in lines)


def test_the_table_bounds_b_minus_a_where_it_has_enough_worlds() -> None:
    # Six worlds, B cheaper by 10 % of the best on each, whose cost A sets: each gain
    # 10 / 9 - 1 (B at the best, A at 10 / 9 of it), so every resample reads the same.
    rows = [row for k in range(6) for row in (_row(f"w/{k}", 0, "A", 10.0),
                                              _row(f"w/{k}", 0, "B", 9.0))]  # fmt: skip
    (w,) = [line for line in table(rows).splitlines() if line.startswith("| w |")]
    assert "| -0.1000 (-0.1000, -0.1000) | 6 / 0 |" not in w  # A is the dearer one here
    assert "| +0.1000 (+0.1000, +0.1000) | 0 / 6 |" in w


def test_the_runs_to_resolve_a_gain_grow_with_the_square_of_the_spread() -> None:
    gains = [[0.01, -0.02], [0.03], [-0.01, 0.0], [0.02], [0.0, 0.01, 0.04]]
    low, high = paired_interval(gains)
    needed = runs_to_resolve(gains, 0.003)
    assert needed == pytest.approx(9 * ((high - low) / 2 / 0.003) ** 2)
    assert runs_to_resolve(gains, 0.006) == pytest.approx(needed / 4)  # twice the gain
    wider = [[2 * g for g in world] for world in gains]  # twice the spread
    assert runs_to_resolve(wider, 0.003) == pytest.approx(4 * needed)
    assert math.isnan(runs_to_resolve(gains[:4], 0.003))  # four worlds bound nothing


def test_the_table_says_how_many_runs_would_bound_a_small_gain() -> None:
    costs = [(10.0, 9.0), (10.0, 10.5), (10.0, 9.8), (10.0, 10.1), (10.0, 9.6), (10.0, 10.0)]
    rows = [
        row
        for k, (a, b) in enumerate(costs)
        for row in (_row(f"w/{k}", 0, "A", a), _row(f"w/{k}", 0, "B", b))
    ]
    best = [min(a, b) for a, b in costs]  # each world's best is one of its two runs
    gains = [[best[k] / b - best[k] / a] for k, (a, b) in enumerate(costs)]  # B - A
    expected = math.ceil(runs_to_resolve(gains))
    last = table(rows).splitlines()[-1]
    assert last.endswith(f"~{expected} runs.") and "0.003" in last
    assert "runs." not in table(rows[:4])  # two worlds: no interval, no count


def test_the_interval_resamples_worlds_and_holds_the_mean() -> None:
    assert all(math.isnan(x) for x in paired_interval([[0.1], [0.2], [], [0.3], [0.4]]))
    one_world_many_seeds = [[0.05] * 20] + [[0.0]] * 4  # five worlds, one run each but one
    low, high = paired_interval(one_world_many_seeds)
    # Worlds resampled, the many-seeded world is left out of a third of the resamples (4/5
    # to the fifth): the interval reaches 0. Runs resampled as if each were a world of its
    # own read 20 of 24 runs at 0.05 nearly every time: a narrow interval around 0.042.
    assert low == 0.0 and 0.045 < high < 0.05
    runs_low, runs_high = paired_interval([[g] for world in one_world_many_seeds for g in world])
    assert 0.03 < runs_low < runs_high < 0.05
    gains = [[0.01, -0.02], [0.03], [-0.01, 0.0], [0.02], [0.0, 0.01, 0.04]]
    low, high = paired_interval(gains)
    every = [g for world in gains for g in world]
    assert low < sum(every) / len(every) < high
    assert paired_interval(gains) == (low, high)  # a fixed resampling seed


def test_variants_run_back_to_back_their_order_alternating(monkeypatch, tmp_path) -> None:
    seen: list[tuple[str, float]] = []

    def fake(method, case, budget, cfg, policy, seed=None):
        seen.append((case.name, portfolio.MID_LNS_SHARE))
        return {"name": case.name, "family": case.family, "seed": seed, "cost": 10.0,
                "optimal": False, "free": 1.0}  # fmt: skip

    class FakeCase:
        def __init__(self, name: str) -> None:
            self.name, self.family, self.ref_cost, self.free = name, "f", None, 1.0

    cases = [FakeCase("w/0"), FakeCase("w/1")]
    monkeypatch.setattr(ab, "world_cases", lambda *a, **k: cases)
    monkeypatch.setattr(ab, "service_policy", lambda store: None)
    warmed: list[float] = []
    monkeypatch.setattr(ab.anytime, "warm_up", lambda *a: warmed.append(portfolio.MID_LNS_SHARE))
    monkeypatch.setattr(ab.anytime, "run_method", fake)
    monkeypatch.setattr(ab, "request_key", lambda *a: "key")
    a, b = (
        "service.solvers.portfolio.MID_LNS_SHARE=0.1",
        "service.solvers.portfolio.MID_LNS_SHARE=0.2",
    )
    results = ab.run(Config(a=(a,), b=(b,), solver_seeds=2, references=None), progress=False)
    assert warmed == [0.1, 0.2]  # each variant warmed up with its settings
    assert seen == [("w/0", 0.1), ("w/0", 0.2), ("w/1", 0.2), ("w/1", 0.1)] * 2
    assert [r["variant"] for r in results["rows"]] == ["A", "B", "B", "A"] * 2
    assert portfolio.MID_LNS_SHARE not in (0.1, 0.2)


def test_the_portfolio_compared_is_the_configured_one(monkeypatch) -> None:
    """``--method auto_2cores`` runs and warms up that portfolio (both cores for a solve)."""

    class FakeCase:
        name, family, ref_cost, free = "w/0", "w", None, 1.0

    methods: list[str] = []
    warmed: list[tuple[str, ...]] = []
    monkeypatch.setattr(ab, "world_cases", lambda *a, **k: [FakeCase()])
    monkeypatch.setattr(ab, "service_policy", lambda store: None)
    monkeypatch.setattr(ab.anytime, "warm_up", lambda cfg, *a: warmed.append(cfg.methods))
    monkeypatch.setattr(ab, "request_key", lambda *a: "key")
    monkeypatch.setattr(
        ab.anytime, "run_method",
        lambda method, case, budget, cfg, policy, seed=None: methods.append(method) or {
            "name": case.name, "family": case.family, "seed": seed, "cost": 10.0,
            "optimal": False, "free": 1.0},
    )  # fmt: skip
    ab.run(Config(method="auto_2cores", solver_seeds=1, references=None), progress=False)
    assert methods == ["auto_2cores"] * 2 and warmed == [("auto_2cores",)] * 2
    assert ab._parse_args(["--method", "auto_2cores"]).method == "auto_2cores"
    with pytest.raises(SystemExit):
        ab._parse_args(["--method", "exact"])


def test_conformance_sets_come_first_measured_against_their_optima(monkeypatch) -> None:
    class FakeCase:
        def __init__(self, name: str, ref_cost: float | None) -> None:
            self.name, self.family, self.ref_cost, self.free = name, name[0], ref_cost, 1.0

    asked: list[tuple] = []

    def sets(names, per_set=None, objective=None):
        asked.append((tuple(names), objective))
        return [FakeCase("c/0", 8.0)]

    monkeypatch.setattr(ab, "conformance_cases", sets)
    monkeypatch.setattr(ab, "world_cases", lambda *a, **k: [FakeCase("w/0", None)])
    monkeypatch.setattr(ab, "service_policy", lambda store: None)
    monkeypatch.setattr(ab.anytime, "warm_up", lambda *a: None)
    monkeypatch.setattr(ab, "request_key", lambda *a: "key")
    monkeypatch.setattr(
        ab.anytime, "run_method",
        lambda method, case, budget, cfg, policy, seed=None: {
            "name": case.name, "family": case.family, "seed": seed, "cost": 10.0,
            "optimal": False, "free": 1.0},
    )  # fmt: skip
    results = ab.run(Config(sets=("wh_25",), solver_seeds=1, references=None), progress=False)
    assert asked == [(("wh_25",), "avg_completion")]
    assert [r["name"] for r in results["rows"]] == ["c/0", "c/0", "w/0", "w/0"]
    assert [r["ratio"] for r in results["rows"][:2]] == [0.8, 0.8]  # against the optimum
