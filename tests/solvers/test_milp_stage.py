"""``auto``'s exact stage ending with the MILP backend (``exact.improve``,
MILP_STAGE_OBJECTIVES): its proofs against brute force, the cross-checks that void a
proof, the time split, and a proof CP-SAT does not reach."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path

import pytest

from service.core.assignment import Assignments
from service.core.decompose import parts
from service.core.problem import Problem, problem_from_request
from service.core.schemas import Objective, ScheduleRequest
from service.solvers import exact, portfolio
from service.solvers.exact import MILP_NAME, ExactResult, improve
from service.solvers.fcfs import fcfs
from service.solvers.milp import MilpResult, solve_milp
from service.solvers.registry import SolveContext, SolverOutput, get_solver
from tests.reference import Candidate, feasible_assignments, reference_problem, tiny_request

TIME_LIMIT_S = 30.0  # generous: tiny problems solve in milliseconds
REL = 1e-6
DATA = Path(__file__).resolve().parents[1] / "data" / "conformance"


def _context(seed: int, objective: Objective = "avg_delay") -> SolveContext:
    req = ScheduleRequest.model_validate(tiny_request(seed))
    return SolveContext(problem_from_request(req), objective, TIME_LIMIT_S)


@cache
def _brute(seed: int) -> list[Candidate]:
    return feasible_assignments(reference_problem(tiny_request(seed)))


def _single(candidate: Candidate) -> Assignments:
    return Assignments.single(candidate.a_first, candidate.following)


def _worst_and_best(seed: int) -> tuple[Candidate, Candidate]:
    ranked = sorted(_brute(seed), key=lambda c: c.costs["avg_delay"])
    return ranked[-1], ranked[0]


def _start(ctx: SolveContext, candidate: Candidate) -> SolverOutput:
    return SolverOutput(_single(candidate))


def _no_cpsat(monkeypatch: pytest.MonkeyPatch) -> None:
    """CP-SAT finds nothing: the stage's answer can only be the MILP's or the hint."""
    monkeypatch.setattr(exact, "solve", lambda *args, **kwargs: None)


@pytest.mark.parametrize("seed", range(12))
def test_the_milp_stage_proves_the_brute_force_optimum(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With CP-SAT finding nothing, the MILP stage proves avg_delay's optimum from the
    dearest valid answer: the evaluator's cost of its answer is the brute-force optimum."""
    _no_cpsat(monkeypatch)
    ctx = _context(seed)
    worst, best = _worst_and_best(seed)
    found, verdict = improve(ctx, _start(ctx, worst), TIME_LIMIT_S)
    assert found.optimal and verdict == f"proven optimal by {MILP_NAME}"
    assert ctx.cost(found.assignment) == pytest.approx(best.costs["avg_delay"], rel=REL, abs=1e-9)


def _fake_milp(
    monkeypatch: pytest.MonkeyPatch, answer: Assignments, objective: float
) -> list[float]:
    """solve_milp returning ``answer`` as proven with ``objective``; the time limits it
    was given."""
    limits: list[float] = []

    def fake(problem, cliques, evaluator, objective_name, time_limit_s, cost_bound):  # noqa: ANN001, ANN202
        limits.append(time_limit_s)
        return MilpResult(answer, True, objective, objective, 0.0, 0.0)

    monkeypatch.setattr(exact, "solve_milp", fake)
    return limits


def test_a_proof_the_evaluator_contradicts_is_not_taken(monkeypatch: pytest.MonkeyPatch) -> None:
    """A MILP 'optimum' whose objective value is not the evaluator's cost of its answer
    is kept as an answer where cheaper, never as proven."""
    _no_cpsat(monkeypatch)
    seed = next(s for s in range(50) if len({c.costs["avg_delay"] for c in _brute(s)}) > 1)
    ctx = _context(seed)
    worst, best = _worst_and_best(seed)
    _fake_milp(monkeypatch, _single(best), 0.5 * best.costs["avg_delay"] - 1.0)
    found, verdict = improve(ctx, _start(ctx, worst), TIME_LIMIT_S)
    assert not found.optimal and verdict == f"improved by {MILP_NAME}"
    assert ctx.cost(found.assignment) == pytest.approx(best.costs["avg_delay"], rel=REL)


def test_a_cheaper_cpsat_answer_voids_the_milp_proof(monkeypatch: pytest.MonkeyPatch) -> None:
    """CP-SAT's unproven answer cheaper than a 'proven' MILP answer: HiGHS erred; CP-SAT's
    answer is kept, unproven."""
    seed = next(s for s in range(50) if len({c.costs["avg_delay"] for c in _brute(s)}) > 2)
    ctx = _context(seed)
    worst, best = _worst_and_best(seed)
    middle = sorted(_brute(seed), key=lambda c: c.costs["avg_delay"])[len(_brute(seed)) // 2]
    unproven = ExactResult(_single(best), False, 0.0, 0.5)
    monkeypatch.setattr(exact, "solve", lambda *args, **kwargs: unproven)
    _fake_milp(monkeypatch, _single(middle), middle.costs["avg_delay"])
    found, verdict = improve(ctx, _start(ctx, worst), TIME_LIMIT_S)
    assert not found.optimal and verdict == "improved by CP-SAT"
    assert ctx.cost(found.assignment) == pytest.approx(best.costs["avg_delay"], rel=REL)


def test_a_hint_as_cheap_as_the_milp_proof_is_proven(monkeypatch: pytest.MonkeyPatch) -> None:
    """The MILP proves an answer whose cost the evaluator reads a bit above the hint's
    (another summation order; within the proof's tolerance): the hint is kept, proven."""
    _no_cpsat(monkeypatch)
    seed = next(s for s in range(50) if len({c.costs["avg_delay"] for c in _brute(s)}) > 1)
    ctx = _context(seed)
    worst, best = _worst_and_best(seed)
    _fake_milp(monkeypatch, _single(worst), best.costs["avg_delay"])
    evaluate = ctx.evaluator.evaluate

    def worst_as_best(assignments: Assignments):  # noqa: ANN202
        """The worst answer read one part in 1e9 above the best's cost."""
        found = evaluate(assignments)
        worst_rows = (assignments.a_first == worst.a_first).all(axis=1) & (
            assignments.following == worst.following
        ).all(axis=1)
        found.costs["avg_delay"][worst_rows] = best.costs["avg_delay"] * (1 + 1e-9)
        return found

    monkeypatch.setattr(ctx.evaluator, "evaluate", worst_as_best)
    found, verdict = improve(ctx, _start(ctx, best), TIME_LIMIT_S)
    assert found.optimal and verdict == f"proven optimal by {MILP_NAME}"
    assert ctx.cost(found.assignment) == pytest.approx(best.costs["avg_delay"], rel=REL)


def test_a_hint_cheaper_than_the_milp_proof_voids_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """The MILP 'proves' an answer dearer than the hint: HiGHS erred; the hint is kept,
    unproven."""
    _no_cpsat(monkeypatch)
    seed = next(s for s in range(50) if len({c.costs["avg_delay"] for c in _brute(s)}) > 1)
    ctx = _context(seed)
    worst, best = _worst_and_best(seed)
    _fake_milp(monkeypatch, _single(worst), worst.costs["avg_delay"])
    found, verdict = improve(ctx, _start(ctx, best), TIME_LIMIT_S)
    assert not found.optimal and verdict == f"{MILP_NAME} did not improve"
    assert ctx.cost(found.assignment) == pytest.approx(best.costs["avg_delay"], rel=REL)


def _cpsat_unproven(monkeypatch: pytest.MonkeyPatch, answer: Assignments) -> list[float]:
    """CP-SAT returning ``answer`` unproven; the time limits it was given."""
    limits: list[float] = []

    def unproven(problem, cliques, objective, time_limit_s, **kwargs):  # noqa: ANN001, ANN202
        limits.append(time_limit_s)
        return ExactResult(answer, False, 0.0, 0.5)

    monkeypatch.setattr(exact, "solve", unproven)
    return limits


def test_cpsat_gets_its_share_and_the_milp_the_rest(monkeypatch: pytest.MonkeyPatch) -> None:
    """CP-SAT searches for 1 - MILP_STAGE_SHARE of the stage's time (at least
    MILP_STAGE_CPSAT_LEAST_S), the MILP until its deadline; where CP-SAT proves, or the
    stage is no longer than CP-SAT's least, the MILP never runs."""
    ctx = _context(0)
    worst, best = _worst_and_best(0)
    cpsat = _cpsat_unproven(monkeypatch, _single(worst))
    milp = _fake_milp(monkeypatch, _single(best), best.costs["avg_delay"])
    found, verdict = improve(ctx, _start(ctx, worst), 2.0)
    assert found.optimal and verdict == f"proven optimal by {MILP_NAME}"
    cpsat_s = max(2.0 * (1 - exact.MILP_STAGE_SHARE), exact.MILP_STAGE_CPSAT_LEAST_S)
    assert cpsat == [pytest.approx(cpsat_s)]
    assert len(milp) == 1 and 2.0 - cpsat_s - 0.1 < milp[0] <= 2.0  # the rest: CP-SAT was quick
    monkeypatch.setattr(exact, "solve", lambda *a, **k: ExactResult(_single(best), True, 0.0))
    found, verdict = improve(ctx, _start(ctx, worst), 2.0)
    assert found.optimal and verdict == "proven optimal by CP-SAT" and len(milp) == 1
    cpsat = _cpsat_unproven(monkeypatch, _single(worst))
    found, _ = improve(ctx, _start(ctx, worst), exact.MILP_STAGE_CPSAT_LEAST_S)
    assert not found.optimal and len(milp) == 1
    assert cpsat == [pytest.approx(exact.MILP_STAGE_CPSAT_LEAST_S)]


@pytest.mark.parametrize("objective", ["avg_completion", "max_completion", "sync_completion"])
def test_other_objectives_keep_cpsat_alone(
    objective: Objective, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Outside MILP_STAGE_OBJECTIVES the stage is CP-SAT's, for all of its time."""
    assert objective not in exact.MILP_STAGE_OBJECTIVES
    ctx = _context(0, objective)
    limits = _cpsat_unproven(monkeypatch, fcfs(ctx).assignment)
    milp = _fake_milp(monkeypatch, fcfs(ctx).assignment, 0.0)
    found, _ = improve(ctx, fcfs(ctx), 2.0)
    assert not found.optimal and limits == [2.0] and milp == []


def _largest_part(set_name: str, index: int) -> Problem:
    """The largest component of a conformance problem."""
    rec = json.loads((DATA / f"{set_name}.jsonl").read_text().splitlines()[index])
    problem = problem_from_request(ScheduleRequest.model_validate(rec["request"]))
    return max(parts(problem), key=lambda p: p.problem.n_conflicts).problem


def test_the_milp_stage_proves_what_cpsat_does_not() -> None:
    """The largest component of the conformance problem wh_100/0 posed for avg_delay (75
    robots, 189 conflicts): CP-SAT alone does not prove it in 4 s; the stage, its last
    MILP_STAGE_SHARE the MILP's, proves the optimum a long MILP run proves too."""
    ctx = SolveContext(_largest_part("wh_100", 0), "avg_delay", 4.0)
    alone = exact.solve(ctx.problem, ctx.cliques, "avg_delay", 4.0, hint=fcfs(ctx).assignment)
    assert alone is not None and not alone.optimal
    found, verdict = improve(ctx, fcfs(ctx), 4.0)
    assert found.optimal and verdict == f"proven optimal by {MILP_NAME}"
    milp = solve_milp(ctx.problem, ctx.cliques, ctx.evaluator, "avg_delay", 60.0)
    assert milp is not None and milp.optimal
    assert ctx.cost(found.assignment) == pytest.approx(milp.objective, rel=REL)


def test_larger_problems_keep_cpsat_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    """Above MILP_STAGE_MAX_CONFLICTS conflicts avg_delay's stage is CP-SAT's, for all of
    its time."""
    ctx = _context(0)
    monkeypatch.setattr(exact, "MILP_STAGE_MAX_CONFLICTS", ctx.problem.n_conflicts - 1)
    limits = _cpsat_unproven(monkeypatch, fcfs(ctx).assignment)
    milp = _fake_milp(monkeypatch, fcfs(ctx).assignment, 0.0)
    found, _ = improve(ctx, fcfs(ctx), 2.0)
    assert not found.optimal and limits == [2.0] and milp == []


def test_lns_before_the_stage_is_patient_only_where_no_step_frees_the_fleet(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``auto``: LNS before the MILP stage ends on MILP_LNS_PATIENCE_S where the fleet has
    more robots than LNS frees at most (wh_100/0's largest component, 75 robots), not on
    a fleet it may free whole (wh_25/4's, 25 robots), nor before CP-SAT alone
    (avg_completion)."""
    patience: list[tuple[int, str, float | None]] = []
    search = portfolio.lns_search

    def recorded(ctx: SolveContext, *args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        patience.append((ctx.problem.n_robots, ctx.objective, kwargs.get("patience_s")))
        return search(ctx, *args, **kwargs)

    monkeypatch.setattr(portfolio, "lns_search", recorded)
    for problem, objective in [
        (_largest_part("wh_100", 0), "avg_delay"),
        (_largest_part("wh_100", 0), "avg_completion"),
        (_largest_part("wh_25", 4), "avg_delay"),
    ]:
        assert problem.n_conflicts <= exact.MILP_STAGE_MAX_CONFLICTS
        get_solver("auto")(SolveContext(problem, objective, 1.0, exact_max_conflicts=20))
    assert patience == [
        (75, "avg_delay", portfolio.MILP_LNS_PATIENCE_S),
        (75, "avg_completion", None),
        (25, "avg_delay", None),
    ]
