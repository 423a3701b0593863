"""The anytime portfolio (``auto``) and decomposition into independent components.

Against brute force (tests/reference.py) on problems made of two independent
tiny problems side by side, under all four objectives (sync_completion, which
does not decompose, is solved whole); decomposition itself: each component's
evaluation gives the whole problem's completion times of its robots.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from service.core.assignment import Assignments
from service.core.decode import Decoder
from service.core.decompose import join, parts
from service.core.evaluate import Evaluator
from service.core.problem import problem_from_request
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.solvers import lns
from service.solvers.dispatch import DispatchPolicy, dispatch
from service.solvers.registry import SolveContext
from tests.reference import feasible_assignments, reference_problem, side_by_side

DATA = Path(__file__).resolve().parents[1] / "data" / "conformance"


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("objective", OBJECTIVES)
def test_auto_reaches_brute_force_on_independent_components(seed: int, objective: str) -> None:
    req = side_by_side(seed)
    assert req is not None
    ref = reference_problem(req)
    best = min(c.costs[objective] for c in feasible_assignments(ref))
    body = {**req, "objective": objective, "options": {"solver": "auto", "time_limit_s": 20.0}}
    answer = dispatch(ScheduleRequest.model_validate(body), DispatchPolicy())
    assert answer.solver.optimal
    assert math.isclose(answer.cost, best, rel_tol=1e-9, abs_tol=1e-9)
    if objective != "sync_completion":
        count = int(answer.solver.detail.split(" independent components")[0])
        assert count >= 2


@pytest.mark.parametrize("seed", range(10))
def test_components_evaluate_like_the_whole(seed: int) -> None:
    req = side_by_side(seed)
    assert req is not None
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    ctx = SolveContext(problem, "avg_completion", 1.0)
    rng = np.random.default_rng(seed)
    whole = Decoder(problem, ctx.cliques).decode(
        rng.random((1, problem.n_nodes)) + 0.01, rng.random((1, problem.n_conflicts))
    )
    full = Evaluator(problem).evaluate(whole)
    pieces = parts(problem)
    assert len(pieces) >= 2
    index = {rid: r for r, rid in enumerate(problem.robot_ids)}
    for part in pieces:
        sub = Assignments(whole.a_first[:, part.conflicts], whole.following[:, part.conflicts])
        completion = Evaluator(part.problem).evaluate(sub).completion[0]
        robots = [index[rid] for rid in part.problem.robot_ids]
        assert np.allclose(completion, full.completion[0, robots], rtol=1e-12)
    joined = join(
        problem,
        [
            (p, Assignments(whole.a_first[:, p.conflicts], whole.following[:, p.conflicts]))
            for p in pieces
        ],
    )
    assert np.array_equal(joined.a_first, whole.a_first)
    assert np.array_equal(joined.following, whole.following)


@pytest.mark.parametrize("seed", range(40))
def test_each_component_keeps_exactly_the_density_limits_inside_it(seed: int) -> None:
    req = side_by_side(seed)
    assert req is not None
    problem = problem_from_request(ScheduleRequest.model_validate(req))
    pieces = parts(problem)
    node_ids = np.asarray(problem.node_ids, dtype=object)
    every = sorted(
        (tuple(node_ids[lim.nodes].tolist()), lim.max_robots) for lim in problem.density_limits
    )
    kept = []
    for part in pieces:
        inside = set(part.problem.node_ids)
        sub_ids = np.asarray(part.problem.node_ids, dtype=object)
        got = sorted(
            (tuple(sub_ids[lim.nodes].tolist()), lim.max_robots)
            for lim in part.problem.density_limits
        )
        assert got == [lim for lim in every if set(lim[0]) <= inside]
        kept += got
    assert sorted(kept) == every  # every limit lies inside one component


@pytest.mark.parametrize("name", ["wh_50", "geo_dense_25"])
def test_auto_uses_and_honours_its_budget(name: str) -> None:
    """A problem CP-SAT does not prove in 1 s: auto answers within 10 % + 0.15 s."""
    line = json.loads((DATA / f"{name}.jsonl").read_text().splitlines()[0])
    body = {**line["request"], "options": {"solver": "auto", "time_limit_s": 1.0}}
    start = time.perf_counter()
    answer = dispatch(ScheduleRequest.model_validate(body), DispatchPolicy())
    elapsed = time.perf_counter() - start
    assert elapsed <= 1.1 + 0.15
    assert answer.cost >= line["ref_cost"] * (1 - 1e-9)
    assert answer.checks.acyclic and answer.checks.density
    if not answer.solver.optimal:
        assert elapsed >= 0.9  # an unproven answer used the budget


def test_auto_runs_no_cp_sat_stage_above_its_cap(monkeypatch: pytest.MonkeyPatch) -> None:
    """Above exact_stage_max_conflicts the first stage and tabu get the budget, CP-SAT none."""
    import service.solvers.portfolio as portfolio

    def no_cp_sat(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("CP-SAT stage ran above the cap")

    monkeypatch.setattr(portfolio, "improve", no_cp_sat)
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    body = {**line["request"], "options": {"solver": "auto", "time_limit_s": 0.5}}
    policy = DispatchPolicy(exact_max_conflicts=0, exact_stage_max_conflicts=10)
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert answer.solver.name == "auto" and not answer.solver.optimal
    assert "no CP-SAT stage above 10 conflicts" in answer.solver.detail
    assert answer.cost >= line["ref_cost"] * (1 - 1e-9)


@pytest.mark.parametrize("objective", ["avg_completion", "avg_delay"])
def test_above_its_cap_auto_runs_no_lns_whatever_time_is_left(
    objective: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Above exact_stage_max_conflicts no LNS stage runs, even where every rule below the
    cap would run it (MID_LNS_LEAST_S 0): the re-insertion turns (from lns_min_conflicts,
    lowered to 0) take the budget to the deadline. The answer is valid, never claimed
    optimal."""
    import service.solvers.portfolio as portfolio

    def no_lns(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("LNS ran above the cap")

    monkeypatch.setattr(portfolio, "lns_search", no_lns)
    monkeypatch.setattr(portfolio, "MID_LNS_LEAST_S", {objective: 0.0})
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    options = {"solver": "auto", "time_limit_s": 1.0}
    body = {**line["request"], "objective": objective, "options": options}
    policy = DispatchPolicy(
        exact_max_conflicts=0, exact_stage_max_conflicts=10, lns_min_conflicts=0
    )
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert "re-insertion search to the deadline above 10 conflicts" in answer.solver.detail
    assert not answer.solver.optimal
    if objective == line["request"]["objective"]:
        assert answer.cost >= line["ref_cost"] * (1 - 1e-9)
    assert answer.checks.acyclic and answer.checks.density


@pytest.mark.parametrize("objective", ["avg_completion", "avg_delay"])
@pytest.mark.parametrize(("lns_min", "posed"), [(0, "avg_completion"), (10**6, None)])
def test_lns_is_posed_for_avg_completion_where_it_is_the_last_stage(
    lns_min: int, posed: str | None, objective: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """From lns_min_conflicts (lowered to 0) LNS is the last stage and its sub-problems are
    posed for avg_completion (LAST_LNS_POSED) for either objective; below it CP-SAT
    follows and LNS is posed for the request's objective (None), so that it may prove.
    The answer is valid either way."""
    import service.solvers.portfolio as portfolio

    calls: list[str | None] = []

    def lns_search(*args: Any, **kwargs: Any) -> Any:
        calls.append(kwargs["posed_for"])
        return lns.lns_search(*args, **kwargs)

    monkeypatch.setattr(portfolio, "lns_search", lns_search)
    monkeypatch.setattr(portfolio, "MID_LNS_LEAST_S", {objective: 0.5})
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    options = {"solver": "auto", "time_limit_s": 1.0}
    body = {**line["request"], "objective": objective, "options": options}
    policy = DispatchPolicy(exact_max_conflicts=0, lns_min_conflicts=lns_min)
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert calls == [posed]
    if objective == line["request"]["objective"]:
        assert answer.cost >= line["ref_cost"] * (1 - 1e-9)
    assert answer.checks.acyclic and answer.checks.density


def test_auto_uses_its_budget_when_tabu_stops_early_and_no_cp_sat_follows() -> None:
    """Tabu search stops on its own (patience) within a fraction of a second on a small
    problem; with no CP-SAT stage to follow, auto restarts it with new seeds from the best
    so far until the budget is spent, instead of returning early unproven."""
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    body = {**line["request"], "options": {"solver": "auto", "time_limit_s": 1.5}}
    policy = DispatchPolicy(exact_max_conflicts=0, exact_stage_max_conflicts=10)
    start = time.monotonic()
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    elapsed = time.monotonic() - start
    assert not answer.solver.optimal
    assert elapsed >= 1.2  # the budget was used (load only makes it slower)
    assert answer.cost >= line["ref_cost"] * (1 - 1e-9)
    assert answer.checks.acyclic and answer.checks.density


@pytest.mark.parametrize(
    ("stage_cap", "objective", "least_s", "lns_follows"),
    [
        (10, "avg_completion", 0.0, False),
        (None, "avg_completion", 2.0, False),
        (None, "avg_completion", 0.5, True),
        (None, "avg_completion", None, False),  # the shipped rule: never for avg_completion
        (None, "avg_delay", None, False),  # the shipped rule: LNS from 4 s for avg_delay
        (None, "avg_delay", math.inf, False),
    ],
)
def test_from_lns_min_conflicts_re_insertion_follows_the_first_stage(
    stage_cap: int | None,
    objective: str,
    least_s: float | None,
    lns_follows: bool,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """From lns_min_conflicts conflicts (lowered to 0) re-insertion search runs in turns
    after the first stage: to the deadline where neither LNS nor CP-SAT follows (above
    the cap; below it, a budget under MID_LNS_LEAST_S of the objective), else for
    REINSERT_SHARE of the time left, then LNS; the answer is valid, no better than the
    proven optimum, and comes within the budget."""
    import service.solvers.portfolio as portfolio

    untils: list[float] = []
    original = portfolio.take_turns

    def recorded(ctx: Any, start: Any, cost: float, until: float, seed: int, **kw: Any) -> Any:
        if "held" not in kw:  # not the turns beside LNS (see BESIDE)
            untils.append(until)
        return original(ctx, start, cost, until, seed, **kw)

    monkeypatch.setattr(portfolio, "take_turns", recorded)
    if least_s is not None:
        monkeypatch.setattr(portfolio, "MID_LNS_LEAST_S", {objective: least_s})
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    options = {"solver": "auto", "time_limit_s": 1.0}
    body = {**line["request"], "objective": objective, "options": options}
    cap = {} if stage_cap is None else {"exact_stage_max_conflicts": stage_cap}
    policy = DispatchPolicy(exact_max_conflicts=0, lns_min_conflicts=0, **cap)
    start = time.monotonic()
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    elapsed = time.monotonic() - start
    assert len(untils) == 1
    assert elapsed <= 1.1 + 0.15
    if lns_follows:  # re-insertion stops well before the deadline
        assert untils[0] < start + 0.9
    else:
        assert untils[0] >= start + 0.95
        assert "re-insertion search to the deadline" in answer.solver.detail
        shipped = {"avg_completion": "no LNS for avg_completion", "avg_delay": "LNS from 4 s"}[
            objective
        ]
        below_cap = (
            shipped
            if least_s is None
            else f"no LNS for {objective}"
            if math.isinf(least_s)
            else f"LNS from {least_s:g} s"
        )
        assert (below_cap if stage_cap is None else "above 10 conflicts") in answer.solver.detail
    if objective == line["request"]["objective"]:
        assert answer.cost >= line["ref_cost"] * (1 - 1e-9)
    assert answer.checks.acyclic and answer.checks.density


@pytest.mark.parametrize(("min_conflicts", "turns"), [(0, True), (10_000, False)])
def test_below_lns_min_conflicts_the_first_stage_is_the_turns(
    min_conflicts: int, turns: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Between exact_max_conflicts (and MID_TURNS_MIN_CONFLICTS) and lns_min_conflicts, a
    solve starts with the plans and the turns for MID_TURNS_SHARE of the time left, in
    place of the large solver (priority_tabu); a smaller problem with the large solver, not
    the turns. Either way LNS follows; the answer is valid, no better than the proven
    optimum, and comes within the budget."""
    import service.solvers.portfolio as portfolio

    untils: list[float] = []
    original = portfolio.take_turns

    def recorded(ctx: Any, start: Any, cost: float, until: float, seed: int, **kw: Any) -> Any:
        if "held" not in kw:  # not the turns beside LNS (see BESIDE)
            untils.append(until)
        return original(ctx, start, cost, until, seed, **kw)

    searched: list[bool] = []
    lns_search = portfolio.lns_search

    def lns_recorded(*args: Any, **kwargs: Any) -> Any:
        searched.append(True)
        return lns_search(*args, **kwargs)

    monkeypatch.setattr(portfolio, "take_turns", recorded)
    monkeypatch.setattr(portfolio, "lns_search", lns_recorded)
    monkeypatch.setattr(portfolio, "MID_TURNS_MIN_CONFLICTS", min_conflicts)
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    body = {**line["request"], "options": {"solver": "auto", "time_limit_s": 1.0}}
    policy = DispatchPolicy(exact_max_conflicts=0, lns_min_conflicts=10_000)
    start = time.monotonic()
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert time.monotonic() - start <= 1.1 + 0.15
    if turns:
        assert len(untils) == 1 and untils[0] < start + 0.25  # MID_TURNS_SHARE of ~1 s
        assert answer.solver.detail.startswith("planned")
        assert "priority_tabu" not in answer.solver.detail
    else:
        assert not untils
        assert "priority_tabu" in answer.solver.detail
    assert searched == [True]
    assert answer.cost >= line["ref_cost"] * (1 - 1e-9)
    assert answer.checks.acyclic and answer.checks.density


@pytest.mark.parametrize("objective", ["avg_completion", "avg_delay", "max_completion"])
def test_the_sums_start_with_the_turns_at_longer_budgets_too(
    objective: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With 2.5 s, between exact_max_conflicts and lns_min_conflicts, avg_completion and
    avg_delay (re-insertion's objectives) start with the plans and the turns, others with
    the large solver."""
    import service.solvers.portfolio as portfolio

    monkeypatch.setattr(portfolio, "MID_TURNS_MIN_CONFLICTS", 0)
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    options = {"solver": "auto", "time_limit_s": 2.5}
    body = {**line["request"], "objective": objective, "options": options}
    policy = DispatchPolicy(exact_max_conflicts=0, lns_min_conflicts=10_000)
    detail = dispatch(ScheduleRequest.model_validate(body), policy).solver.detail
    if objective != "max_completion":
        assert detail.startswith("planned") and "priority_tabu" not in detail
    else:
        assert "priority_tabu" in detail


def test_small_problems_go_straight_to_cp_sat_whatever_lns_min_conflicts_says() -> None:
    """At or below exact_max_conflicts no first stage, re-insertion or LNS runs, even with
    lns_min_conflicts lowered below it: CP-SAT proves the tiny problem."""
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    body = {**line["request"], "options": {"solver": "auto", "time_limit_s": 5.0}}
    policy = DispatchPolicy(exact_max_conflicts=10_000, lns_min_conflicts=0)
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert answer.solver.optimal
    assert "reinsert" not in answer.solver.detail and "lns" not in answer.solver.detail
    assert answer.cost == pytest.approx(line["ref_cost"], rel=1e-9)


def test_a_re_schedule_starts_from_the_previous_answer_not_a_plan(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With a previous answer (a re-schedule) no plan of the whole fleet is made: the
    first stage is tabu search from it, as below lns_min_conflicts (at 250 robots a plan
    costs 15-20 ms of a 100-ms re-schedule, and the previous answer is the better start);
    the answer is valid and no dearer than the previous one."""
    import service.solvers.portfolio as portfolio
    from service.core.check import check
    from service.solvers.registry import get_solver
    from service.solvers.tabu import plain_start

    def no_plan(*args: object, **kwargs: object) -> object:
        raise AssertionError("a warm re-schedule made a plan")

    monkeypatch.setattr(portfolio, "planned_starts", no_plan)
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    problem = problem_from_request(ScheduleRequest.model_validate(line["request"]))
    cold = SolveContext(problem, "avg_completion", 0.3)
    previous = plain_start(cold)
    ctx = SolveContext(
        problem, "avg_completion", 0.3, warm=previous, exact_max_conflicts=0, lns_min_conflicts=0
    )
    found = get_solver("auto")(ctx)
    assert found is not None
    evaluator = Evaluator(problem)
    assert (
        evaluator.evaluate(found.assignment).costs["avg_completion"][0]
        <= evaluator.evaluate(previous).costs["avg_completion"][0] + 1e-9
    )
    checks = check(problem, ctx.cliques, found.assignment)
    assert checks.acyclic[0] and checks.density[0]


def test_the_other_plans_start_lineages_of_their_own(monkeypatch: pytest.MonkeyPatch) -> None:
    """``auto`` starts its turns from the cheapest plan and hands them the other plans
    (cheaper first), each the start of a lineage of its own (``take_turns``' ``others``),
    in each component it solves apart."""
    import service.solvers.portfolio as portfolio
    from service.solvers.registry import get_solver

    made: list[list[tuple[Assignments, float]]] = []
    given: list[tuple[Assignments, list[tuple[Assignments, float]]]] = []
    planned_starts, take_turns = portfolio.planned_starts, portfolio.take_turns

    def planned(*args: Any) -> list[tuple[Assignments, float]]:
        made.append(planned_starts(*args))
        return made[-1]

    def turned(ctx: Any, start: Any, cost: float, until: float, seed: int, **kw: Any) -> Any:
        if "held" not in kw:  # not the turns beside LNS (see BESIDE)
            given.append((start, kw["others"]))
        return take_turns(ctx, start, cost, until, seed, **kw)

    monkeypatch.setattr(portfolio, "planned_starts", planned)
    monkeypatch.setattr(portfolio, "take_turns", turned)
    line = json.loads((DATA / "wh_50.jsonl").read_text().splitlines()[0])
    problem = problem_from_request(ScheduleRequest.model_validate(line["request"]))
    ctx = SolveContext(problem, "avg_completion", 0.3, exact_max_conflicts=0, lns_min_conflicts=0)
    assert get_solver("auto")(ctx) is not None
    assert len(made) == len(given) >= 1
    assert max(len(plans) for plans in made) == portfolio.PLANNED_ORDERS  # as time allows
    for plans, (start, others) in zip(made, given, strict=True):
        assert start is plans[0][0] and others == plans[1:]


@pytest.mark.parametrize("plan_found", [True, False])
def test_plans_replace_the_instant_answer_where_one_is_found(
    monkeypatch: pytest.MonkeyPatch, plan_found: bool
) -> None:
    """From lns_min_conflicts the instant answer is sought only where no plan is found (it
    costs ~25-55 ms at 5,000-10,000 conflicts, and every plan measured was cheaper); either
    way the answer is valid."""
    import service.solvers.portfolio as portfolio
    from service.core.check import check
    from service.solvers.registry import get_solver

    sought: list[bool] = []
    plain_start, planned_starts = portfolio.plain_start, portfolio.planned_starts

    def watched(ctx: SolveContext) -> Assignments:
        sought.append(True)
        return plain_start(ctx)

    def planned(*args: Any, **kwargs: Any) -> list[tuple[Assignments, float]]:
        return planned_starts(*args, **kwargs) if plan_found else []

    monkeypatch.setattr(portfolio, "plain_start", watched)
    monkeypatch.setattr(portfolio, "planned_starts", planned)
    line = json.loads((DATA / "wh_50.jsonl").read_text().splitlines()[0])
    problem = problem_from_request(ScheduleRequest.model_validate(line["request"]))
    ctx = SolveContext(problem, "avg_completion", 0.3, exact_max_conflicts=0, lns_min_conflicts=0)
    found = get_solver("auto")(ctx)
    assert found is not None
    assert bool(sought) != plan_found
    checks = check(problem, ctx.cliques, found.assignment)
    assert checks.acyclic[0] and checks.density[0] and checks.forced[0]


@pytest.mark.parametrize(
    ("objective", "per_conflict"),
    [("max_completion", None), ("sync_completion", None), ("max_completion", 1.0)],
)
def test_the_first_stage_answer_of_max_and_sync_gets_types_by_descent_where_cheaper(
    objective: str, per_conflict: float | None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """For DESCENT_OBJECTIVES above exact_max_conflicts the first stage's directions get
    types by descent from all-exclusive (``retype.descend_types``): called once, with the
    first stage's directions, and kept exactly where cheaper (the stages say so); not
    where the time left after the first stage is less than DESCENT_S_PER_CONFLICT's (1 s a
    conflict: never), and then the first stage has the whole budget."""
    import service.solvers.portfolio as portfolio
    from service.core.retype import descend_types

    calls: list[tuple[np.ndarray, float]] = []  # (directions, cost of the first stage's answer)
    real_first = portfolio.get_solver("priority_tabu")
    budgets: list[float] = []  # the first stage's time limit

    def first_stage(ctx: SolveContext) -> Any:
        budgets.append(ctx.time_limit_s)
        found = real_first(ctx)
        calls.append((found.assignment.a_first.copy(), ctx.cost(found.assignment)))
        return found

    descended: list[tuple[np.ndarray, float]] = []  # (directions given, cost reached)

    def descend(*args: Any) -> Any:
        found = descend_types(*args)
        descended.append((args[3].copy(), found[1]))
        return found

    monkeypatch.setattr(portfolio, "get_solver", lambda name: first_stage)
    monkeypatch.setattr(portfolio, "descend_types", descend)
    if per_conflict is not None:
        monkeypatch.setattr(portfolio, "DESCENT_S_PER_CONFLICT", per_conflict)
    line = json.loads((DATA / "wh_25.jsonl").read_text().splitlines()[0])
    body = {
        **line["request"],
        "objective": objective,
        "options": {"solver": "auto", "time_limit_s": 1.0},
    }
    policy = DispatchPolicy(exact_max_conflicts=0, exact_stage_max_conflicts=10)
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert answer.checks.acyclic and answer.checks.density
    assert len(calls) == 1
    if per_conflict is not None:  # no time for the descent: the first stage had it all
        assert not descended and budgets[0] > 0.9
        return
    assert len(descended) == 1 and budgets[0] < 0.35
    (directions, descended_cost), (first_directions, first_cost) = descended[0], calls[0]
    # priority_tabu never ends above the start it searched from: its answer is descended
    assert np.array_equal(directions, first_directions)
    assert ("types by descent" in answer.solver.detail) == (descended_cost < first_cost)
    assert answer.cost <= min(descended_cost, first_cost) + 1e-9


def _wh50_context(time_limit_s: float, first_stage: str = "priority_tabu") -> SolveContext:
    """wh_50's first problem for avg_completion, every stage above the exact cap."""
    line = json.loads((DATA / "wh_50.jsonl").read_text().splitlines()[0])
    problem = problem_from_request(ScheduleRequest.model_validate(line["request"]))
    return SolveContext(
        problem, "avg_completion", time_limit_s, exact_max_conflicts=0, first_stage=first_stage
    )


def test_the_turns_beside_the_exact_stages_give_their_answer_where_cheaper(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``auto`` (a component's stages) starts re-insertion turns beside its exact stages
    from the answer those start from, and keeps the turns' answer where it is cheaper than
    theirs (the exact stages here return their start unchanged), with a detail that says
    so."""
    import service.solvers.portfolio as portfolio
    from service.solvers.registry import get_solver
    from service.solvers.turns import TurnsResult

    ctx = _wh50_context(0.5, first_stage="fcfs")  # a first stage that leaves room
    good = get_solver("auto")(_wh50_context(1.0)).assignment
    good_cost = ctx.cost(good)
    handed: list[Assignments] = []

    class Found:
        def ended(self) -> TurnsResult:
            return TurnsResult(good, good_cost, 3)

    def started(ctx_: SolveContext, start: Assignments, cost: float, deadline: float) -> Found:
        assert cost == ctx_.cost(start) and deadline > time.monotonic()
        handed.append(start)
        return Found()

    def unchanged(ctx_: SolveContext, deadline: float, best: Any, *rest: Any) -> Any:
        return best.__class__(best.assignment, optimal=False, detail="exact stages")

    monkeypatch.setattr(portfolio._Beside, "start", staticmethod(started))
    monkeypatch.setattr(portfolio, "_exact_tail", unchanged)
    out = portfolio._staged(ctx, time.monotonic() + ctx.time_limit_s)
    assert len(handed) == 1 and ctx.cost(handed[0]) > good_cost  # the start was dearer
    assert out.assignment is good and not out.optimal
    assert out.detail == "exact stages; re-insertion beside them cheaper (x3 turns)"


@pytest.mark.parametrize("optimal", [True, False])
def test_a_dearer_answer_of_the_turns_beside_or_any_beside_a_proof_is_not_taken(
    optimal: bool,
) -> None:
    from service.solvers.portfolio import _with_beside
    from service.solvers.registry import SolverOutput
    from service.solvers.tabu import plain_start
    from service.solvers.turns import TurnsResult

    ctx = _wh50_context(1.0)
    start = plain_start(ctx)
    cost = ctx.cost(start)
    out = SolverOutput(start, optimal=optimal, detail="exact stages")
    assert _with_beside(ctx, out, None) is out
    assert _with_beside(ctx, out, TurnsResult(plain_start(ctx), cost, 2)) is out  # as dear
    cheaper = _with_beside(ctx, out, TurnsResult(plain_start(ctx), cost - 1.0, 2))
    assert (cheaper is out) == optimal


def test_the_turns_beside_stop_when_the_exact_stages_end_early(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Where the exact stages prove optimality early, ``auto`` (a component's stages)
    answers at once: the turns beside them stop at their next step, not at the deadline
    (with a spare core)."""
    import service.solvers.portfolio as portfolio

    ran: list[float] = []

    def proven(ctx_: SolveContext, deadline: float, best: Any, *rest: Any) -> Any:
        time.sleep(0.2)  # the turns beside are under way
        ran.append(time.monotonic())
        return best.__class__(best.assignment, optimal=True, detail="proven")

    monkeypatch.setattr(portfolio, "cores_per_solve", lambda: 2)
    monkeypatch.setattr(portfolio, "_exact_tail", proven)
    started = portfolio._Beside.start
    begun: list[Any] = []
    monkeypatch.setattr(
        portfolio._Beside, "start", staticmethod(lambda *a: begun.append(started(*a)) or begun[-1])
    )
    out = portfolio._staged(_wh50_context(5.0), time.monotonic() + 5.0)
    assert out.optimal and out.detail == "proven"
    assert len(begun) == 1 and begun[0] is not None
    assert time.monotonic() - ran[0] < 0.3


def test_no_turns_beside_where_off_or_no_core_is_spare(monkeypatch: pytest.MonkeyPatch) -> None:
    import service.solvers.portfolio as portfolio
    from service.solvers.tabu import plain_start

    ctx = _wh50_context(1.0)
    start = plain_start(ctx)
    deadline = time.monotonic() + 1.0
    monkeypatch.setattr(portfolio, "cores_per_solve", lambda: ctx.workers)
    assert portfolio._Beside.start(ctx, start, ctx.cost(start), deadline) is None
    monkeypatch.setattr(portfolio, "cores_per_solve", lambda: ctx.workers + 1)
    monkeypatch.setattr(portfolio, "BESIDE", False)
    assert portfolio._Beside.start(ctx, start, ctx.cost(start), deadline) is None


@pytest.mark.parametrize(
    ("name", "order"), [("wh_25", ["lns", "beside"]), ("wh_50", ["beside", "lns"])]
)
def test_the_turns_beside_wait_for_the_cp_sat_stage_where_lns_may_prove(
    monkeypatch: pytest.MonkeyPatch, name: str, order: list[str]
) -> None:
    """Where LNS may prove optimality (a fleet of up to ``lns.MAX_ROBOTS``, which a step
    frees whole) the turns beside start with the CP-SAT stage, from LNS's answer, and leave
    LNS's model building the interpreter; on larger fleets they start with LNS."""
    import service.solvers.portfolio as portfolio

    events: list[str] = []

    def searched(ctx_: SolveContext, start: Assignments, *args: Any, **kw: Any) -> Any:
        events.append("lns")
        return SimpleNamespace(best=start, cost=ctx_.cost(start), steps=0, optimal=False)

    started = portfolio._Beside.start

    def beside(*args: Any) -> Any:
        events.append("beside")
        return started(*args)

    monkeypatch.setattr(portfolio, "lns_search", searched)
    monkeypatch.setattr(portfolio._Beside, "start", staticmethod(beside))
    monkeypatch.setattr(portfolio, "cores_per_solve", lambda: 2)
    line = json.loads((DATA / f"{name}.jsonl").read_text().splitlines()[0])
    problem = problem_from_request(ScheduleRequest.model_validate(line["request"]))
    assert (problem.n_robots > lns.MAX_ROBOTS) == (order[0] == "beside")
    ctx = SolveContext(problem, "avg_completion", 1.0, exact_max_conflicts=0)
    out = portfolio._staged(ctx, time.monotonic() + 1.0)
    assert events == order
    assert out.assignment is not None
