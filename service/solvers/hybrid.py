"""CP-SAT warm-started with the GNN-VAE's answer: an anytime exact solver.

``gnn_vae_exact`` first runs ``gnn_vae_refined`` (at most its own 1 s budget),
then gives CP-SAT the rest of the request's time limit with that assignment as
a solution hint. CP-SAT starts its search near the learned answer instead of
FCFS and proves optimality when it can; the answer is the cheaper of the two
(by the one evaluator), so it is never worse than ``gnn_vae_refined``.
Without a model for the objective it answers ``None`` and the dispatcher
degrades to plain ``exact``.
"""

from __future__ import annotations

import time
from dataclasses import replace

from service.solvers.exact import improve
from service.solvers.refine import gnn_vae_refined
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["gnn_vae_exact"]


@register("gnn_vae_exact")
def gnn_vae_exact(ctx: SolveContext) -> SolverOutput | None:
    """The GNN-VAE's refined answer, improved (and maybe proven optimal) by hinted CP-SAT."""
    start = time.perf_counter()
    learned = gnn_vae_refined(ctx)
    if learned is None:
        return None
    remaining = ctx.time_limit_s - (time.perf_counter() - start)
    if remaining <= 0:
        return replace(learned, detail="no time left for CP-SAT")
    improved, verdict = improve(ctx, learned, remaining)
    return replace(improved, detail=verdict)
