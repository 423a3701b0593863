"""First come, first served: the instant, always-available fallback.

Each conflict is won by the node that is expected to arrive first (node enter
time; equal times by node index), which is a strict total order agreeing with
every path, so the result is acyclic. Following-type is granted wherever every
clique's budget allows, earliest conflicts (by pair enter time) first. Both go
through the shared decoder, so density limits hold by construction, and so do
fixed directions: the decoder lets a fixed first side pass first and moves the
other robot's arrival order behind it (:meth:`Decoder.repair`).
"""

from __future__ import annotations

import numpy as np

from service.core.problem import Problem
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["fcfs", "fcfs_priorities"]


def fcfs_priorities(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """FCFS's node ranks (V,) (expected enter times, increasing along each path) and
    conflict scores (M,) (minus the earliest pair enter: earlier conflicts first).

    The searches that start from FCFS (cmaes, bbts) read their start here.
    """
    return problem.node_enter, -problem.pair_enter.min(axis=1)


@register("fcfs")
def fcfs(ctx: SolveContext) -> SolverOutput:
    """FCFS assignment of ``ctx.problem``; deterministic, ignores seed and time limit."""
    ranks, scores = fcfs_priorities(ctx.problem)
    return SolverOutput(ctx.decoder.decode_ranks(ranks[None], scores[None]), optimal=False)
