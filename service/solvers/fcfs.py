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

__all__ = ["BLENDS", "blended_priorities", "fcfs", "fcfs_priorities"]

# How far each start of :func:`blended_priorities` moves a node's rank from its enter
# time toward its robot's planned completion: 0 is FCFS, 1 orders robots by planned
# completion (shortest first: the classic rule for average completion on a shared
# resource), negative values put robots with much left first (longest first, for the
# makespan). Measured on generated 250-robot warehouses (avg_completion, graph cost
# against FCFS): 0.5 gave 0.63 (two-way) and 0.88 (two-lane), 0.75 0.65 and 0.82; on a
# 100-robot one-way warehouse 0.9 gave 0.83; negative values 1.09-1.62. All of them
# together cost ~45 ms at 22,000 conflicts (decoding and evaluating 10 rows).
BLENDS = (-1.0, -0.5, -0.25, 0.0, 0.1, 0.25, 0.5, 0.75, 0.9, 1.0)


def fcfs_priorities(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """FCFS's node ranks (V,) (expected enter times, increasing along each path) and
    conflict scores (M,) (minus the earliest pair enter: earlier conflicts first).

    The searches that start from FCFS (cmaes, bbts) read their start here.
    """
    return problem.node_enter, -problem.pair_enter.min(axis=1)


def blended_priorities(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """Node ranks (K, V) and conflict scores (K, M) of the K = len(BLENDS) starts
    ``(1 - mu) enter + mu completion``, mu in BLENDS (mu = 0 is FCFS).

    Each row is non-decreasing along every path, which is all the decoder needs for an
    acyclic answer: enter times do not decrease along a path, the robot's completion is
    constant on it, and for mu <= 1 the weight of enter is >= 0 (written this way, not as
    ``enter + mu (completion - enter)``, rounding keeps the order too). Scores are FCFS's.
    """
    enter, scores = fcfs_priorities(problem)
    finish = problem.tp_time[problem.last_tp][problem.node_robot]  # (V,) robot's completion
    mu = np.asarray(BLENDS)[:, None]  # (K, 1)
    ranks = (1.0 - mu) * enter[None] + mu * finish[None]  # (K, V)
    return ranks, np.repeat(scores[None], mu.size, axis=0)


@register("fcfs")
def fcfs(ctx: SolveContext) -> SolverOutput:
    """FCFS assignment of ``ctx.problem``; deterministic, ignores seed and time limit."""
    ranks, scores = fcfs_priorities(ctx.problem)
    return SolverOutput(ctx.decoder.decode_ranks(ranks[None], scores[None]), optimal=False)
