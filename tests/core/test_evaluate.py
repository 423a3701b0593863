"""The evaluator: hand-computed cases, the trap, batching, and the brute-force reference."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core import evaluate
from service.core.assignment import Assignments
from service.core.check import check
from service.core.cliques import find_cliques
from service.core.decode import Decoder
from service.core.evaluate import Evaluation, Evaluator
from service.core.problem import Problem, problem_from_request
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from tests.reference import (
    OBJECTIVE_NAMES,
    costs,
    is_acyclic,
    least_times,
    reference_problem,
    tiny_request,
    trap_request,
)

EXCLUSIVE, FOLLOWING = False, True


def _problem(req: dict[str, Any]) -> Problem:
    return problem_from_request(ScheduleRequest.model_validate(req))


def _evaluate(req: dict[str, Any], a_first: list[bool], following: list[bool]) -> tuple:
    problem = _problem(req)
    ev = Evaluator(problem)
    return problem, ev, ev.evaluate(Assignments.single(a_first, following))


def _delays(problem: Problem, ev: Evaluator, result: Evaluation) -> list[list[float]]:
    """D at every time point, per robot."""
    d = ev.delays_at(result, 0, np.arange(problem.tp_time.size))
    return [
        d[problem.tp_start[r] : problem.tp_start[r + 1]].tolist() for r in range(problem.n_robots)
    ]


def _costs(result: Evaluation) -> dict[str, float]:
    return {k: float(v[0]) for k, v in result.costs.items()}


def _robot(rid: str, *nodes: tuple[float, float], goal: float | None = None) -> dict[str, Any]:
    robot: dict[str, Any] = {
        "id": rid,
        "nodes": [
            {"id": f"{rid}{k}", "enter": e, "exit": x, "density": 3}
            for k, (e, x) in enumerate(nodes)
        ],
    }
    if goal is not None:
        robot["goal_time"] = goal
    return robot


# Two robots, one conflict, pair sections strictly inside the nodes:
#   a: node a0 [0, 10], section [4, 8]  -> time points a: 0, 4, 8, 10
#   b: node b0 [1, 9],  section [3, 5]  -> time points b: 1, 3, 5, 9
TWO = {
    "robots": [_robot("a", (0.0, 10.0)), _robot("b", (1.0, 9.0))],
    "conflicts": [
        {"a": "a0", "b": "b0", "a_enter": 4.0, "a_exit": 8.0, "b_enter": 3.0, "b_exit": 5.0}
    ],
}


def test_two_robots_exclusive_inside_nodes() -> None:
    problem, ev, result = _evaluate(TWO, [True], [EXCLUSIVE])
    # a -> b exclusive: T~_b(3) >= T~_a(8) = 8, so D_b(3) = 8 - 3 = 5 and D_b stays 5 after;
    # D_b(1) = 0 (before b's pair enter). a never waits.
    assert problem.tp_time.tolist() == [0, 4, 8, 10, 1, 3, 5, 9]
    assert _delays(problem, ev, result) == [[0, 0, 0, 0], [0, 5, 5, 5]]
    # completion a = 10, b = 9 + 5 = 14.
    assert result.completion[0].tolist() == [10, 14]
    assert result.converged.tolist() == [True]
    assert _costs(result) == pytest.approx(
        {
            "avg_completion": 12.0,  # (10 + 14) / 2
            "max_completion": 14.0,
            "sync_completion": 14.0,  # 12 + (|10 - 12| + |14 - 12|) / 2
            "avg_delay": 1.875,  # (0 / 4 + (0 + 5 + 5 + 5) / 4) / 2 = 3.75 / 2
        }
    )


def test_two_robots_following_inside_nodes() -> None:
    problem, ev, result = _evaluate(TWO, [True], [FOLLOWING])
    # a -> b following: T~_b(3) >= T~_a(4) = 4, so D_b(3) = 4 - 3 = 1 from b's pair enter on.
    assert _delays(problem, ev, result) == [[0, 0, 0, 0], [0, 1, 1, 1]]
    # completion a = 10, b = 9 + 1 = 10.
    assert result.completion[0].tolist() == [10, 10]
    assert _costs(result) == pytest.approx(
        {
            "avg_completion": 10.0,
            "max_completion": 10.0,
            "sync_completion": 10.0,  # no spread
            "avg_delay": 0.375,  # (0 + (0 + 1 + 1 + 1) / 4) / 2
        }
    )


def test_two_robots_other_direction() -> None:
    problem, ev, result = _evaluate(TWO, [False], [EXCLUSIVE])
    # b -> a exclusive: T~_a(4) >= T~_b(5) = 5, so D_a = 1 from a's pair enter (4) on.
    assert _delays(problem, ev, result) == [[0, 1, 1, 1], [0, 0, 0, 0]]
    # completion a = 10 + 1 = 11, b = 9: avg 10, sync 10 + (1 + 1) / 2 = 11.
    assert _costs(result) == pytest.approx(
        {
            "avg_completion": 10.0,
            "max_completion": 11.0,
            "sync_completion": 11.0,
            "avg_delay": 0.375,
        }
    )


# A chain a -> b -> c (whole nodes as sections), c with a second node after the conflict:
#   a: [0, 4];  b: [2, 6];  c: [5, 9], [11, 12]
CHAIN = {
    "robots": [
        _robot("a", (0.0, 4.0)),
        _robot("b", (2.0, 6.0)),
        _robot("c", (5.0, 9.0), (11.0, 12.0)),
    ],
    "conflicts": [{"a": "a0", "b": "b0"}, {"a": "b0", "b": "c0"}],
}


def test_chain_of_three_propagates_delays() -> None:
    problem, ev, result = _evaluate(CHAIN, [True, True], [EXCLUSIVE, EXCLUSIVE])
    # a -> b: T~_b(2) >= T~_a(4) = 4            -> D_b = 2, so T~_b(6) = 8.
    # b -> c: T~_c(5) >= T~_b(6) = 6 + D_b = 8  -> D_c = 3 at 5 and, never decreasing, at 9, 11, 12.
    assert _delays(problem, ev, result) == [[0, 0], [2, 2], [3, 3, 3, 3]]
    # completions 4, 8, 12 + 3 = 15.
    assert result.completion[0].tolist() == [4, 8, 15]
    assert _costs(result) == pytest.approx(
        {
            "avg_completion": 9.0,  # (4 + 8 + 15) / 3
            "max_completion": 15.0,
            "sync_completion": 13.0,  # 9 + (5 + 1 + 6) / 3
            "avg_delay": 5.0 / 3.0,  # (0 + 2 + 3) / 3
        }
    )


def test_chain_following_propagates_pair_enter() -> None:
    problem, ev, result = _evaluate(CHAIN, [True, True], [FOLLOWING, FOLLOWING])
    # a -> b following: T~_b(2) >= T~_a(0) = 0 -> no wait;
    # b -> c following: T~_c(5) >= T~_b(2) = 2 -> no wait.
    assert _delays(problem, ev, result) == [[0, 0], [0, 0], [0, 0, 0, 0]]
    assert _costs(result)["avg_completion"] == pytest.approx((4 + 6 + 12) / 3)


def test_goal_time_after_last_node() -> None:
    req = {
        "robots": [_robot("a", (0.0, 4.0), goal=7.0), _robot("b", (1.0, 5.0))],
        "conflicts": [{"a": "a0", "b": "b0"}],
    }
    problem, ev, result = _evaluate(req, [False], [EXCLUSIVE])
    # b -> a exclusive: T~_a(0) >= T~_b(5) = 5 -> D_a = 5 at a's time points 0, 4 and goal 7.
    assert problem.tp_time[: problem.tp_start[1]].tolist() == [0, 4, 7]
    assert _delays(problem, ev, result) == [[5, 5, 5], [0, 0]]
    # completion is the (delayed) goal time: 7 + 5 = 12, not the last exit 4 + 5 = 9.
    assert result.completion[0].tolist() == [12, 5]
    assert _costs(result) == pytest.approx(
        {
            "avg_completion": 8.5,  # (12 + 5) / 2
            "max_completion": 12.0,
            "sync_completion": 12.0,  # 8.5 + (3.5 + 3.5) / 2
            "avg_delay": 2.5,  # ((5 + 5 + 5) / 3 + 0) / 2
        }
    )
    # Zero delay: completion is the goal time itself.
    assert ev.free_costs()["max_completion"] == 7.0


def test_avg_delay_averages_over_time_points() -> None:
    # b waits twice: for a at its first node, then longer for c at its second node.
    #   a: [0, 10] section [4, 8]
    #   b: [1, 9] section [3, 5] (with a), [10, 12] section [10, 11] (with c), goal 13
    #   c: [0, 20] section [14, 16]
    req = {
        "robots": [
            _robot("a", (0.0, 10.0)),
            _robot("b", (1.0, 9.0), (10.0, 12.0), goal=13.0),
            _robot("c", (0.0, 20.0)),
        ],
        "conflicts": [
            {"a": "a0", "b": "b0", "a_enter": 4.0, "a_exit": 8.0, "b_enter": 3.0, "b_exit": 5.0},
            {
                "a": "c0",
                "b": "b1",
                "a_enter": 14.0,
                "a_exit": 16.0,
                "b_enter": 10.0,
                "b_exit": 11.0,
            },
        ],
    }
    problem, ev, result = _evaluate(req, [True, True], [EXCLUSIVE, EXCLUSIVE])
    # b's time points: 1, 3, 5, 9, 10, 11, 12, 13.
    # a -> b: T~_b(3) >= 8 -> D_b(3) = 5.   c -> b: T~_b(10) >= T~_c(16) = 16 -> D_b(10) = 6.
    # D_b = 0, 5, 5, 5, 6, 6, 6, 6 -> mean 39 / 8.
    assert _delays(problem, ev, result)[1] == [0, 5, 5, 5, 6, 6, 6, 6]
    # a and c never wait: avg_delay = (0 + 39/8 + 0) / 3 = 13 / 8.
    assert _costs(result)["avg_delay"] == pytest.approx(13.0 / 8.0)
    # completions 10, 13 + 6 = 19, 20.
    assert result.completion[0].tolist() == [10, 19, 20]


def test_sync_completion_penalises_spread() -> None:
    # Same average completion, different spread: sync = avg + mean |c_i - avg|.
    # a -> b exclusive (TWO): completions 10, 14 -> 12 + 2 = 14;
    # b -> a following: T~_a(4) >= T~_b(3) = 3 -> no wait: completions 10, 9 -> 9.5 + 0.5 = 10.
    _, _, first = _evaluate(TWO, [True], [EXCLUSIVE])
    _, _, second = _evaluate(TWO, [False], [FOLLOWING])
    assert _costs(first)["sync_completion"] == pytest.approx(14.0)
    assert _costs(second)["sync_completion"] == pytest.approx(10.0)
    assert _costs(second)["avg_completion"] == pytest.approx(9.5)


def test_no_conflicts_is_free() -> None:
    req = {"robots": [_robot("a", (0.0, 4.0), goal=5.0), _robot("b", (1.0, 3.0))]}
    problem, ev, result = _evaluate(req, [], [])
    assert result.completion[0].tolist() == [5, 3]
    assert _costs(result) == pytest.approx(ev.free_costs())
    assert _costs(result)["sync_completion"] == pytest.approx(4.0 + 1.0)


# --- the three-robot trap ------------------------------------------------------------------------


def test_trap_node_cycle_without_waiting_has_finite_times() -> None:
    problem = _problem(trap_request())
    ev = Evaluator(problem)
    cycle = Assignments.single([False] * 3, [False] * 3)  # b -> a, c -> b, a -> c
    result = ev.evaluate(cycle)
    # b -> a: T~_a(8) >= T~_b(2) = 2; c -> b: T~_b(8) >= T~_c(2); a -> c: T~_c(8) >= T~_a(2):
    # every wait is already satisfied by the plan, so the least times are the plan.
    assert result.converged.tolist() == [True]
    assert result.completion[0].tolist() == [10, 10, 10]
    assert _costs(result) == pytest.approx(
        {"avg_completion": 10.0, "max_completion": 10.0, "sync_completion": 10.0, "avg_delay": 0.0}
    )
    # ... and yet it is a node cycle, which the checker must reject.
    assert check(problem, find_cliques(problem), cycle).acyclic.tolist() == [False]


def test_trap_positive_cycle_does_not_converge() -> None:
    problem = _problem(trap_request())
    result = Evaluator(problem).evaluate(Assignments.single([True] * 3, [False] * 3))
    # a -> b: T~_b(0) >= T~_a(10); b -> c: T~_c(0) >= T~_b(10); c -> a: T~_a(0) >= T~_c(10):
    # each lap adds 10 to everything, so no least times exist.
    assert result.converged.tolist() == [False]
    assert all(math.isinf(float(v[0])) for v in result.costs.values())
    assert least_times(reference_problem(trap_request()), [True] * 3, [False] * 3) is None


def test_zero_weight_cycle_has_finite_least_times() -> None:
    """A node cycle of following-type conflicts whose pair sections all start at 0.

    a -> b: T~_b(0) >= T~_a(0); b -> c: T~_c(0) >= T~_b(0); c -> a: T~_a(0) >= T~_c(0).
    The plan itself satisfies all three (a cycle of weight zero), so, as in the
    trap, the least times exist and are the plan: costs 10 each.
    """
    req = trap_request()
    for robot in req["robots"]:
        robot["nodes"][0]["density"] = 3
    for c in req["conflicts"]:
        c.update(a_enter=0.0, a_exit=2.0, b_enter=0.0, b_exit=2.0)
    assignment = ([True] * 3, [FOLLOWING] * 3)
    ref = reference_problem(req)
    assert least_times(ref, *assignment) == [[0, 2, 10]] * 3
    problem, _, result = _evaluate(req, *assignment)
    assert result.completion[0].tolist() == [10, 10, 10]
    assert _costs(result)["avg_completion"] == 10.0


# --- batches and the brute-force reference ---------------------------------------------------


def _random_batch(problem: Problem, seed: int, size: int) -> Assignments:
    rng = np.random.default_rng(seed)
    shape = (size, problem.n_conflicts)
    return Assignments(rng.random(shape) < 0.5, rng.random(shape) < 0.5)


def test_batch_equals_one_by_one() -> None:
    """A batch's delays, completions and costs are those of each sample alone, exactly."""
    for seed in range(10):
        problem = _problem(small_problem(seed))
        ev = Evaluator(problem)
        batch = _random_batch(problem, seed, 16)
        together = ev.evaluate(batch)
        for s in range(batch.n_samples):
            alone = ev.evaluate(batch.take(s))
            np.testing.assert_array_equal(together.event_delay[s], alone.event_delay[0])
            np.testing.assert_array_equal(together.completion[s], alone.completion[0])
            assert together.converged[s] == alone.converged[0]
            for k in OBJECTIVES:  # exactly: searches compare costs of either kind
                assert together.costs[k][s] == alone.costs[k][0]


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    size=st.integers(1, 24),
    threads=st.integers(2, 5),
    stitched=st.booleans(),
)
def test_threads_change_no_number(seed: int, size: int, threads: int, stitched: bool) -> None:
    """Walking a batch in several threads' shares gives exactly the one-thread answer,
    cyclic (non-converging) samples included, whatever the split."""
    request = stitched_problem(seed, 12, 2.5) if stitched else small_problem(seed)
    problem = _problem(request)
    batch = _random_batch(problem, seed, size)
    one = Evaluator(problem).evaluate(batch)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(evaluate, "MIN_THREAD_WORK", 1)  # split even the smallest batch
        many = Evaluator(problem, threads=threads).evaluate(batch)
    np.testing.assert_array_equal(many.event_delay, one.event_delay)
    np.testing.assert_array_equal(many.converged, one.converged)
    for k in OBJECTIVES:
        np.testing.assert_array_equal(many.costs[k], one.costs[k])


def test_threads_must_be_positive() -> None:
    with pytest.raises(ValueError, match="threads"):
        Evaluator(_problem(small_problem(0)), threads=0)


@pytest.mark.parametrize("seed", range(40))
def test_least_times_equal_brute_force(seed: int) -> None:
    """On random assignments (cyclic ones included) of random small problems."""
    req = small_problem(seed) if seed % 2 else tiny_request(seed)
    problem = _problem(req)
    ref = reference_problem(req)
    # The time points are the contract's: sorted distinct times per robot.
    assert [
        problem.tp_time[problem.tp_start[r] : problem.tp_start[r + 1]].tolist()
        for r in range(problem.n_robots)
    ] == ref.time_points
    ev = Evaluator(problem)
    batch = _random_batch(problem, seed, 24)
    result = ev.evaluate(batch)
    for s in range(batch.n_samples):
        a_first, following = batch.a_first[s].tolist(), batch.following[s].tolist()
        times = least_times(ref, a_first, following)
        if not result.converged[s]:
            # Never for an acyclic assignment; for a cyclic one the least times may or may
            # not exist (see the trap), but a positive cycle always means not converged.
            assert not is_acyclic(ref, a_first)
            continue
        assert times is not None
        expect = [
            t - p
            for ts, ps in zip(times, ref.time_points, strict=True)
            for t, p in zip(ts, ps, strict=True)
        ]
        got = ev.delays_at(result, s, np.arange(problem.tp_time.size))
        np.testing.assert_allclose(got, expect, rtol=0, atol=1e-9)
        np.testing.assert_allclose(result.completion[s], [t[-1] for t in times], rtol=1e-12)
        want = costs(ref, times)
        for k in OBJECTIVE_NAMES:
            assert result.costs[k][s] == pytest.approx(want[k], rel=1e-12, abs=1e-9)


def _decoded(problem: Problem, seed: int) -> Assignments:
    """A valid (acyclic) assignment: random priorities and type scores decoded."""
    rng = np.random.default_rng(seed)
    return Decoder(problem, find_cliques(problem)).decode(
        rng.exponential(size=(1, problem.n_nodes)) + 1e-3, rng.random((1, problem.n_conflicts))
    )


@pytest.mark.parametrize("seed", range(6))
def test_only_binding_conflicts_hold_robots_back(seed: int) -> None:
    """Dropping a conflict that is not binding changes no completion time; some bind."""
    request = stitched_problem(seed, 12, 3.0)
    problem = _problem(request)
    assignment = _decoded(problem, seed)
    ev = Evaluator(problem)
    evaluation = ev.evaluate(assignment)
    binding = ev.binding(assignment, evaluation)
    assert binding.any() and not binding.all()
    for c in np.flatnonzero(~binding).tolist():
        kept = np.delete(np.arange(problem.n_conflicts), c)
        without = {**request, "conflicts": [request["conflicts"][k] for k in kept.tolist()]}
        dropped = Evaluator(_problem(without)).evaluate(
            Assignments(assignment.a_first[:, kept], assignment.following[:, kept])
        )
        np.testing.assert_allclose(dropped.completion, evaluation.completion, rtol=1e-12)


def _walked(seed: int, stitched: bool) -> tuple[Problem, Assignments, Evaluator, Evaluation]:
    """A stitched problem of 10 robots (or a small one), a decoded assignment of it, an
    evaluator and its evaluation."""
    problem = _problem(stitched_problem(seed, 10, 3.0) if stitched else small_problem(seed))
    assignment = _decoded(problem, seed)
    ev = Evaluator(problem)
    return problem, assignment, ev, ev.evaluate(assignment)


def _walk_with_floor(problem: Problem, assignment: Assignments, floor: np.ndarray) -> np.ndarray:
    """(E+1,) least delays of one assignment with each event's delay at least ``floor``."""
    ev = Evaluator(problem)
    delay = floor[None].copy()  # (1, E+1) the walk raises lower bounds
    a_first = assignment.a_first.astype(np.uint8)
    following = assignment.following.astype(np.uint8)
    assert evaluate._longest_paths(*ev._fixed, a_first, following, delay)[0]
    return delay[0]


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), stitched=st.booleans())
def test_latest_delays_are_the_latest_that_keep_the_held_events(seed: int, stitched: bool) -> None:
    """Held events (here completions) keep their least delays; any other event delayed
    up to its latest (a floor on it, the rest walked again) leaves every held event where
    it was, and a second past it raises one (or it has no latest: inf)."""
    problem, assignment, ev, evaluation = _walked(seed, stitched)
    rng = np.random.default_rng(seed)
    least = evaluation.event_delay[0]  # (E+1,)
    held = np.zeros(least.size, dtype=bool)
    held[ev.graph.last_event] = True
    latest = ev.latest_delays(assignment, evaluation, held)
    assert (latest >= least - 1e-9).all()
    np.testing.assert_array_equal(latest[held], least[held])
    free = np.flatnonzero(~held[:-1])  # events, the zero-delay source left out
    for e in rng.choice(free, size=min(8, free.size), replace=False) if free.size else ():
        floor = np.zeros(least.size)
        floor[e] = latest[e] if np.isfinite(latest[e]) else least[e] + 1e6
        np.testing.assert_allclose(_walk_with_floor(problem, assignment, floor)[held], least[held])
        if np.isfinite(latest[e]):
            floor[e] = latest[e] + 1.0
            assert (_walk_with_floor(problem, assignment, floor)[held] > least[held] + 0.5).any()


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), stitched=st.booleans(), n_held=st.integers(1, 4))
def test_critical_events_are_those_no_delay_of_which_leaves_the_held_events(
    seed: int, stitched: bool, n_held: int
) -> None:
    """An event is critical to some held events exactly when any rise of its delay (a
    floor on it, the rest walked again) raises one of them by as much; the others can
    rise a little and leave every held event where it was."""
    problem, assignment, ev, evaluation = _walked(seed, stitched)
    rng = np.random.default_rng(seed)
    least = evaluation.event_delay[0]  # (E+1,)
    held = np.zeros(least.size, dtype=bool)
    held[rng.choice(ev.n_events, size=min(n_held, ev.n_events), replace=False)] = True
    critical = ev.critical_slopes(assignment, held.astype(float))[0]  # (E+1,)
    assert critical[held].all()
    latest = ev.latest_delays(assignment, evaluation, held)
    rise = 1e-3
    for e in np.flatnonzero(~held[:-1]):
        floor = np.zeros(least.size)
        floor[e] = least[e] + (rise if critical[e] else min(rise, (latest[e] - least[e]) / 2))
        raised = _walk_with_floor(problem, assignment, floor)[held] - least[held]
        if critical[e]:
            assert raised.max() == pytest.approx(rise, rel=1e-6)
        else:  # room to rise (latest_delays is checked against walks above)
            assert latest[e] > least[e] and raised.max() == pytest.approx(0.0, abs=1e-9)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    stitched=st.booleans(),
    objective=st.sampled_from(evaluate.MONOTONE_OBJECTIVES),
)
def test_no_move_of_a_conflict_whose_wait_is_not_critical_lowers_the_cost(
    seed: int, stitched: bool, objective: str
) -> None:
    """Reversing a conflict or flipping its type lowers a cost of MONOTONE_OBJECTIVES only
    where its wait is critical to what the cost reads (full evaluation of both moves of
    every other conflict; moves that close a cycle cost inf)."""
    _, assignment, ev, evaluation = _walked(seed, stitched)
    critical = ev.critical_waits(assignment, evaluation, objective)  # (M,)
    others = np.flatnonzero(~critical)  # (K,)
    cost = float(evaluation.costs[objective][0])
    for flip_type in (False, True):
        a_first = np.repeat(assignment.a_first, others.size, axis=0)  # (K, M)
        following = np.repeat(assignment.following, others.size, axis=0)
        changed = following if flip_type else a_first
        changed[np.arange(others.size), others] ^= True
        costs = ev.evaluate(Assignments(a_first, following)).costs[objective]  # (K,)
        assert np.all(costs >= cost - 1e-9 * max(1.0, abs(cost)))


def test_cost_weights_refuse_sync_completion() -> None:
    """The spread of sync_completion may fall when a delay rises: no critical events."""
    problem = _problem(small_problem(0))
    ev = Evaluator(problem)
    assignment = _decoded(problem, 0)
    with pytest.raises(ValueError, match="may fall"):
        ev.cost_weights("sync_completion", ev.evaluate(assignment))


@settings(max_examples=30, deadline=None, derandomize=True)
@given(seed=st.integers(0, 10_000), stitched=st.booleans())
def test_slopes_bound_what_a_push_past_the_latest_raises(seed: int, stitched: bool) -> None:
    """An event pushed a little past its latest (a floor on it, the rest walked again)
    pushes held events by as much; their weight is at most the event's slope (which
    counts a held event once per way to it), some are pushed wherever the slope is
    positive, and no slope exceeds the total held weight."""
    request = stitched_problem(seed, 10, 3.0) if stitched else small_problem(seed)
    problem = _problem(request)
    rng = np.random.default_rng(seed)
    assignment = _decoded(problem, seed)
    ev = Evaluator(problem)
    weight = np.zeros(ev.n_events + 1)  # (E+1,) held events by weight: completions
    weight[ev.graph.last_event] = rng.uniform(0.5, 2.0, ev.graph.last_event.size)
    slope = np.empty(ev.n_events + 1)
    evaluation, latest = ev.evaluate_with_latest(assignment, weight, slope)
    assert latest is not None
    least, held = evaluation.event_delay[0], weight > 0
    assert (slope[:-1] <= weight.sum() + 1e-9).all() and (slope[held] >= weight[held]).all()
    eps = 1e-6
    for e in rng.choice(ev.n_events, size=min(12, ev.n_events), replace=False):
        if not np.isfinite(latest[e]):
            continue
        floor = np.zeros(least.size)
        floor[e] = latest[e] + eps
        rise = _walk_with_floor(problem, assignment, floor) - least  # (E+1,)
        assert weight[rise >= eps * (1 - 1e-3)].sum() <= slope[e] + 1e-9
        assert (slope[e] > 0) == bool((rise[held] > eps / 2).any())


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), stitched=st.booleans(), decoded=st.booleans())
def test_evaluate_with_latest_is_evaluate_and_latest_delays(
    seed: int, stitched: bool, decoded: bool
) -> None:
    """One walk gives what :meth:`evaluate` and :meth:`latest_delays` give apart; an
    assignment with a cycle (random directions often close one) gets no latest delays
    and its cyclic evaluation."""
    request = stitched_problem(seed, 10, 3.0) if stitched else small_problem(seed)
    problem = _problem(request)
    ev = Evaluator(problem)
    if decoded:
        assignment = _decoded(problem, seed)
    else:
        rng = np.random.default_rng(seed)
        assignment = Assignments.single(
            rng.random(problem.n_conflicts) < 0.5, rng.random(problem.n_conflicts) < 0.3
        )
    held = np.random.default_rng(seed + 1).random(ev.n_events + 1) < 0.5
    evaluation, latest = ev.evaluate_with_latest(assignment, held)
    apart = ev.evaluate(assignment)
    np.testing.assert_array_equal(evaluation.event_delay, apart.event_delay)
    for objective in apart.costs:
        np.testing.assert_array_equal(evaluation.costs[objective], apart.costs[objective])
    if latest is None:
        assert not decoded
        with pytest.raises(ValueError, match="cycle"):
            ev.latest_delays(assignment, apart, held)
    else:
        np.testing.assert_array_equal(latest, ev.latest_delays(assignment, apart, held))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    stitched=st.booleans(),
    objective=st.sampled_from(["avg_completion", "avg_delay"]),
    shift=st.sampled_from([-0.1, -1e-6, 0.0, 1e-6, 0.1]),
)
def test_evaluate_with_latest_below_skips_only_answers_not_cheaper(
    seed: int, stitched: bool, objective: str, shift: float
) -> None:
    """With ``below``, the evaluation is the same; the latest delays are the same where
    the cost is below it, and none where it is not (beyond rounding)."""
    request = stitched_problem(seed, 10, 3.0) if stitched else small_problem(seed)
    problem = _problem(request)
    ev = Evaluator(problem)
    assignment = _decoded(problem, seed)
    held = ev.held_weights(objective)
    full, latest = ev.evaluate_with_latest(assignment, held)
    cost = float(full.costs[objective][0])
    below = cost * (1 + shift) + shift
    bounded, bounded_latest = ev.evaluate_with_latest(assignment, held, below=(objective, below))
    np.testing.assert_array_equal(bounded.event_delay, full.event_delay)
    assert float(bounded.costs[objective][0]) == cost
    if cost < below:
        assert latest is not None and bounded_latest is not None
        np.testing.assert_array_equal(bounded_latest, latest)
    elif shift < 0:
        assert bounded_latest is None
    with pytest.raises(ValueError, match="not a sum"):
        ev.evaluate_with_latest(assignment, held, below=("max_completion", below))


@pytest.mark.parametrize("seed", range(8))
def test_binding_matches_its_definition(seed: int) -> None:
    """The compiled loop marks exactly the conflicts whose active slot's constraint holds
    with equality at a positive wait (the definition, in numpy gathers here)."""
    problem = _problem(stitched_problem(seed, 12, 3.0) if seed % 2 else small_problem(seed))
    ev = Evaluator(problem)
    assignment = _decoded(problem, seed)
    evaluation = ev.evaluate(assignment)
    delay, a_first = evaluation.event_delay[0], assignment.a_first[0]
    slot = 2 * np.arange(a_first.size) + a_first  # (M,)
    kind = assignment.following[0].astype(np.intp)
    wait = delay[ev.graph.target[slot]]
    tol = 1e-9 * max(1.0, float(np.abs(problem.tp_time).max()))
    tight = np.abs(wait - delay[ev.graph.source[kind, slot]] - ev.graph.offset[kind, slot]) <= tol
    expected = (wait > tol) & tight & ~problem.realized
    np.testing.assert_array_equal(ev.binding(assignment, evaluation), expected)


def test_latest_delays_refuse_a_cycle() -> None:
    problem = _problem(trap_request())
    ev = Evaluator(problem)
    cyclic = Assignments.single([True] * 3, [False] * 3)  # a positive cycle: no least times
    with pytest.raises(ValueError, match="cycle"):
        ev.latest_delays(cyclic, ev.evaluate(cyclic), np.ones(ev.n_events + 1, dtype=bool))


@pytest.mark.parametrize("seed", range(6))
def test_objective_weights_sum_the_objectives(seed: int) -> None:
    """The event delays weighted by them give avg_delay, and avg_completion less the free
    cost times the robots; a maximum or the synchronised mean has none."""
    problem = _problem(stitched_problem(seed, 12, 3.0) if seed % 2 else small_problem(seed))
    ev = Evaluator(problem)
    batch = _random_batch(problem, seed, 8)
    result = ev.evaluate(batch)
    ok = result.converged
    delay = result.event_delay[ok]  # (S, E+1)
    np.testing.assert_allclose(
        delay @ ev.objective_weights("avg_delay"), result.costs["avg_delay"][ok]
    )
    free = ev.free_costs()["avg_completion"]
    np.testing.assert_allclose(
        delay @ ev.objective_weights("avg_completion") / problem.n_robots + free,
        result.costs["avg_completion"][ok],
    )
    for objective in ("max_completion", "sync_completion"):
        with pytest.raises(ValueError, match="sum"):
            ev.objective_weights(objective)


@pytest.mark.parametrize("seed", range(6))
def test_held_weights_hold_avg_delay_by_each_robots_completion(seed: int) -> None:
    """avg_completion holds its own weights; avg_delay each robot's completion event,
    weighing the robot's events' weights summed (the same total), so that a held robot
    may wait longer on its way where its completion waits for a later wait (its latest
    delays there above its least), which holding every event never allows."""
    problem = _problem(stitched_problem(seed, 12, 3.0) if seed % 2 else small_problem(seed))
    ev = Evaluator(problem)
    np.testing.assert_array_equal(
        ev.held_weights("avg_completion"), ev.objective_weights("avg_completion")
    )
    weight, held = ev.objective_weights("avg_delay"), ev.held_weights("avg_delay")
    last = ev.objective_weights("avg_completion") > 0  # (E+1,) the completion events
    assert (held[~last] == 0).all() and (held[last] > 0).all()
    event_robot = problem.tp_robot[problem.events]  # (E,)
    np.testing.assert_allclose(
        np.bincount(event_robot, held[:-1], problem.n_robots),
        np.bincount(event_robot, weight[:-1], problem.n_robots),
    )
    assignment = _random_batch(problem, seed, 1)
    evaluation = ev.evaluate(assignment)
    if not evaluation.converged[0]:
        return
    every = ev.latest_delays(assignment, evaluation, weight > 0)
    by_completion = ev.latest_delays(assignment, evaluation, held > 0)
    np.testing.assert_allclose(every[:-1], evaluation.event_delay[0, :-1])  # no room
    assert (by_completion >= every - 1e-9).all()
    assert (by_completion > every + 1e-9).any()  # these seeds' answers have room
    for objective in ("max_completion", "sync_completion"):
        with pytest.raises(ValueError, match="sum"):
            ev.held_weights(objective)


def test_an_empty_batch_has_empty_results() -> None:
    problem = _problem(small_problem(3))
    empty = np.zeros((0, problem.n_conflicts), dtype=bool)
    result = Evaluator(problem).evaluate(Assignments(empty, empty))
    assert result.completion.shape == (0, problem.n_robots)
    assert all(result.costs[k].shape == (0,) for k in OBJECTIVES)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    rows=st.integers(1, 12).flatmap(  # robots, then 1-5 rows of that many completions
        lambda robots: st.lists(
            st.lists(st.floats(0.0, 1e5), min_size=robots, max_size=robots),
            min_size=1,
            max_size=5,
        )
    )
)
def test_completion_costs_are_the_mean_the_max_and_the_mean_plus_spread(
    rows: list[list[float]],
) -> None:
    """avg, max and sync completion of every row of a batch (one robot too) are its mean,
    its max and its mean plus its mean absolute deviation, and each row's are bit for
    bit those of the row alone."""
    completion = np.array(rows)  # (S, R)
    got = evaluate.costs_from_completion(completion)
    mean = completion.mean(axis=1)
    spread = np.abs(completion - mean[:, None]).mean(axis=1)
    np.testing.assert_allclose(got["avg_completion"], mean, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(got["max_completion"], completion.max(axis=1))
    np.testing.assert_allclose(got["sync_completion"], mean + spread, rtol=1e-12, atol=1e-9)
    for s, row in enumerate(completion):
        alone = evaluate.costs_from_completion(row[None, :])
        assert all(alone[k][0] == got[k][s] for k in got)
