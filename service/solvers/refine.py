"""Local search in the decoder's input space, and the GNN-VAE refined by it.

:func:`refine` is a (1 + lambda) evolution strategy over node bids and
following scores: each round perturbs the incumbent's bids log-normally and
its scores normally (each candidate with its own step size, so small and
large moves are tried together), decodes every candidate with the shared
constraint-guaranteed decoder, evaluates them in one batched call, and keeps
the best. Every candidate is valid by construction, so the search never has
to repair anything. It stops at the time budget or after ``patience`` rounds
without improvement.

``gnn_vae_refined`` (the published "Ours*") starts it from the GNN-VAE's best
sample. Measured while designing it (stitched problems, avg_completion,
delay ratio against CP-SAT's best in 30 s): 50 robots sparse 0.57 -> 0.87,
dense 0.44 -> 0.79, 250 robots sparse 0.77 -> 0.92 with 0.5 s of search.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from service.core.assignment import Assignments
from service.core.decode import bids_from_ranks, decode_candidates
from service.learning.features import graph_tensors
from service.learning.infer import propose
from service.solvers.gnn_vae import DEFAULT_SAMPLES
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["RefineConfig", "gnn_vae_refined", "refine"]


@dataclass(frozen=True)
class RefineConfig:
    """Step sizes and stopping rules of the local search (chosen on stitched problems)."""

    population: int = 64  # lambda: candidates per round
    bid_step: float = 0.3  # largest log-std of the bid perturbation
    score_step: float = 0.2  # largest std of the score perturbation
    patience: int = 30  # rounds without improvement before stopping
    max_seconds: float = 1.0  # search budget (the request's time limit caps it too)


def refine(
    ctx: SolveContext,
    bids: np.ndarray,
    scores: np.ndarray,
    budget_s: float,
    cfg: RefineConfig = RefineConfig(),
) -> tuple[Assignments, float]:
    """Improve the assignment decoded from (bids (V,), scores (M,)) -> (best, its cost)."""
    rng = np.random.default_rng(ctx.seed)
    objective, decoder = ctx.objective, ctx.decoder
    best = decode_candidates(decoder, bids[None], scores[None], objective)
    costs = ctx.evaluator.evaluate(best).costs[objective]
    k = int(np.argmin(costs))
    best, best_cost = best.take(k), float(costs[k])
    deadline = time.perf_counter() + budget_s
    stale = 0
    while time.perf_counter() < deadline and stale < cfg.patience:
        step = rng.random((cfg.population, 1))  # (P, 1) each candidate's own step size
        cand_bids = bids * np.exp(rng.normal(0.0, cfg.bid_step, (cfg.population, bids.size)) * step)
        cand_scores = scores + rng.normal(0.0, cfg.score_step, (cfg.population, scores.size)) * step
        cand = decode_candidates(decoder, cand_bids, cand_scores, objective)
        costs = ctx.evaluator.evaluate(cand).costs[objective]
        k = int(np.argmin(costs))
        if costs[k] < best_cost:
            best, best_cost, stale = cand.take(k), float(costs[k]), 0
            row = k % cfg.population  # non-monotone objectives decode 2 candidates per row
            bids, scores = cand_bids[row], cand_scores[row]
        else:
            stale += 1
    return best, best_cost


@register("gnn_vae_refined")
def gnn_vae_refined(ctx: SolveContext) -> SolverOutput | None:
    """The GNN-VAE's best sample, improved by :func:`refine` within the time limit.

    The FCFS ranks join the samples as one more starting candidate: on large
    stitched problems the model's samples are sometimes worse than FCFS, and
    the search should never start below it.
    """
    stored = ctx.models.get(ctx.objective)
    if stored is None:
        return None
    start = time.perf_counter()
    samples = ctx.samples or DEFAULT_SAMPLES
    bids, probs = propose(stored.model, graph_tensors(ctx.problem, ctx.cliques), samples, ctx.seed)
    fcfs_bids = bids_from_ranks(ctx.problem, ctx.problem.node_enter + 1.0)  # (V,) enter >= 0
    bids = np.vstack([bids, fcfs_bids])  # (S+1, V)
    probs = np.vstack([probs, np.ones(ctx.problem.n_conflicts)])  # (S+1, M)
    candidates = decode_candidates(ctx.decoder, bids, probs, ctx.objective)
    costs = ctx.evaluator.evaluate(candidates).costs[ctx.objective]
    row = int(np.argmin(costs)) % (samples + 1)
    budget = min(RefineConfig.max_seconds, ctx.time_limit_s) - (time.perf_counter() - start)
    assignment, _ = refine(ctx, bids[row], probs[row], max(budget, 0.0))
    return SolverOutput(assignment, model=stored.name, samples=samples)
