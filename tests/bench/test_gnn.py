"""bench.gnn: small problems paired against a baseline run."""

from __future__ import annotations

import numpy as np
import pytest

from bench.gnn import SAMPLE_COUNTS, paired_lines


def _rows(objective: str, costs: list[float], opt: list[float]) -> list[dict]:
    return [
        {"set": "held-out", "objective": objective, "opt": o, "free": 0.5 * o}
        | {f"gnn{s}": c for s in SAMPLE_COUNTS}
        for c, o in zip(costs, opt, strict=True)
    ]


def test_differences_are_paired_by_problem_with_their_standard_error() -> None:
    opt = [1.0, 2.0, 4.0]
    base = _rows("avg_completion", [1.25, 2.0, 5.0], opt)  # ratios 0.8, 1.0, 0.8
    mine = _rows("avg_completion", [1.0, 2.5, 5.0], opt)  # ratios 1.0, 0.8, 0.8
    line = paired_lines(mine, base)[1]
    diff = np.array([0.2, -0.2, 0.0])
    se = diff.std(ddof=1) / np.sqrt(3)
    assert f"0.8667, +0.00000 +- {se:.5f}" in line
    # avg_delay: minus the gap, so a smaller gap is a positive difference.
    gaps = paired_lines(
        _rows("avg_delay", [1.0, 2.0, 4.0], opt), _rows("avg_delay", [1.5, 2.0, 4.5], opt)
    )
    assert "+0.33333" in gaps[1]


def test_a_baseline_of_other_problems_is_refused() -> None:
    with pytest.raises(ValueError, match="other held-out"):
        paired_lines(_rows("avg_completion", [1.0], [1.0]), _rows("avg_completion", [1.0], [2.0]))
