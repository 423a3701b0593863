"""gnn_vae_exact: CP-SAT hinted with the GNN-VAE's answer."""

from __future__ import annotations

from pathlib import Path

import pytest

from service.core.check import check
from service.learning.generate import stitched_problem
from service.learning.store import load_all
from service.solvers.exact import exact
from service.solvers.hybrid import gnn_vae_exact
from service.solvers.refine import gnn_vae_refined
from service.solvers.registry import SolveContext
from tests.solvers.common import context, cost

STORE = Path(__file__).resolve().parents[2] / "model_store"


@pytest.fixture(scope="module")
def models() -> dict:
    loaded, errors = load_all(STORE, ("avg_completion",))
    assert not errors
    return loaded


def _ctx(robots: int, density: float, limit: float, models: dict) -> SolveContext:
    return context(stitched_problem(7, robots, density), "avg_completion", limit, models=models)


def test_proves_the_optimum_where_cp_sat_can(models: dict) -> None:
    ctx = _ctx(10, 2.0, 30.0, models)
    out = gnn_vae_exact(ctx)
    assert out.optimal and out.model is not None
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.all()
    plain = exact(_ctx(10, 2.0, 30.0, models))
    assert plain.optimal
    assert cost(ctx, out) == pytest.approx(cost(ctx, plain))


def test_never_worse_than_the_refined_answer_it_starts_from(models: dict) -> None:
    ctx = _ctx(30, 4.0, 3.0, models)
    out = gnn_vae_exact(ctx)
    assert check(ctx.problem, ctx.cliques, out.assignment).ok.all()
    refined = gnn_vae_refined(_ctx(30, 4.0, 3.0, models))  # ends by patience, well within 1 s
    assert cost(ctx, out) <= cost(ctx, refined) + 1e-9


def test_without_a_model_it_has_no_answer() -> None:
    assert gnn_vae_exact(_ctx(10, 2.0, 5.0, {})) is None
