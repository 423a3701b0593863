"""The exact CP-SAT solver against brute-force enumeration, top-L, time limits, determinism."""

from __future__ import annotations

import time
from dataclasses import replace
from functools import cache
from typing import Any

import numpy as np
import pytest

from service.core.assignment import Assignments
from service.core.check import check
from service.core.evaluate import Evaluator
from service.core.problem import problem_from_request
from service.core.schemas import OBJECTIVES, Objective, ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from service.solvers.exact import (
    build_seconds,
    exact,
    integer_times,
    literal_domains,
    solve,
    time_slots,
    top_assignments,
)
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext
from tests.reference import (
    Candidate,
    costs,
    density_groups,
    density_ok,
    feasible_assignments,
    is_acyclic,
    least_times,
    reference_problem,
    tiny_request,
    trap_request,
)

TIME_LIMIT_S = 30.0  # generous: tiny problems solve in milliseconds
TINY_SEEDS = range(60)
TOP_SEEDS = range(16)
TOP_COUNT = 6
REL = 1e-9


def _context(req: dict[str, Any], objective: Objective = "avg_completion") -> SolveContext:
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    return SolveContext(problem, objective, TIME_LIMIT_S)


@cache
def _brute(seed: int) -> list[Candidate]:
    return feasible_assignments(reference_problem(tiny_request(seed)))


def _cost(ctx: SolveContext, assignment: Assignments, objective: Objective) -> float:
    return float(ctx.evaluator.evaluate(assignment).costs[objective][0])


@pytest.mark.parametrize("seed", TINY_SEEDS)
def test_optimum_equals_brute_force(seed: int) -> None:
    """All 2^M directions x 2^M types, filtered by acyclicity and density, for each objective."""
    req = tiny_request(seed)
    ref = reference_problem(req)
    candidates = _brute(seed)
    ctx = _context(req)
    for objective in OBJECTIVES:
        best = min(c.costs[objective] for c in candidates)
        result = solve(ctx.problem, ctx.cliques, objective, TIME_LIMIT_S, seed=0, workers=1)
        assert result is not None and result.optimal, objective
        a_first = result.assignment.a_first[0].tolist()
        following = result.assignment.following[0].tolist()
        # Valid by the reference's own rules, and optimal by its own least times.
        assert is_acyclic(ref, a_first)
        assert density_ok(density_groups(ref), following)
        got = costs(ref, least_times(ref, a_first, following))[objective]
        assert got == pytest.approx(best, rel=REL), objective
        assert _cost(ctx, result.assignment, objective) == pytest.approx(best, rel=REL), objective


def test_tiny_problems_cover_what_matters() -> None:
    """The tiny set exercises following types, binding budgets and explicit limits."""
    binding = limits = following_wins = 0
    for seed in TINY_SEEDS:
        req = tiny_request(seed)
        ctx = _context(req)
        binding += bool(ctx.cliques.binding().any())
        limits += bool(req.get("density_limits"))
        candidates = _brute(seed)
        best = min(c.costs["avg_completion"] for c in candidates)
        exclusive_best = min(
            (c.costs["avg_completion"] for c in candidates if not any(c.following)),
        )
        following_wins += best < exclusive_best
    assert binding >= 10
    assert limits >= 10
    assert following_wins >= 10
    assert sum(bool(_context(tiny_request(s)).cliques.forbidden().any()) for s in TINY_SEEDS) >= 10


@pytest.mark.parametrize("seed", TINY_SEEDS)
def test_typed_slots_bind_as_all_slots_do(seed: int) -> None:
    """Dropping the rows a conflict's type domain makes redundant (never following-type:
    its following-level rows; always following-type, as realized ones of a re-schedule
    are: its exclusive-level rows) leaves every event's least delay behind its waits as
    it was, for any assignment the domains allow."""
    ctx = _context(tiny_request(seed))
    p = ctx.problem
    scale, ti, _ = integer_times(p)
    grid = Evaluator(replace(p, tp_time=ti / scale))
    _, _, f_lo, f_hi = literal_domains(p, ctx.cliques.forbidden())
    rng = np.random.default_rng(seed)
    f_lo = np.where(rng.random(p.n_conflicts) < 0.3, f_hi, f_lo)  # some always following
    every = time_slots(p, ti, np.arange(p.n_conflicts))
    typed = every.typed(f_lo, f_hi)
    assert typed.conflict.size < every.conflict.size or (f_lo == f_hi).sum() == 0
    for _ in range(8):
        a_first = rng.random(p.n_conflicts) < 0.5
        following = np.where(f_lo == f_hi, f_lo == 1, rng.random(p.n_conflicts) < 0.5)
        delay = np.rint(
            grid.evaluate(Assignments.single(a_first, following)).event_delay[0] * scale
        )
        waits = []
        for slots in (every, typed):
            bound = np.zeros(delay.size)  # (E+1,) the most each event waits for
            on = slots.active(a_first, following)
            np.maximum.at(bound, slots.target[on], delay[slots.source[on]] + slots.offset[on])
            waits.append(bound)
        np.testing.assert_array_equal(waits[0], waits[1])


@pytest.mark.parametrize("objective", OBJECTIVES)
@pytest.mark.parametrize("seed", TOP_SEEDS)
def test_top_assignments_match_brute_force(seed: int, objective: Objective) -> None:
    ctx = _context(tiny_request(seed), objective)
    found = top_assignments(ctx.problem, ctx.cliques, objective, TOP_COUNT, TIME_LIMIT_S)
    everything = sorted(c.costs[objective] for c in _brute(seed))
    assert len(found) == min(TOP_COUNT, len(everything))
    assert all(r.optimal for r in found)
    keys = {(r.assignment.a_first.tobytes(), r.assignment.following.tobytes()) for r in found}
    assert len(keys) == len(found)  # distinct
    batch = Assignments(
        np.concatenate([r.assignment.a_first for r in found]),
        np.concatenate([r.assignment.following for r in found]),
    )
    assert check(ctx.problem, ctx.cliques, batch).ok.all()
    got = ctx.evaluator.evaluate(batch).costs[objective]
    assert np.all(np.diff(got) >= -1e-9 * np.abs(got[1:]))  # non-decreasing
    best = solve(ctx.problem, ctx.cliques, objective, TIME_LIMIT_S)
    assert best is not None
    assert got[0] == pytest.approx(_cost(ctx, best.assignment, objective), rel=REL)
    np.testing.assert_allclose(got, everything[: len(found)], rtol=REL)


def test_top_assignments_returns_all_when_fewer_exist() -> None:
    # The trap with density 1: every conflict exclusive, 6 acyclic orders of 3 robots.
    ctx = _context(trap_request())
    found = top_assignments(ctx.problem, ctx.cliques, "avg_completion", 20, TIME_LIMIT_S)
    assert len(found) == 6
    assert len({r.assignment.a_first.tobytes() for r in found}) == 6


def test_trap_answer_is_acyclic() -> None:
    req = trap_request()
    ref = reference_problem(req)
    best_acyclic = feasible_assignments(ref)
    ctx = _context(req)
    for objective in OBJECTIVES:
        result = solve(ctx.problem, ctx.cliques, objective, TIME_LIMIT_S)
        assert result is not None and result.optimal
        assert check(ctx.problem, ctx.cliques, result.assignment).ok.tolist() == [True]
        # Not the free node cycle (cost 10 each): someone must wait.
        cost = _cost(ctx, result.assignment, objective)
        assert cost == pytest.approx(min(c.costs[objective] for c in best_acyclic), rel=REL)
        assert cost > ctx.evaluator.free_costs()[objective]


def test_exact_declines_when_building_alone_would_overrun() -> None:
    """Where the model's building estimate exceeds the limit, the solver answers None at
    once (the dispatcher then answers FCFS) instead of building past the limit; given
    the time, the same problem is solved."""
    problem = problem_from_request(ScheduleRequest.model_validate(stitched_problem(1, 250, 4.0)))
    ctx = SolveContext(problem, "avg_completion", 0.05)
    assert build_seconds(problem, ctx.cliques, ctx.objective) > 0.05
    start = time.perf_counter()
    assert exact(ctx) is None
    assert time.perf_counter() - start < 0.05
    roomy = SolveContext(
        problem, "avg_completion", 10 * build_seconds(problem, ctx.cliques, ctx.objective)
    )
    roomy.__dict__["cliques"] = ctx.cliques
    out = exact(roomy)
    assert out is not None
    assert check(problem, ctx.cliques, out.assignment).ok.tolist() == [True]


def test_tiny_time_limit_is_honoured() -> None:
    """60 robots, 240 conflicts: far from solved within these limits.

    The limits are wall-clock, so whether a given short solve finds anything
    depends on the machine's load; what must hold is the time bound and that
    every answer found is valid.
    """
    ctx = _context(stitched_problem(3, 60, 4.0))
    hint = fcfs(ctx).assignment
    answers = []
    for objective, limits in (("avg_completion", (0.001, 0.1, 1.0)), ("sync_completion", (0.01,))):
        for limit in limits:
            start = time.perf_counter()
            result = solve(ctx.problem, ctx.cliques, objective, limit, workers=1, hint=hint)
            assert time.perf_counter() - start < limit + 2.0  # model building included
            answers.append(result)
        start = time.perf_counter()
        answers += top_assignments(ctx.problem, ctx.cliques, objective, 3, 0.05)
        assert time.perf_counter() - start < 3 * 0.05 + 3.0
    found = [r for r in answers if r is not None]
    assert found  # the hinted 1 s solve at least
    for result in found:
        assert check(ctx.problem, ctx.cliques, result.assignment).ok.tolist() == [True]


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_same_seed_one_worker_same_assignment(objective: Objective) -> None:
    for seed in (11, 12, 13):
        ctx = _context(small_problem(seed), objective)
        runs = [
            solve(ctx.problem, ctx.cliques, objective, TIME_LIMIT_S, seed=7, workers=1)
            for _ in range(2)
        ]
        assert runs[0] is not None and runs[1] is not None
        np.testing.assert_array_equal(runs[0].assignment.a_first, runs[1].assignment.a_first)
        np.testing.assert_array_equal(runs[0].assignment.following, runs[1].assignment.following)


def test_registered_solver_is_warm_started_and_optimal() -> None:
    for seed in range(5):
        ctx = _context(small_problem(seed), "max_completion")
        out = exact(ctx)
        assert out is not None and out.optimal
        assert check(ctx.problem, ctx.cliques, out.assignment).ok.tolist() == [True]
        result = solve(ctx.problem, ctx.cliques, "max_completion", TIME_LIMIT_S)
        assert result is not None
        assert _cost(ctx, out.assignment, "max_completion") == pytest.approx(
            _cost(ctx, result.assignment, "max_completion"), rel=REL
        )


def test_no_conflicts() -> None:
    req = small_problem(0)
    req["conflicts"] = []
    ctx = _context(req)
    for objective in OBJECTIVES:
        result = solve(ctx.problem, ctx.cliques, objective, TIME_LIMIT_S)
        assert result is not None and result.optimal
        assert result.assignment.a_first.shape == (1, 0)
        assert _cost(ctx, result.assignment, objective) == ctx.evaluator.free_costs()[objective]
