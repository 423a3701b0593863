"""Types re-decided for an assignment's directions, from the waits its schedule has.

The decoder fills every density clique's following budget greedily by a score. A score
fixed before the directions (FCFS's, or the learned probabilities that large graphs
share across draws) spends the budget where following spares little.
:func:`~service.core.decode.following_gain` scores by the wait following spares given
the directions: at planned times first, then at the updated times of the schedule kept
so far (its real waits, which move once the types change), a few rounds, each kept only
when cheaper. Measured on the learned model's cheapest of 100 draws on the
generalization worlds of 100 and 250 robots (docs/benchmarks.md, "Following-type where it
spares most"): planned times alone 4-9 % cheaper on average, with three rounds at updated
times 10-14 %, in 1-33 ms. Robot-priority search refits its best this way as it goes
(:mod:`service.solvers.priority`; docs/benchmarks.md, "Types refitted during priority
search").
"""

from __future__ import annotations

import numpy as np

from service.core.assignment import Assignments
from service.core.decode import Decoder
from service.core.evaluate import Evaluation, Evaluator
from service.core.schemas import Objective

__all__ = ["REFIT_ROUNDS", "refit_types", "updated_pair_times"]

# Rounds at updated times after the one at planned times (each stops the refit when it
# is not cheaper); the third still improved on some 250-robot worlds.
REFIT_ROUNDS = 3


def updated_pair_times(
    evaluator: Evaluator, evaluation: Evaluation, sample: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Each side's updated pair enter and exit times (M, 2) each, of one evaluated sample."""
    p = evaluator.problem
    enter = p.tp_time[p.tp_pair_enter] + evaluator.delays_at(evaluation, sample, p.tp_pair_enter)
    exit_ = p.tp_time[p.tp_pair_exit] + evaluator.delays_at(evaluation, sample, p.tp_pair_exit)
    return enter, exit_


def refit_types(
    decoder: Decoder,
    evaluator: Evaluator,
    objective: Objective,
    start: Assignments,
    rounds: int = REFIT_ROUNDS,
) -> tuple[Assignments, float]:
    """The cheapest of ``start`` (a valid batch of one) and its directions with the types
    they gain most from, at planned times, then at the updated times of the cheapest so
    far, for up to ``rounds`` rounds (stopping at one that is not cheaper) -> (it, its cost).

    Every candidate keeps ``start``'s directions and takes the decoder's greedy types,
    so it is valid whenever ``start`` is (fixed types are honoured by the decoder).
    """
    best, evaluation = start, evaluator.evaluate(start)
    best_cost = float(evaluation.costs[objective][0])
    candidate = Assignments(start.a_first, decoder.gain_types(start.a_first))  # planned
    for round_ in range(rounds + 1):
        found = evaluator.evaluate(candidate)
        cost = float(found.costs[objective][0])
        if cost < best_cost:
            best, best_cost, evaluation = candidate, cost, found
        elif round_ > 0:
            break
        times = updated_pair_times(evaluator, evaluation)  # (M, 2) each
        candidate = Assignments(best.a_first, decoder.gain_types(best.a_first, *times))
    return best, best_cost
