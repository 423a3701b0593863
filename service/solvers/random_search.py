"""Random search: the uninformed baseline every search method should beat.

Draws node bids and following scores independently of the problem, decodes
them with the shared constraint-guaranteed decoder (so every sample is valid),
evaluates them in batches with the batched evaluator and keeps the cheapest.
It tells how much of another solver's quality comes from its search or model
rather than from the decoder alone.

Distributions: bids ~ U(0, 1] i.i.d. per node (strictly positive, as the
decoder requires; each node's rank is then a sum of uniforms along its robot's
path, so earlier nodes of a path tend to pass first), scores ~ U[0, 1) i.i.d.
per conflict (a random greedy priority; for sync_completion, whose decoder
variant only takes scores above 0.5, each conflict is a following candidate
with probability 1/2). Exponential and log-uniform bids gave about the same
best of 100 samples on stitched 20-robot problems (none won on every one),
and uniform ones need no guard against drawing exactly zero.

Samples: ``ctx.samples`` input rows (``DEFAULT_SAMPLES`` if unset), drawn ``BATCH``
at a time and decoded and evaluated in chunks: the first row alone, then as many rows
as the time left holds at the last chunk's pace, so the time limit holds even where a
row takes milliseconds (at 250 robots a batch of 64 took 0.58 s, and a 0.05-s request
ran that long); the first row always runs. Rows are drawn whole batches at a time, so
which rows are drawn does not depend on timing: deterministic for ``ctx.seed`` when it
stops on its sample count.
"""

from __future__ import annotations

import time

import numpy as np

from service.core.assignment import Assignments
from service.core.decode import decode_candidates
from service.solvers.pace import Pace
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["BATCH", "DEFAULT_SAMPLES", "random_search"]

DEFAULT_SAMPLES = 100  # input rows drawn when the request does not say
BATCH = 64  # input rows drawn at a time (decoded in chunks the time left holds)


def _best_of(ctx: SolveContext, bids: np.ndarray, scores: np.ndarray) -> tuple[Assignments, float]:
    """Decode and evaluate the rows ``bids`` (B, V), ``scores`` (B, M) -> (the cheapest,
    its cost)."""
    candidates = decode_candidates(ctx.decoder, bids, scores, ctx.objective)  # B or 2B
    costs = ctx.evaluator.evaluate(candidates).costs[ctx.objective]
    k = int(np.argmin(costs))
    return candidates.take(k), float(costs[k])


@register("random")
def random_search(ctx: SolveContext) -> SolverOutput:
    """The cheapest of ``ctx.samples`` random decodes; ``samples`` = rows evaluated."""
    pace = Pace(time.perf_counter() + ctx.time_limit_s)
    rng = np.random.default_rng(ctx.seed)
    total = ctx.samples or DEFAULT_SAMPLES
    best, best_cost, evaluated = None, np.inf, 0
    while evaluated < total:
        size = min(BATCH, total - evaluated)
        bids = 1.0 - rng.random((size, ctx.problem.n_nodes))  # (B, V) in (0, 1]
        scores = rng.random((size, ctx.problem.n_conflicts))  # (B, M) in [0, 1)
        done = 0
        while done < size:
            chunk = min(size - done, 1 if best is None else pace.units())
            if chunk < 1:
                return SolverOutput(best, samples=evaluated)
            began = pace.clock()
            candidate, cost = _best_of(ctx, bids[done : done + chunk], scores[done : done + chunk])
            pace.record(began, chunk)
            if cost < best_cost:
                best, best_cost = candidate, cost
            done += chunk
            evaluated += chunk
    return SolverOutput(best, samples=evaluated)
