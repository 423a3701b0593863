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

:func:`descend_types` instead searches: from every conflict exclusive, the single type
flip the one evaluator finds cheapest, again and again while one is cheaper. The greedy
fill by spared wait stops in poor local optima where following-type couples robots
(a second robot that follows must also leave after the first): given the directions of a
5-s ``auto`` answer of a two-way warehouse of 100 robots, the refit types cost 2.0x that
answer and no single flip improved them, where the descent from exclusive reached 1.05x
in 55 flips (docs/benchmarks.md, session 44). A round takes up to FLIPS_PER_ROUND flips.
It costs only the flips that may be cheaper: a following-type conflict's constraint (the
first side's pair enter) never asks more than its exclusive one (its pair exit, later on
the same robot), so a flip to exclusive only raises delays, and a flip to following only
lowers the events that a path of tight constraints leads to from its wait. For the
objectives that never fall when a delay rises (MONOTONE_OBJECTIVES) only flips to
following of binding waits with such a path to an event the cost reads can be cheaper
(on a 250-robot two-lane warehouse a third of the binding waits for avg_completion, a
tenth for max_completion), each by at most a bound (:class:`_FlipBounds`): a round costs
them in order of it and stops where no flip left may be among its cheapest, 2-6x faster
than costing every flip on 100-250-robot warehouses, with the same answers
(docs/benchmarks.md, session 46).
"""

from __future__ import annotations

import time

import numba
import numpy as np

from service.core.assignment import Assignments
from service.core.decode import Decoder
from service.core.evaluate import MONOTONE_OBJECTIVES, Evaluation, Evaluator
from service.core.incremental import IncrementalEvaluator, apply_moves
from service.core.orientation import OrientationGraph
from service.core.schemas import Objective

__all__ = ["FLIPS_PER_ROUND", "REFIT_ROUNDS", "descend_types", "refit_types", "updated_pair_times"]

# Rounds at updated times after the one at planned times (each stops the refit when it
# is not cheaper); the third still improved on some 250-robot worlds.
REFIT_ROUNDS = 3
# Flips a round of descend_types may take together. Measured (session 44,
# `/tmp/s44/batch.py`, not committed; the best draw's directions of six held-out generated
# warehouses of 50 robots, 820-1,020 conflicts): one flip a round 120-236 ms; 4 49-141 ms
# and costs within 0.4 % either way; 8 44-69 ms, 0-4 % dearer; 16 26-54 ms, 1-5 % dearer.
FLIPS_PER_ROUND = 8
# Flips costed between two looks at the deadline in a round of descend_types, at most: the
# first chunk costs twice FLIPS_PER_ROUND, each next one twice the last. Each call of the
# incremental evaluator orders the whole graph first (~1 ms at 250 robots): small chunks
# throughout slow the unbounded descent of sync_completion, while the bounded ones mostly
# stop within 16-48 flips (session 46).
COSTED_PER_CHECK = 64


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


def descend_types(
    orientation: OrientationGraph,
    evaluator: Evaluator,
    objective: Objective,
    a_first: np.ndarray,
    deadline: float,
) -> tuple[Assignments, float, int]:
    """Types for the valid directions ``a_first`` (1, M) by descent over single type
    flips, from every conflict exclusive (realized ones following), until no flip that
    keeps the answer valid is cheaper
    (:meth:`~service.core.orientation.OrientationGraph.feasible`: never a realized type,
    never past a clique's budget) or ``deadline`` (monotonic) passes -> (the answer, its
    cost, rounds). A round costs the flips that may be cheaper (:func:`_type_flips`)
    incrementally
    (:class:`~service.core.incremental.IncrementalEvaluator`: the one evaluator's numbers),
    those that may gain most first, until none left may gain as much as the
    FLIPS_PER_ROUND-th cheapest (:class:`_FlipBounds`), and takes the cheapest alone or,
    where cheaper still, with up to FLIPS_PER_ROUND - 1 more of the cheaper ones in order
    of their own cost (each still valid on top of those before): the same flips as when
    every one is costed. The answer is valid whenever the directions are."""
    problem = orientation.problem
    answer = Assignments(a_first, (problem.fixed_type == 1)[None])  # (1, M) each
    evaluation = evaluator.evaluate(answer)
    cost = float(evaluation.costs[objective][0])
    may = (problem.fixed_type < 0) & ~orientation.cliques.forbidden()  # (M,)
    if objective in MONOTONE_OBJECTIVES and not orientation.cliques.binding().any():
        return _all_following(evaluator, objective, answer, cost, may)
    incremental, bounds = IncrementalEvaluator(evaluator), _FlipBounds(evaluator, objective)
    # (Q,) following-type conflicts per clique, kept flip by flip: counting anew reads every
    # clique incidence (31 ms a count on wh_mixed/250/500030, cliques of up to 3,321
    # conflicts: half its descent's time).
    counts = orientation.cliques.following_counts(answer.following)[0]
    rounds = 0
    while time.monotonic() < deadline:
        moves = _type_flips(orientation, evaluator, answer, evaluation, may, objective, counts)
        gains = bounds.of(answer, evaluation, moves)  # (K,)
        costs = _flip_costs(incremental, answer, evaluation, moves, gains, objective, deadline)
        if costs is None:  # the deadline passed during the round
            break
        order = np.argsort(costs, kind="stable")
        cheaper = moves[order[costs[order] < cost][:FLIPS_PER_ROUND]]  # (<= FLIPS_PER_ROUND,)
        if not cheaper.size:
            break
        best = apply_moves(answer, cheaper[:1])
        best_counts = _counted(orientation, counts, answer.following[0], cheaper[:1])
        combined, combined_counts = best, best_counts
        for move in cheaper[1:]:
            a_first, following = combined.a_first[0], combined.following[0]
            if orientation.feasible(a_first, following, move[None], combined_counts)[0]:
                combined = apply_moves(combined, move[None])
                combined_counts = _counted(orientation, combined_counts, following, move[None])
        taken = (best,) if combined is best else (best, combined)
        found = min(
            ((evaluator.evaluate(option), option) for option in taken),
            key=lambda pair: float(pair[0].costs[objective][0]),
        )  # the best alone on ties
        if not float(found[0].costs[objective][0]) < cost:  # cheaper only by rounding: done
            break
        counts = best_counts if found[1] is best else combined_counts
        evaluation, answer, rounds = found[0], found[1], rounds + 1
        cost = float(evaluation.costs[objective][0])
    return answer, cost, rounds


def _all_following(
    evaluator: Evaluator, objective: Objective, start: Assignments, cost: float, may: np.ndarray
) -> tuple[Assignments, float, int]:
    """Where no clique's budget binds, the descent's end in one step for an objective that
    never falls when a delay rises: every conflict that may be following-type made so
    (``may`` (M,)), which gives every event its least time (a following-type constraint
    never asks more than the exclusive one), so no flip is cheaper. ``start`` (1, M), the
    all-exclusive answer of cost ``cost``, stands where that is not cheaper (rounds 0).
    Graphs derived from paths have no binding budget (service/geometry/graph.py), and
    there the descent took a round per FLIPS_PER_ROUND of their thousands of waits."""
    following = Assignments(start.a_first, start.following | may[None])  # (1, M) each
    following_cost = float(evaluator.evaluate(following).costs[objective][0])
    if following_cost < cost:
        return following, following_cost, 1
    return start, cost, 0


def _flip_costs(
    incremental: IncrementalEvaluator,
    answer: Assignments,
    evaluation: Evaluation,
    moves: np.ndarray,
    gains: np.ndarray,
    objective: Objective,
    deadline: float,
) -> np.ndarray | None:
    """The costs (K,) of ``moves`` (K,) that may be among the FLIPS_PER_ROUND cheapest
    below ``answer``'s (inf for the others): costed in order of ``gains`` (K,), the most
    each may lower the cost, in growing chunks (see COSTED_PER_CHECK), until the next may
    gain nothing or less than the FLIPS_PER_ROUND-th largest gain found. The ``deadline``
    (monotonic) is checked between chunks (None: it passed): a move can propagate
    through every event, so a whole round of a large graph could run far past it."""
    cost = float(evaluation.costs[objective][0])
    costs = np.full(moves.size, np.inf)  # (K,)
    order = np.argsort(-gains, kind="stable")  # (K,) the most promising first
    lo, size = 0, FLIPS_PER_ROUND
    while lo < moves.size:
        found = cost - costs[order[:lo]]  # (lo,) gains of those costed
        bar = np.sort(found)[-FLIPS_PER_ROUND] if lo >= FLIPS_PER_ROUND else 0.0
        if gains[order[lo]] <= 0 or gains[order[lo]] < bar:
            break
        if lo and time.monotonic() >= deadline:
            return None
        size = min(2 * size, COSTED_PER_CHECK)
        chunk = order[lo : lo + size]
        costs[chunk] = incremental.costs(answer, evaluation, moves[chunk])[objective]
        lo += chunk.size
    return costs


def _type_flips(
    orientation: OrientationGraph,
    evaluator: Evaluator,
    answer: Assignments,
    evaluation: Evaluation,
    may: np.ndarray,
    objective: Objective,
    counts: np.ndarray,
) -> np.ndarray:
    """The type flips (moves M + m) of ``answer`` (its following-type ``counts`` (Q,) per
    clique) that keep it valid and may lower its ``objective``: of a conflict whose type
    ``may`` (M,) change, a binding wait made following-type, or (except for
    MONOTONE_OBJECTIVES, which a flip to exclusive never lowers) a following-type conflict
    made exclusive. Any other flip changes no delay, or only raises delays."""
    useful = may & evaluator.binding(answer, evaluation)  # (M,)
    if objective in MONOTONE_OBJECTIVES:
        useful &= ~answer.following[0]
    else:
        useful |= may & answer.following[0]
    flips = orientation.problem.n_conflicts + np.flatnonzero(useful)  # (K,)
    return flips[orientation.feasible(answer.a_first[0], answer.following[0], flips, counts)]


def _counted(
    orientation: OrientationGraph, counts: np.ndarray, following: np.ndarray, flips: np.ndarray
) -> np.ndarray:
    """A copy of ``counts`` (Q,), the following-type conflicts per clique of the types
    ``following`` (M,), after the type ``flips`` (moves M + m, distinct)."""
    out = counts.copy()
    for move in flips:
        conflict = int(move) - orientation.problem.n_conflicts
        orientation.count_type_move(out, conflict, not following[conflict])
    return out


class _FlipBounds:
    """The most each flip of a binding wait to following-type can lower a cost of
    MONOTONE_OBJECTIVES (inf for the others: no bound), built once per descent (E events,
    M conflicts).

    Its wait's event falls by its relief: down to what its other constraints (its
    robot's previous event, its other conflicts, and the flipped conflict's own
    following-type constraint) ask, at least zero; none of them reads an event after it.
    Every other event falls by at most that much, and only those a path of constraints
    that hold with equality leads to (only through such a path does a fall travel). So a
    wait not critical to an event the cost reads
    (:meth:`~service.core.evaluate.Evaluator.critical_slopes`) gains nothing; a critical
    one at most its relief times its slope, the cost's weight those paths reach (the
    maximum: its relief; avg_completion: the robots' count over the fleet's).
    """

    def __init__(self, evaluator: Evaluator, objective: Objective) -> None:
        graph = evaluator.graph
        self.evaluator, self.objective = evaluator, objective
        n_events = evaluator.n_events
        by_target = np.argsort(graph.target, kind="stable")  # (2M,) slots by their event
        start = np.zeros(n_events + 2, dtype=np.int64)  # (E+2,) event e's: start[e]:start[e+1]
        np.cumsum(np.bincount(graph.target, minlength=n_events + 1), out=start[1:])
        self._graph = (
            graph.chain_prev(), graph.target, graph.source, graph.offset, graph.live, start,
            by_target,
        )  # fmt: skip

    def of(self, answer: Assignments, evaluation: Evaluation, moves: np.ndarray) -> np.ndarray:
        """(K,) the most each of ``moves`` (K,), type flips of binding exclusive waits of
        the single ``answer`` (its ``evaluation``), can lower the cost (a hair above, so
        that rounding never makes a gain exceed it; 0 where it gains nothing)."""
        if self.objective not in MONOTONE_OBJECTIVES:
            return np.full(moves.size, np.inf)
        evaluator, n_conflicts = self.evaluator, answer.a_first.shape[1]
        held = evaluator.cost_weights(self.objective, evaluation)  # (E+1,)
        critical, slope = evaluator.critical_slopes(answer, held)  # (E+1,) each
        relief, target = _relief(
            moves - n_conflicts, answer.a_first[0].astype(np.int64),
            answer.following[0].astype(np.int64), evaluation.event_delay[0], *self._graph,
        )  # fmt: skip
        if self.objective == "max_completion":  # the maximum falls by the relief at most
            reach = critical[target].astype(np.float64)  # (K,)
        else:  # the weight those paths reach, of the sum's (avg_delay) or the mean's
            per = (
                1.0 / evaluation.completion.shape[1] if self.objective == "avg_completion" else 1.0
            )
            reach = np.where(critical[target], slope[target] * per, 0.0)  # (K,)
        gain = relief * reach  # (K,)
        cost = float(evaluation.costs[self.objective][0])
        return np.where(gain > 0, gain * (1 + 1e-9) + 1e-9 * max(1.0, abs(cost)), 0.0)


@numba.njit(cache=True, nogil=True)
def _relief(
    conflicts: np.ndarray,  # (K,) int, binding exclusive waits
    a_first: np.ndarray,  # (M,) int
    following: np.ndarray,  # (M,) int
    delay: np.ndarray,  # (E+1,) float, least delays
    chain_prev: np.ndarray,  # (E,) int, previous event of the same robot, or -1
    target: np.ndarray,  # (2M,) int
    source: np.ndarray,  # (2, 2M) int
    offset: np.ndarray,  # (2, 2M) float
    live: np.ndarray,  # (2M,) bool
    start: np.ndarray,  # (E+2,) int, slots constraining event e: by_target[start[e]:start[e+1]]
    by_target: np.ndarray,  # (2M,) int
) -> tuple[np.ndarray, np.ndarray]:
    """(K,) how far each conflict's wait falls once it is following-type (see
    _FlipBounds), and (K,) the event that waits."""
    relief = np.empty(conflicts.size)
    events = np.empty(conflicts.size, dtype=np.int64)
    for i in range(conflicts.size):
        c = conflicts[i]
        j = 2 * c + a_first[c]  # the slot of the side passing second
        e = target[j]
        floor = max(0.0, delay[source[1, j]] + offset[1, j])
        if chain_prev[e] >= 0:
            floor = max(floor, delay[chain_prev[e]])
        for k in range(start[e], start[e + 1]):
            other = by_target[k]
            c_other = other // 2
            if other != j and live[other] and other == 2 * c_other + a_first[c_other]:
                kind = following[c_other]
                floor = max(floor, delay[source[kind, other]] + offset[kind, other])
        relief[i], events[i] = max(delay[e] - floor, 0.0), e
    return relief, events
