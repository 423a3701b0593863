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

from service.core.assignment import Assignments
from service.core.problem import Problem
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = [
    "COMPLETION_BLENDS",
    "EXIT_BLENDS",
    "blended_priorities",
    "cheapest_blend",
    "fcfs",
    "fcfs_priorities",
]

# The starts of :func:`blended_priorities`: node ranks moved from the node's enter time
# toward its robot's planned completion (0 is FCFS; 1 lets the robot that plans to finish
# first pass first everywhere, the shortest-processing-time rule for average completion;
# negative values put robots with much left first, for the makespan), and toward the
# node's exit time (1: first to leave, first to pass). Measured on generated warehouses
# and floors of 25-250 robots (graph cost against FCFS, four objectives): the best row
# cost 0.55-0.97 of FCFS (avg_completion 0.62 at 250 two-way robots, 0.75 at 100); the
# exit rows won on five of the six worlds' avg_delay. All 17 rows, each with two type
# rules (:func:`cheapest_blend`), cost ~65 ms at 22,000 conflicts (decoding and
# evaluating them; 10 ms with FCFS's types alone).
COMPLETION_BLENDS = (-1.0, -0.5, -0.25, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0)
EXIT_BLENDS = (0.5, 0.75, 1.0)


def fcfs_priorities(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """FCFS's node ranks (V,) (expected enter times, increasing along each path) and
    conflict scores (M,) (minus the earliest pair enter: earlier conflicts first).

    The searches that start from FCFS (cmaes, bbts) read their start here.
    """
    return problem.node_enter, -problem.pair_enter.min(axis=1)


def blended_priorities(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """Node ranks (K, V) and conflict scores (K, M) of the K starts ``(1 - mu) enter +
    mu target``: target the robot's planned completion for mu in COMPLETION_BLENDS
    (first rows; mu = 0 is FCFS), then the node's exit time for mu in EXIT_BLENDS.

    Each row is non-decreasing along every path, which is all the decoder needs for an
    acyclic answer: enter and exit times do not decrease along a path, the robot's
    completion is constant on it, and for mu <= 1 the weight of enter is >= 0 (written
    this way, not as ``enter + mu (target - enter)``, rounding keeps the order too).
    Scores are FCFS's.
    """
    enter, scores = fcfs_priorities(problem)
    finish = problem.tp_time[problem.last_tp][problem.node_robot]  # (V,) robot's completion
    mu = np.array(COMPLETION_BLENDS + EXIT_BLENDS)[:, None]  # (K, 1)
    target = np.concatenate(
        [
            np.repeat(finish[None], len(COMPLETION_BLENDS), axis=0),
            np.repeat(problem.node_exit[None], len(EXIT_BLENDS), axis=0),
        ]
    )  # (K, V)
    ranks = (1.0 - mu) * enter[None] + mu * target
    return ranks, np.repeat(scores[None], mu.size, axis=0)


def cheapest_blend(ctx: SolveContext) -> tuple[np.ndarray, Assignments, float]:
    """The cheapest start of :func:`blended_priorities` under ``ctx``'s objective, each
    row's directions with FCFS's types or with the types its directions gain most from
    (:meth:`~service.core.decode.Decoder.gain_types`): its node ranks (V,), its
    assignment (a batch of one) and its cost.

    Kept in ``ctx`` once found (~50 ms at 22,000 conflicts): the portfolio's start and
    the searches that start there (tabu, priority search) all ask, and contexts copied
    for a stage after the first ask share it."""
    cached = ctx.__dict__.get("_cheapest_blend")
    if cached is None:
        ranks, scores = blended_priorities(ctx.problem)  # (K, V), (K, M)
        a_first = ctx.decoder.directions(ranks)  # (K, M)
        # Every row has FCFS's scores, and types depend on scores alone: decoded once.
        fcfs_types = np.repeat(ctx.decoder.types(scores[:1]), len(ranks), axis=0)  # (K, M)
        gain_types = ctx.decoder.gain_types(a_first)  # (K, M)
        found = Assignments(
            np.concatenate([a_first, a_first]), np.concatenate([fcfs_types, gain_types])
        )  # 2K rows
        costs = ctx.evaluator.evaluate(found).costs[ctx.objective]  # (2K,)
        k = int(np.argmin(costs))
        start = (ranks[k % len(ranks)], found.take(k), float(costs[k]))
        cached = ctx.__dict__["_cheapest_blend"] = start
    return cached


@register("fcfs")
def fcfs(ctx: SolveContext) -> SolverOutput:
    """FCFS assignment of ``ctx.problem``; deterministic, ignores seed and time limit."""
    ranks, scores = fcfs_priorities(ctx.problem)
    return SolverOutput(ctx.decoder.decode_ranks(ranks[None], scores[None]), optimal=False)
