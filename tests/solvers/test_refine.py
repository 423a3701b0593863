"""gnn_vae_refined: valid, never worse than its starting points, deterministic for a seed;
both model solvers without samples where the least model request outlasts the limit (refined:
more than a share of it)."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.core.assignment import Assignments
from service.core.check import check
from service.learning.generate import stitched_problem
from service.learning.store import load_all
from service.solvers.fcfs import fcfs
from service.solvers.gnn_vae import embed_fits, gnn_vae, least_request_s
from service.solvers.refine import (
    PLANNED_SAMPLES_LEAST_SHARE,
    SAMPLES_LEAST_SHARE,
    gnn_vae_refined,
)
from service.solvers.registry import SolveContext, SolverOutput
from service.solvers.tabu import plain_start
from tests.solvers.common import context, cost

STORE = Path(__file__).resolve().parents[2] / "model_store"


@pytest.fixture(scope="module")
def models() -> dict:
    loaded, errors = load_all(STORE, ("avg_completion", "sync_completion"))
    assert not errors
    return loaded


def _ctx(seed: int, objective: str, models: dict, time_limit_s: float = 30.0) -> SolveContext:
    return context(stitched_problem(seed, 30, 3.0), objective, time_limit_s, seed=1, models=models)


@pytest.mark.parametrize("objective", ["avg_completion", "sync_completion"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refined_is_valid_and_never_worse(seed: int, objective: str, models: dict) -> None:
    ctx = _ctx(seed, objective, models)
    out = gnn_vae_refined(ctx)
    assert out is not None and out.model is not None
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.all()
    refined = cost(ctx, out)
    assert refined <= cost(ctx, fcfs(ctx)) + 1e-9
    assert refined <= cost(ctx, gnn_vae(ctx)) + 1e-9


def test_refined_is_deterministic_when_tabu_ends_by_patience(models: dict) -> None:
    first, again = (gnn_vae_refined(_ctx(4, "avg_completion", models)) for _ in range(2))
    assert "tabu iterations" in first.detail
    assert (first.assignment.a_first == again.assignment.a_first).all()
    assert (first.assignment.following == again.assignment.following).all()


def test_refined_without_a_model_has_no_answer() -> None:
    assert gnn_vae_refined(_ctx(0, "avg_completion", {})) is None


def test_a_limit_below_the_least_model_request_gets_no_samples(models: dict) -> None:
    least = least_request_s(_ctx(0, "avg_completion", models))
    short = _ctx(0, "avg_completion", models, time_limit_s=0.9 * least)
    assert not embed_fits(short, short.time_limit_s)
    assert gnn_vae(short) is None  # the dispatcher falls back
    _assert_refined_without_samples(short)


def _assert_refined_without_samples(ctx: SolveContext) -> None:
    refined = gnn_vae_refined(ctx)
    assert refined is not None and refined.samples == 0
    assert "too large for the model" in refined.detail
    assert check(ctx.problem, ctx.cliques, refined.assignment).ok.all()


@pytest.mark.parametrize("planned", [False, True])
def test_refined_samples_only_where_the_least_model_request_is_a_small_share(
    planned: bool, models: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A quarter of the budget; where the draws are also planned, half."""
    from service.solvers import gnn_vae as gnn

    if planned:
        monkeypatch.setattr(gnn, "PLANNED_MIN_CONFLICTS", 0)
    least = least_request_s(_ctx(0, "avg_completion", models))
    enough = least / (PLANNED_SAMPLES_LEAST_SHARE if planned else SAMPLES_LEAST_SHARE)
    _assert_refined_without_samples(_ctx(0, "avg_completion", models, 0.9 * enough))
    refined = gnn_vae_refined(_ctx(0, "avg_completion", models, 1.1 * enough))
    assert refined is not None and refined.samples >= 1


def test_a_limit_at_the_least_model_request_samples(models: dict) -> None:
    ctx = _ctx(0, "avg_completion", models)
    fits = _ctx(0, "avg_completion", models, time_limit_s=least_request_s(ctx))
    assert embed_fits(fits, fits.time_limit_s)
    out = gnn_vae(fits)
    assert out is not None and out.samples >= 1


def test_refined_starts_from_a_plan_in_the_draws_orders_where_cheaper(
    models: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    """From PLANNED_MIN_CONFLICTS conflicts the model's start is the cheaper of its best
    draw and the plans in its draws' orders; tabu never ends above its start."""
    from service.solvers import gnn_vae as gnn
    from service.solvers import refine

    monkeypatch.setattr(gnn, "PLANNED_MIN_CONFLICTS", 0)
    starts: list[float] = []

    def spied(ctx: SolveContext, sampled: object, deadline: float, descend: bool) -> tuple:
        answer, replaced = gnn.model_answer(ctx, sampled, deadline, descend)
        starts.append(float(ctx.evaluator.evaluate(answer).costs[ctx.objective][0]))
        assert starts[-1] <= sampled.cost
        return answer, replaced

    monkeypatch.setattr(refine, "model_answer", spied)
    ctx = _ctx(5, "avg_completion", models)
    out = gnn_vae_refined(ctx)
    assert out is not None and out.samples >= 1 and len(starts) == 1
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.all()
    assert cost(ctx, out) <= starts[0] + 1e-9


@pytest.mark.parametrize("seed", [5, 6])
def test_where_plans_serve_tabu_runs_from_the_cheaper_start_alone(
    seed: int, models: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the draws are also planned, tabu runs once, from the cheaper of the model's
    start and FCFS (so the answer is never dearer than either); elsewhere from both."""
    from service.solvers import gnn_vae as gnn
    from service.solvers import refine

    searched: list[float] = []  # the cost of each start tabu ran from
    model_starts: list[float] = []
    real_tabu, real_start = refine.tabu_search, refine.model_answer

    def tabu(ctx: SolveContext, start: Assignments, **kwargs: object) -> tuple:
        searched.append(cost(ctx, SolverOutput(start)))
        return real_tabu(ctx, start, **kwargs)

    def model_start(ctx: SolveContext, sampled: object, deadline: float, descend: bool) -> tuple:
        answer, replaced = real_start(ctx, sampled, deadline, descend)
        model_starts.append(cost(ctx, SolverOutput(answer)))
        return answer, replaced

    monkeypatch.setattr(refine, "tabu_search", tabu)
    monkeypatch.setattr(refine, "model_answer", model_start)
    ctx = _ctx(seed, "avg_completion", models)
    assert gnn_vae_refined(ctx) is not None and len(searched) == 2  # not planned: both
    searched.clear()
    model_starts.clear()
    monkeypatch.setattr(gnn, "PLANNED_MIN_CONFLICTS", 0)
    out = gnn_vae_refined(ctx)
    assert out is not None and out.samples >= 1 and "the cheaper of it and FCFS" in out.detail
    fcfs_start = cost(ctx, SolverOutput(plain_start(ctx)))
    assert len(searched) == 1 and len(model_starts) == 1
    assert searched[0] == min(model_starts[0], fcfs_start)
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.all()
    assert cost(ctx, out) <= searched[0] + 1e-9


@pytest.mark.parametrize(("share", "descends"), [(1.0, True), (0.0, False)])
def test_the_model_start_is_descended_only_where_the_least_request_is_small(
    share: float, descends: bool, models: dict, monkeypatch: pytest.MonkeyPatch
) -> None:
    """From PLANNED_MIN_CONFLICTS conflicts the model's start gets types by descent only
    where the least model request takes at most DESCENT_LEAST_SHARE of the budget."""
    from service.solvers import gnn_vae as gnn
    from service.solvers import refine

    asked: list[bool] = []
    real_start = refine.model_answer

    def model_start(ctx: SolveContext, sampled: object, deadline: float, descend: bool) -> tuple:
        asked.append(descend)
        return real_start(ctx, sampled, deadline, descend)

    monkeypatch.setattr(gnn, "PLANNED_MIN_CONFLICTS", 0)
    monkeypatch.setattr(refine, "DESCENT_LEAST_SHARE", share)
    monkeypatch.setattr(refine, "model_answer", model_start)
    out = gnn_vae_refined(_ctx(5, "avg_completion", models))
    assert out is not None and asked == [descends]
