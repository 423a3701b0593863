"""Stored labels: valid, costed by the evaluator, best first, and honest about proof and gap."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import find_cliques
from service.core.evaluate import Evaluator
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.datagen.labels import HINT_ABOVE_CONFLICTS, contexts, portfolio_hint, portfolio_labels
from service.learning.data import iter_problems
from service.motion.plan import derived_request
from service.scenarios import generate
from service.solvers.tabu import plain_start

GAP_TOL = 1e-6  # CP-SAT's bound is on integer-scaled times (TIME_DIGITS significant digits)


def _bits(text: str) -> np.ndarray:
    return np.array([c == "1" for c in text], dtype=bool)


def test_every_stored_target_is_valid_and_costed_by_the_evaluator(tiny_dataset: Path) -> None:
    for record in iter_problems(tiny_dataset):
        for objective, targets in record["targets"].items():
            request = ScheduleRequest.model_validate({**record["request"], "objective": objective})
            problem = problem_from_request(request)
            assert targets, (record["index"], objective)
            batch = Assignments(
                np.stack([_bits(t["a_first"]) for t in targets]),
                np.stack([_bits(t["following"]) for t in targets]),
            )
            assert check(problem, find_cliques(problem), batch).ok.all()
            # one at a time, as stored: a batch may sum in another order (last-bit changes)
            evaluate = Evaluator(problem).evaluate
            costs = [evaluate(batch.take(i)).costs[objective][0] for i in range(len(targets))]
            assert [t["cost"] for t in targets] == costs


def test_proof_and_gap_agree_and_targets_come_best_first(tiny_dataset: Path) -> None:
    for record in iter_problems(tiny_dataset):
        for targets in record["targets"].values():
            costs = [t["cost"] for t in targets]
            assert costs == sorted(costs)
            for t in targets:
                assert t["gap"] == 0.0 if t["optimal"] else t["gap"] is None or t["gap"] >= 0.0
            assert all(t["optimal"] for t in targets[:-1])  # enumeration stops at an unproven


def _context(kind: str, robots: int, seed: int, objective: str, time_limit_s: float):
    problem = problem_from_request(derived_request(generate(kind, robots, seed)))
    return contexts(problem, [objective], time_limit_s)[objective]


@pytest.mark.parametrize(
    ("kind", "robots", "seed", "objective"),
    [
        ("wh_two_way", 10, 3, "sync_completion"),
        ("wh_two_way", 12, 2006180987, "avg_completion"),
        ("wh_two_lane", 12, 1378039150, "sync_completion"),
    ],
)
def test_the_gap_bounds_the_distance_to_the_optimum(
    kind: str, robots: int, seed: int, objective: str
) -> None:
    (label,) = portfolio_labels(_context(kind, robots, seed, objective, 0.1), 1)
    (best,) = portfolio_labels(_context(kind, robots, seed, objective, 60.0), 1)
    assert best["optimal"]
    if label["optimal"]:
        assert label["cost"] == pytest.approx(best["cost"], rel=GAP_TOL)
    elif label["gap"] is not None:
        assert label["cost"] * (1 - label["gap"]) <= best["cost"] * (1 + GAP_TOL)


def test_large_problems_start_from_a_deterministic_search_hint() -> None:
    ctx = _context("wh_one_way", 20, 7, "avg_completion", 0.2)
    assert ctx.problem.n_conflicts > HINT_ABOVE_CONFLICTS
    hint, again = portfolio_hint(ctx), portfolio_hint(ctx)
    assert np.array_equal(hint.a_first, again.a_first)
    assert np.array_equal(hint.following, again.following)
    assert check(ctx.problem, ctx.cliques, hint).ok.all()
    hint_cost = ctx.evaluator.evaluate(hint).costs["avg_completion"][0]
    start_cost = ctx.evaluator.evaluate(plain_start(ctx)).costs["avg_completion"][0]
    assert hint_cost < start_cost  # the searches improved on the cheapest blend
    label = portfolio_labels(ctx, 3)[0]
    assert label["cost"] <= hint_cost
