"""CMA-ES in the decoder's input space, started from FCFS.

The search variable is x = [log bid multipliers (V), score offsets (M)]:
a candidate's bids are the FCFS bids times exp(x[:V]) and its scores are the
FCFS scores, normalised to [0, 1], plus x[V:]. Both blocks are then on a
scale of about one, so one step size ``sigma0`` fits both; x = 0, the mean
the search starts from, decodes to FCFS's order. Every candidate goes through the shared
constraint-guaranteed decoder, so the search is unconstrained and never has
to repair anything; the decoded cost is piecewise constant in x, which CMA-ES
(rank-based, derivative-free) tolerates.

Each generation asks cma for a population, decodes all of it in one batch,
evaluates it in one batched call and tells the costs back. For
sync_completion each x decodes to two assignments (see
:func:`decode_candidates`) and its fitness is the cheaper one. The best
assignment ever evaluated is kept, not cma's mean, and the FCFS assignment is
evaluated first, so the answer is never worse than FCFS.

Above ``full_covariance_max_dim`` dimensions the covariance is diagonal
(sep-CMA-ES): the full matrix costs O(n^2) per sample and O(n^3) per
decomposition, infeasible at the thousands of dimensions of large problems.
Measured on stitched problems of 10 to 80 robots (both objectives), full
covariance gave the same costs (mean ratio to FCFS 0.935 vs 0.936) in over
100 times the time. ``sigma0`` = 0.1 had the best mean ratio to FCFS of 0.02,
0.05, 0.1 and 0.3 over stitched problems of 20, 80 and 250 robots (0.951
against 0.955 for 0.3, which on 250 robots changes too many conflicts at once
and barely beats FCFS).

Stops at the evaluation budget or at the time limit (checked each
generation). When cma's own termination criteria end a run early (on these
piecewise-constant costs usually flat fitness, once the step is too small to
change any decision), it restarts from the best point found with twice the
population (IPOP-CMA-ES), so the budget is used rather than left idle.
Deterministic for ``ctx.seed`` unless it is the time limit that stops it.
cma samples from a private generator seeded with ``ctx.seed``, never from
numpy's global one, so concurrent requests cannot disturb each other.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cma
import numpy as np

from service.core.assignment import Assignments
from service.core.decode import bids_from_ranks, decode_candidates
from service.solvers.fcfs import fcfs, fcfs_priorities
from service.solvers.pace import Pace
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["CmaesConfig", "cmaes", "cmaes_search"]

# |log bid multiplier| is clipped here so that bids stay positive and finite however
# far cma's step size grows; a factor of e^30 already reorders any two nodes.
LOG_BID_LIMIT = 30.0


@dataclass(frozen=True)
class CmaesConfig:
    """Step size, population and stopping rules."""

    sigma0: float = 0.1  # initial step size in x (log bid factor, normalised score)
    popsize: int | None = None  # None: cma's default 4 + 3 ln(n)
    max_evaluations: int = 20_000  # x points evaluated (the last generation may overrun)
    full_covariance_max_dim: int = 100  # larger problems use a diagonal covariance


def _start(ctx: SolveContext) -> tuple[np.ndarray, np.ndarray]:
    """FCFS bids (V,) > 0 and FCFS following scores normalised to [0, 1] (M,), M > 0."""
    problem = ctx.problem
    ranks, scores = fcfs_priorities(problem)
    bids = bids_from_ranks(problem, ranks + 1.0)  # ranks >= 0; bids must be positive
    span = np.ptp(scores)
    return bids, (scores - scores.min()) / span if span > 0 else np.zeros_like(scores)


def cmaes_search(
    ctx: SolveContext, cfg: CmaesConfig = CmaesConfig()
) -> tuple[Assignments, float, int]:
    """CMA-ES from FCFS -> (best assignment, its cost, points evaluated incl. FCFS)."""
    pace = Pace(time.perf_counter() + ctx.time_limit_s)
    objective, n_nodes = ctx.objective, ctx.problem.n_nodes
    best = fcfs(ctx).assignment
    best_cost = float(ctx.evaluator.evaluate(best).costs[objective][0])
    if ctx.problem.n_conflicts == 0:  # nothing to decide
        return best, best_cost, 1
    bids0, scores0 = _start(ctx)
    dim = n_nodes + ctx.problem.n_conflicts
    rng = np.random.default_rng(ctx.seed)
    options: dict[str, object] = {
        "seed": np.nan,  # leave numpy's global generator alone: cma samples through randn
        "randn": lambda n, d: rng.standard_normal((n, d)),
        "verbose": -9,  # no output, no log files (one diagnostic UserWarning remains: pyproject)
        "CMA_diagonal": dim > cfg.full_covariance_max_dim,
    }
    best_x, evaluated, popsize = np.zeros(dim), 1, cfg.popsize
    # A generation starts only where one as long as the last (twice as long after a
    # restart, whose population doubles) ends in time: at 250 robots one takes 0.2-0.35 s,
    # and 0.5-s requests ran 0.78-0.92 s.
    scale = 1.0
    while evaluated < cfg.max_evaluations and pace.fits(scale):
        if popsize is not None:
            options["popsize"] = popsize
        options["maxfevals"] = cfg.max_evaluations - evaluated
        es = cma.CMAEvolutionStrategy(best_x, cfg.sigma0, options)
        if es.stop():  # nothing left to run (never expected: maxfevals > 0)
            break
        while not es.stop() and pace.fits(scale):
            began = pace.clock()
            solutions = es.ask()
            x = np.asarray(solutions)  # (P, V + M)
            log_factor = np.clip(x[:, :n_nodes], -LOG_BID_LIMIT, LOG_BID_LIMIT)  # (P, V)
            scores = scores0 + x[:, n_nodes:]  # (P, M)
            bids = bids0 * np.exp(log_factor)  # (P, V)
            candidates = decode_candidates(ctx.decoder, bids, scores, objective)
            costs = ctx.evaluator.evaluate(candidates).costs[objective]  # (P,) or (2P,)
            k = int(np.argmin(costs))
            if costs[k] < best_cost:
                best, best_cost = candidates.take(k), float(costs[k])
                best_x = x[k % len(solutions)]
            fitness = costs.reshape(-1, len(solutions)).min(axis=0)  # (P,) rows k, k+P share x_k
            es.tell(solutions, fitness.tolist())
            evaluated += len(solutions)
            pace.record(began)
            scale = 1.0
        popsize = 2 * es.popsize  # IPOP: each restart doubles the population
        scale = 2.0
    return best, best_cost, evaluated


@register("cmaes")
def cmaes(ctx: SolveContext) -> SolverOutput:
    """CMA-ES from FCFS within the request's time limit; ``samples`` = points evaluated.

    ``ctx.samples`` is not used: the population and budget are :class:`CmaesConfig`'s.
    """
    best, _, evaluated = cmaes_search(ctx)
    return SolverOutput(best, samples=evaluated)
