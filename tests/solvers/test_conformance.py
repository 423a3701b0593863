"""Conformance: the exact solver reaches every reference optimum; no solver beats it.

The reference costs (``tests/data/conformance``) come from an independent
implementation of the contract (a MILP solved to proven optimality). Costs of
our answers are always the shared evaluator's, never the solver's own value.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from service.core.check import check
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.solvers.exact import solve
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext

DATA = Path(__file__).resolve().parents[1] / "data" / "conformance"
SETS = ("small", "geo_10")
# Generous: the slowest line takes ~30 ms; a hit limit would show as optimal=False.
TIME_LIMIT_S = 60.0
REL_TOL = 1e-6


def _lines() -> list[dict[str, Any]]:
    return [
        json.loads(line)
        for name in SETS
        for line in (DATA / f"{name}.jsonl").read_text().splitlines()
        if line.strip()
    ]


LINES = _lines()


def test_every_line_is_here() -> None:
    manifest = json.loads((DATA / "MANIFEST.json").read_text())
    assert len(LINES) == sum(manifest["sets"][name]["lines"] for name in SETS)
    assert all(line["ref_optimal"] for line in LINES)


@pytest.mark.parametrize("line", LINES, ids=[line["name"] for line in LINES])
def test_exact_reaches_reference_and_fcfs_never_beats_it(line: dict[str, Any]) -> None:
    request = ScheduleRequest.model_validate(line["request"])
    ctx = SolveContext(problem_from_request(request), request.objective, TIME_LIMIT_S)
    ref = line["ref_cost"]

    result = solve(ctx.problem, ctx.cliques, ctx.objective, TIME_LIMIT_S, seed=0, workers=1)
    assert result is not None
    assert result.optimal
    assert check(ctx.problem, ctx.cliques, result.assignment).ok.tolist() == [True]
    cost = float(ctx.evaluator.evaluate(result.assignment).costs[ctx.objective][0])
    assert cost == pytest.approx(ref, rel=REL_TOL)

    answer = fcfs(ctx).assignment
    assert check(ctx.problem, ctx.cliques, answer).ok.tolist() == [True]
    fcfs_cost = float(ctx.evaluator.evaluate(answer).costs[ctx.objective][0])
    assert fcfs_cost >= ref * (1 - REL_TOL)
