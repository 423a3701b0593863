"""CP-SAT tuning: the configurations bench.cpsat compares reach the brute-force optimum,
``search`` runs a built model, a misspelt parameter fails loudly, only sync_completion
searches with the LP, and the deterministic mode repeats itself."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from service.api.runtime import dispatch_policy
from service.core.problem import problem_from_request
from service.core.schemas import OBJECTIVES, Objective, OptionsIn, ScheduleRequest
from service.settings import Settings
from service.solvers.dispatch import dispatch
from service.solvers.exact import DTIME_PER_S, Tuning, build_model, search, solve
from service.solvers.fcfs import fcfs
from service.solvers.registry import SolveContext
from tests.reference import feasible_assignments, reference_problem, tiny_request

DATA = Path(__file__).resolve().parents[1] / "data" / "conformance"
TIME_LIMIT_S = 30.0  # generous: tiny problems solve in milliseconds
REL = 1e-9
TUNINGS: dict[str, Tuning] = {
    "linearization 0": {"linearization_level": 0},
    "linearization 2": {"linearization_level": 2},
    "CP-SAT's default probing": {"cp_model_probing_level": 2},
    "interleaved": {"interleave_search": True},
    "LNS only": {"use_lns_only": True},
    "deterministic time": {"max_deterministic_time": 10.0},
}


def _context(seed: int, objective: Objective) -> SolveContext:
    req = ScheduleRequest.model_validate(tiny_request(seed))
    return SolveContext(problem_from_request(req), objective, TIME_LIMIT_S)


@pytest.mark.parametrize("name", [n for n in TUNINGS if n != "LNS only"])
@pytest.mark.parametrize("objective", OBJECTIVES)
def test_tuned_searches_prove_the_brute_force_optimum(name: str, objective: Objective) -> None:
    for seed in range(8):
        ctx = _context(seed, objective)
        best = min(
            c.costs[objective] for c in feasible_assignments(reference_problem(tiny_request(seed)))
        )
        for workers in (1, 2):
            result = solve(
                ctx.problem,
                ctx.cliques,
                objective,
                TIME_LIMIT_S,
                workers=workers,
                tuning=TUNINGS[name],
            )
            assert result is not None and result.optimal, (seed, workers)
            cost = float(ctx.evaluator.evaluate(result.assignment).costs[objective][0])
            assert cost == pytest.approx(best, rel=REL), (seed, workers)
            assert result.deterministic_time >= 0.0


def test_lns_only_workers_keep_a_valid_answer_and_never_prove_worse() -> None:
    """LNS alone cannot prove (it searches neighbourhoods), but what it returns is no worse
    than the optimum and valid; with 2 workers, within the limit."""
    for seed in range(8):
        ctx = _context(seed, "avg_completion")
        optimum = solve(ctx.problem, ctx.cliques, "avg_completion", TIME_LIMIT_S)
        result = solve(
            ctx.problem, ctx.cliques, "avg_completion", 1.0, workers=2, tuning=TUNINGS["LNS only"]
        )
        assert optimum is not None and result is not None
        got, best = (
            float(ctx.evaluator.evaluate(r.assignment).costs["avg_completion"][0])
            for r in (result, optimum)
        )
        assert got >= best - REL * abs(best)


def test_only_sync_completion_searches_with_the_lp() -> None:
    """Level 0 measured best for every objective but sync_completion (exact.py)."""
    ctx = _context(3, "avg_completion")
    levels = {o: build_model(ctx.problem, ctx.cliques, o).linearization for o in OBJECTIVES}
    assert levels == {o: int(o == "sync_completion") for o in OBJECTIVES}


def test_the_service_searches_without_probing() -> None:
    """Probing in presolve delayed the first improvement on 100-robot warehouses by ~2 s
    (exact.PROBING_LEVEL); tuning given to ``search`` still overrides it."""
    ctx = _context(3, "avg_completion")
    for objective in OBJECTIVES:
        tuning = build_model(ctx.problem, ctx.cliques, objective).tuning()
        assert tuning["cp_model_probing_level"] == 0, objective


def test_search_runs_a_built_model_and_tuning_overrides_the_defaults() -> None:
    ctx = _context(3, "avg_completion")
    em = build_model(ctx.problem, ctx.cliques, "avg_completion")
    plain = search(em, TIME_LIMIT_S)
    capped = search(em, TIME_LIMIT_S, tuning={"max_deterministic_time": 0.0})
    assert plain is not None and plain.optimal
    assert capped is None or not capped.optimal  # no work allowed: no proof
    with pytest.raises(AttributeError):
        search(em, TIME_LIMIT_S, tuning={"linearisation_level": 2})  # misspelt: loud


def _wh() -> tuple[ScheduleRequest, SolveContext]:
    """A 50-robot warehouse of the conformance set (CP-SAT does not prove it within 1 s)."""
    rec = json.loads((DATA / "wh_50.jsonl").read_text().splitlines()[0])
    request = ScheduleRequest.model_validate(rec["request"])
    return request, SolveContext(problem_from_request(request), request.objective, 5.0)


@pytest.mark.parametrize("workers", [1, 2])
def test_deterministic_mode_repeats_its_answer_when_the_limit_cuts_it(workers: int) -> None:
    """Cut by its deterministic budget (not proven), the same answer on every run."""
    _, ctx = _wh()
    hint = fcfs(ctx).assignment
    answers = set()
    for _ in range(3):
        result = solve(
            ctx.problem, ctx.cliques, ctx.objective, 0.5, workers=workers, hint=hint,
            deterministic=True,
        )  # fmt: skip
        assert result is not None and not result.optimal
        assert result.deterministic_time <= 1.5 * DTIME_PER_S * 0.5
        answers.add((result.assignment.a_first.tobytes(), result.assignment.following.tobytes()))
    assert len(answers) == 1


def test_the_setting_makes_the_exact_solver_deterministic() -> None:
    policy = dispatch_policy(Settings(exact_deterministic=True))
    assert policy.exact_deterministic and not dispatch_policy(Settings()).exact_deterministic
    request = _wh()[0].model_copy(
        update={"options": OptionsIn(solver="exact", time_limit_s=0.5, seed=3)}
    )
    first, again = (dispatch(request, policy) for _ in range(2))
    assert first.solver.name == "exact" and not first.solver.optimal
    assert first.assignment == again.assignment and first.cost == again.cost
