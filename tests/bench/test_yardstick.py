"""bench.yardstick: runs re-rated on every run's best cost, on the problems all measured."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from bench.yardstick import load_runs, main, table, yardsticks


def _row(name: str, cost: float, **more: Any) -> dict[str, Any]:
    family = name.rsplit("/", 1)[0]
    row = {"name": name, "family": family, "method": "auto", "budget_s": 1.0, "cost": cost}
    return {"free": 10.0, "ref_cost": None, "conformance": False, **row, **more}


def _write(path: Path, rows: list[dict[str, Any]]) -> Path:
    path.write_text(json.dumps({"rows": rows}))
    return path


def test_each_problem_is_rated_against_the_least_cost_any_run_or_reference_knows(
    tmp_path: Path,
) -> None:
    before = _write(tmp_path / "a.json", [_row("wh_two_way 100/0", 20.0, ref_cost=14.0)])
    after = _write(tmp_path / "b.json", [_row("wh_two_way 100/0", 15.0)])
    runs = load_runs([before, after])
    assert yardsticks(runs) == {("wh_two_way 100/0", 10.0): 14.0}
    line = next(x for x in table(runs).splitlines() if "| wh_two_way 100 |" in x)
    # 14 / 20 and (14 - 10) / (20 - 10); 14 / 15 and 4 / 5
    assert line.endswith("| 1 | 0.7000 / 0.400 | 0.9333 / 0.800 |")
    assert line.startswith("| warehouse |")


def test_only_problems_every_run_measured_at_a_budget_count(tmp_path: Path) -> None:
    one = _write(tmp_path / "a.json", [_row("wh_25/0", 12.0), _row("wh_25/1", 30.0)])
    two = _write(tmp_path / "b.json", [_row("wh_25/0", 12.0), _row("wh_25/1", 11.0, budget_s=5.0)])
    text = table(load_runs([one, two]))
    assert "| wh_25 | 1 s | 1 | 1.0000 / 1.000 | 1.0000 / 1.000 |" in text
    assert "5 s" not in text  # wh_25/1 at 5 s: the first run never measured it
    # the same name, another world (its free cost): not the same problem
    anew = _write(tmp_path / "c.json", [_row("wh_25/0", 9.0, free=8.0)])
    assert "| wh_25 |" not in table(load_runs([one, anew]))


def test_variants_and_methods_of_one_file_are_runs_of_their_own(tmp_path: Path) -> None:
    rows = [_row("geo_dense_25/0", 12.0, variant="A", conformance=True, ref_cost=11.0)]
    rows += [_row("geo_dense_25/0", 11.0, variant="B", conformance=True, ref_cost=11.0)]
    rows += [_row("geo_dense_25/0", 14.0, variant="B", method="fcfs", conformance=True)]
    runs = load_runs([_write(tmp_path / "rows.json", rows)])
    assert sorted(runs) == [f"{tmp_path / 'rows.json'} {m} {v}" for m, v in
                            (("auto", "A"), ("auto", "B"), ("fcfs", "B"))]  # fmt: skip
    assert "| dense geometric | all conformance | 1 s | 1 |" in table(runs)


def test_the_cli_prints_and_writes_the_table(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = _write(tmp_path / "a.json", [_row("floor_sparse 50/0", 12.0)])
    assert main([str(run), "--out", str(tmp_path / "t.md")]) == 0
    printed = capsys.readouterr().out
    assert "| other | floor_sparse 50 | 1 s | 1 | 1.0000 / 1.000 |" in printed
    assert (tmp_path / "t.md").read_text() == printed
