"""Robot-priority search and re-insertion search in turns.

The two searches get stuck in different places. Re-insertion
(:mod:`service.solvers.reinsert`) re-plans a few robots with every other robot's times
held, so it never delays a held robot: on the dense two-way warehouses of 250 robots
(~175 conflicts per robot) it plateaued at 0.81 of the best known after 30 s on this
project's slower bench machine. Priority search (:mod:`service.solvers.priority`) shifts
one robot's priority against every robot it meets, delaying them where that pays, but
its random shifts rarely find the fine re-orderings re-insertion finds in a step. In
turns, each starts from the other's answer: priority search from ranks that decode to
it (:func:`~service.solvers.priority.answer_ranks`), re-insertion from its directions.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import NamedTuple

from service.core.assignment import Assignments
from service.solvers.priority import answer_ranks, priority_search
from service.solvers.registry import SolveContext
from service.solvers.reinsert import reinsert_search

__all__ = ["TurnsConfig", "TurnsResult", "take_turns"]


@dataclass(frozen=True)
class TurnsConfig:
    """How long a turn lasts and how it is split."""

    turn_s: float = 0.5  # a turn's length, at most
    turn_share: float = 0.25  # ... and at most this share of the time given
    priority_share: float = 0.6  # priority search's part of a turn, re-insertion the rest
    adapt: bool = True
    least_share: float = 0.1


class TurnsResult(NamedTuple):
    """The best answer, its cost and the turns taken."""

    best: Assignments
    cost: float
    turns: int


def take_turns(
    ctx: SolveContext,
    start: Assignments,
    cost: float,
    deadline: float,
    seed: int,
    config: TurnsConfig = TurnsConfig(),
) -> TurnsResult:
    """Re-insertion then priority search, in turns from the valid ``start`` (of ``cost``)
    until ``deadline`` (monotonic); each turn's searches get the next seed."""
    best, turns, share = start, 0, config.priority_share
    turn_s = min(config.turn_s, config.turn_share * (deadline - time.monotonic()))
    while time.monotonic() < deadline:
        began, before = time.monotonic(), cost
        found = reinsert_search(
            ctx, best, min(deadline, began + (1 - share) * turn_s), seed + turns
        )
        best, cost = found.best, found.cost
        middle, between = time.monotonic(), cost
        left = min(share * turn_s, deadline - middle)
        if left <= 0:
            break
        ranks = answer_ranks(ctx, best)
        # Given less than PriorityConfig.refit_min_s (0.5 s) here, it refits no types.
        best, cost, _ = priority_search(ctx, left, seed + turns, start=(ranks, best, cost))
        turns += 1
        if config.adapt:
            rate_r = (before - between) / max(middle - began, 1e-6)
            rate_p = (between - cost) / max(time.monotonic() - middle, 1e-6)
            if rate_r + rate_p > 0:
                measured = rate_p / (rate_r + rate_p)
                share = min(
                    max(0.5 * share + 0.5 * measured, config.least_share), 1 - config.least_share
                )
    return TurnsResult(best, cost, turns)
