"""bench.milp: the quick run end to end, and how proofs are counted."""

from __future__ import annotations

import json
from pathlib import Path

from bench.milp import QUICK, main, summary_rows


def _row(backend: str, proven: bool, wrong: bool, seconds: float) -> dict:
    return {
        "backend": backend, "family": "wh_25", "name": "x", "proven": proven,
        "wrong_proof": wrong, "seconds": seconds, "ratio": 1.0, "ref_runtime_s": 2.0,
    }  # fmt: skip


def test_a_proof_counts_only_within_its_mark_and_a_wrong_one_never() -> None:
    rows = [
        _row("cpsat", True, False, 0.5),
        _row("cpsat", False, True, 0.2),  # claimed optimal at a cost above the optimum
        _row("milp", True, False, 2.5),
        _row("milp", False, False, 10.0),
    ]
    table = {(r[0], r[1]): r for r in summary_rows(rows, (1.0, 3.0))}
    assert table[("wh_25", "cpsat")][3:6] == ["50 %", "50 %", "1.0000"]
    assert table[("wh_25", "cpsat")][6] == 1  # the wrong proof, counted apart
    assert table[("wh_25", "milp")][3:5] == ["0 %", "50 %"]
    assert table[("all", "milp")][2] == 2


def test_quick_run_writes_its_tables(tmp_path: Path) -> None:
    out = tmp_path / "milp"
    assert main(["--quick", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    rows = results["rows"]
    assert {r["backend"] for r in rows} == {"cpsat", "milp"}
    assert len(rows) == 2 * QUICK.per_set
    assert all(r["proven"] and not r["wrong_proof"] for r in rows)  # wh_25: both prove fast
    assert (out / "milp.png").exists() and "proven <= 1 s" in (out / "tables.md").read_text()
    assert main(["--quick", "--out", str(out), "--summarize"]) == 0
