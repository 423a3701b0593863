"""First come, first served: the instant, always-available fallback.

Each conflict is won by the node that is expected to arrive first (node enter
time; equal times by node index), which is a strict total order agreeing with
every path, so the result is acyclic. Following-type is granted wherever every
clique's budget allows, earliest conflicts (by pair enter time) first. Both go
through the shared decoder, so density limits hold by construction.
"""

from __future__ import annotations

from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["fcfs"]


@register("fcfs")
def fcfs(ctx: SolveContext) -> SolverOutput:
    """FCFS assignment of ``ctx.problem``; deterministic, ignores seed and time limit."""
    problem = ctx.problem
    ranks = problem.node_enter[None, :]  # (1, V) strictly increasing along each path
    first_enter = problem.pair_enter.min(axis=1)  # (M,)
    scores = -first_enter[None, :]  # (1, M) earlier conflicts get following-type first
    return SolverOutput(ctx.decoder.decode_ranks(ranks, scores), optimal=False)
