"""Every solver honours fixed directions (a conflict's ``first``).

CP-SAT against the brute-force reference (which only enumerates directions
agreeing with the fixed ones), a property test over the whole registry on
random problems with random acyclic fixed directions, and the GNN-VAE's
sampled candidates (which go through the shared decoder).
"""

from __future__ import annotations

from pathlib import Path
from typing import get_args

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core.check import check
from service.core.decode import decode_candidates
from service.core.schemas import OBJECTIVES, SolverName
from service.learning.features import graph_tensors
from service.learning.generate import small_problem, stitched_problem
from service.learning.infer import propose
from service.learning.store import load_all
from service.solvers.dispatch import DispatchPolicy  # noqa: F401  (registers every solver)
from service.solvers.exact import solve
from service.solvers.registry import get_solver
from tests.reference import (
    costs,
    feasible_assignments,
    fix_directions,
    honours_fixed,
    least_times,
    reference_problem,
    tiny_request,
)
from tests.solvers.common import context

STORE = Path(__file__).resolve().parents[2] / "model_store"
MODELS, _ = load_all(STORE, OBJECTIVES)
TIME_LIMIT_S = 0.5
REL = 1e-9


@pytest.mark.parametrize("seed", range(30))
def test_exact_optimum_equals_brute_force_with_fixed_directions(seed: int) -> None:
    req = fix_directions(tiny_request(seed), seed)
    ref = reference_problem(req)
    candidates = feasible_assignments(ref)
    for objective in OBJECTIVES:
        ctx = context(req, objective)
        best = min(c.costs[objective] for c in candidates)
        result = solve(ctx.problem, ctx.cliques, objective, 30.0, seed=0, workers=1)
        assert result is not None and result.optimal, objective
        assert check(ctx.problem, ctx.cliques, result.assignment).ok[0]
        a_first = result.assignment.a_first[0].tolist()
        assert honours_fixed(ref, a_first)
        got = costs(ref, least_times(ref, a_first, result.assignment.following[0].tolist()))
        assert got[objective] == pytest.approx(best, rel=REL), objective


def test_fixed_directions_change_the_optimum_somewhere() -> None:
    """The brute-force set above is not vacuous: fixing directions cuts optima off."""
    worse = 0
    for seed in range(30):
        free = feasible_assignments(reference_problem(tiny_request(seed)))
        fixed = feasible_assignments(reference_problem(fix_directions(tiny_request(seed), seed)))
        worse += min(c.costs["avg_completion"] for c in fixed) > min(
            c.costs["avg_completion"] for c in free
        )
    assert worse >= 3


def _request(family: str, seed: int, robots: int) -> dict:
    if family == "tiny":
        return tiny_request(seed)
    if family == "small":
        return small_problem(seed)
    return stitched_problem(seed, robots, 3.0)


@pytest.mark.parametrize("name", sorted(set(get_args(SolverName)) - {"auto"}))
@settings(
    max_examples=4, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    family=st.sampled_from(["tiny", "small", "stitched"]),
    seed=st.integers(0, 10_000),
    robots=st.integers(2, 30),
    share=st.floats(0.1, 1.0),
    objective=st.sampled_from(OBJECTIVES),
)
def test_every_answer_honours_fixed_directions(
    name: str, family: str, seed: int, robots: int, share: float, objective: str
) -> None:
    req = fix_directions(_request(family, seed, robots), seed, share)
    ctx = context(req, objective, TIME_LIMIT_S, seed=seed, models=MODELS)
    out = get_solver(name)(ctx)
    if out is None:  # only CP-SAT may find nothing in time
        assert name == "exact"
        return
    checks = check(ctx.problem, ctx.cliques, out.assignment)
    assert checks.acyclic[0] and checks.density[0] and checks.forced[0]


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_every_gnn_vae_candidate_honours_fixed_directions(objective: str) -> None:
    """The learned model knows nothing of fixed directions; the shared decoder enforces them."""
    req = fix_directions(stitched_problem(5, 25, 3.0), 5, share=0.7)
    ctx = context(req, objective, TIME_LIMIT_S, models=MODELS)
    graph = graph_tensors(ctx.problem, ctx.cliques)
    bids, probs = propose(MODELS[objective].model, graph, 16, seed=0)  # (S, V), (S, M)
    ranks = ctx.decoder.ranks(bids)  # (S, V), before the repair
    _, first, second = ctx.problem.forced_arcs
    assert np.any(ranks[:, first] > ranks[:, second])  # the model alone breaks some
    candidates = decode_candidates(ctx.decoder, bids, probs, objective)
    assert check(ctx.problem, ctx.cliques, candidates).ok.all()
    out = get_solver("gnn_vae")(ctx)
    assert out is not None and out.model == MODELS[objective].name
    assert check(ctx.problem, ctx.cliques, out.assignment).ok[0]
