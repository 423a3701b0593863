"""Labels: per objective, the best assignments the exact solvers find, best first.

Two labellers, both deterministic wherever CP-SAT proves its answer (one worker,
a fixed seed, a hint that does not depend on the clock):

* :func:`top_labels` (the ``small`` and ``stitched`` kinds, as published): CP-SAT's
  top-L by no-good re-solves, each solve within the time limit; targets
  ``{"a_first", "following", "cost", "optimal"}``.
* :func:`portfolio_labels` (the ``scenario`` kind): the exact portfolio, staged as
  the service's ``auto``. CP-SAT starts from the cheapest of FCFS and its blends, and
  above ``HINT_ABOVE_CONFLICTS`` conflicts from robot-priority search then tabu search
  from there, the service's first stage (unhinted, CP-SAT found no solution at all
  within 1 s from 60 robots of a warehouse up; datasets made before session 12 were
  hinted by tabu search alone); both searches run to their own round and iteration
  limits, never a clock, so the hint is the same on every machine. CP-SAT
  then proves the top-L where it can; otherwise the single target is the best known
  answer (CP-SAT's, or its hint's when CP-SAT found nothing or the hint evaluates
  cheaper), with ``optimal`` false and ``gap`` the relative gap CP-SAT reports
  between its answer and its best bound (null when CP-SAT found nothing). Targets
  also hold ``gap`` (0 when proven).

Costs are always the one evaluator's (CP-SAT works on integer-scaled times).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from service.core.assignment import Assignments
from service.core.problem import Problem
from service.core.schemas import Objective
from service.solvers.exact import ExactResult, top_assignments
from service.solvers.priority import PriorityConfig, priority_search
from service.solvers.registry import SolveContext
from service.solvers.tabu import plain_start, tabu_search

__all__ = ["HINT_ABOVE_CONFLICTS", "contexts", "portfolio_hint", "portfolio_labels", "top_labels"]

# CP-SAT from FCFS up to this many conflicts, as the service's portfolio (``auto``) does.
HINT_ABOVE_CONFLICTS = SolveContext.exact_max_conflicts
# The hint's robot-priority search: a round cap instead of a clock (1,000 rounds take
# ~1 s on a 100-robot warehouse, 4-8 s at 250 robots; most stop on patience sooner).
HINT_PRIORITY = PriorityConfig(max_rounds=1000)

Target = dict[str, Any]


def _bits(mask: np.ndarray) -> str:
    return "".join("1" if x else "0" for x in mask.tolist())


def _target(assignment: Assignments, cost: float, optimal: bool) -> Target:
    """A stored target: the assignment as bit strings, its cost, whether it is proven."""
    return {
        "a_first": _bits(assignment.a_first[0]),
        "following": _bits(assignment.following[0]),
        "cost": cost,
        "optimal": optimal,
    }


def contexts(
    problem: Problem, objectives: Sequence[Objective], time_limit_s: float
) -> dict[Objective, SolveContext]:
    """One labelling context per objective (``time_limit_s`` per CP-SAT solve), all sharing
    the problem's cliques and evaluator."""
    out = {o: SolveContext(problem, o, time_limit_s, seed=0) for o in objectives}
    first = out[objectives[0]]
    for ctx in out.values():
        ctx.__dict__.update(cliques=first.cliques, evaluator=first.evaluator)  # cached properties
    return out


def top_labels(ctx: SolveContext, top: int) -> list[Target]:
    """CP-SAT's top-``top`` assignments, unhinted (the published labels)."""
    found = top_assignments(ctx.problem, ctx.cliques, ctx.objective, top, ctx.time_limit_s)
    return [_target(r.assignment, ctx.cost(r.assignment), r.optimal) for r in found]


def portfolio_hint(ctx: SolveContext) -> Assignments:
    """The cheapest blend, improved above ``HINT_ABOVE_CONFLICTS`` conflicts by
    robot-priority search (which starts there and never returns worse) then tabu search,
    both to their round and iteration limits (no clock: the same hint on every machine)."""
    if ctx.problem.n_conflicts <= HINT_ABOVE_CONFLICTS:
        return plain_start(ctx)
    found = priority_search(ctx, math.inf, seed=ctx.seed, cfg=HINT_PRIORITY)[0]
    return tabu_search(ctx, found, budget_s=math.inf)[0]


def portfolio_labels(ctx: SolveContext, top: int) -> list[Target]:
    """The exact portfolio's labels with their gaps (see the module doc)."""
    hint = portfolio_hint(ctx)
    found = top_assignments(
        ctx.problem, ctx.cliques, ctx.objective, top, ctx.time_limit_s, hint=hint
    )
    targets = [_with_gap(r, ctx.cost(r.assignment)) for r in found]
    if not (found and found[0].optimal):
        hint_cost = ctx.cost(hint)
        if not targets or hint_cost < targets[0]["cost"]:
            gap = targets[0]["gap"] if targets else None  # bounds the hint's gap from above
            targets = [{**_target(hint, hint_cost, False), "gap": gap}]
    return targets


def _with_gap(result: ExactResult, cost: float) -> Target:
    return {**_target(result.assignment, cost, result.optimal), "gap": result.gap}
