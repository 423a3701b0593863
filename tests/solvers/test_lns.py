"""Large-neighbourhood search: every sub-problem's answer is valid and no worse, the held
graph's reachability survives the pruning of implied arcs, and with every robot freed one
step is the whole problem (brute force on tiny problems)."""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.check import check
from service.core.problem import Problem, problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.generate import small_problem, stitched_problem
from service.solvers import lns
from service.solvers.dispatch import DispatchPolicy, dispatch
from service.solvers.registry import SolveContext
from service.solvers.tabu import plain_start
from tests.reference import feasible_assignments, reference_problem, tiny_request
from tests.worlds import world_request

DATA = Path(__file__).resolve().parents[1] / "data" / "conformance"
SLOW = [HealthCheck.too_slow]


def _conformance(name: str, index: int = 0) -> dict:
    return json.loads((DATA / f"{name}.jsonl").read_text().splitlines()[index])


def _context(
    request: dict, objective: str, time_limit_s: float = 1.0, workers: int = 1
) -> SolveContext:
    validated = ScheduleRequest.model_validate({**request, "objective": objective})
    return SolveContext(problem_from_request(validated), objective, time_limit_s, workers=workers)


def _closure(n: int, tails: np.ndarray, heads: np.ndarray) -> np.ndarray:
    """(n, n) bool: v reachable from u by one or more arcs."""
    reach = np.zeros((n, n), dtype=bool)
    reach[tails, heads] = True
    for k in range(n):  # Warshall
        reach |= reach[:, [k]] & reach[[k], :]
    return reach


@settings(max_examples=60, deadline=None, derandomize=True)
@given(n=st.integers(2, 12), density=st.floats(0.05, 0.9), seed=st.integers(0, 10_000))
def test_pruning_implied_arcs_keeps_reachability(n: int, density: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)  # a DAG: arcs go forward in this order
    pairs = [(order[i], order[j]) for i in range(n) for j in range(i + 1, n)]
    arcs = [p for p in pairs if rng.random() < density]
    starts = np.array(sorted({int(u) for u, _ in arcs} | {int(order[-1])}), dtype=np.int64)
    arcs.sort(key=lambda arc: int(np.flatnonzero(starts == arc[0])[0]))  # grouped by start
    tails = np.array([u for u, _ in arcs], dtype=np.int64)
    heads = np.array([v for _, v in arcs], dtype=np.int64)
    kept_tails, kept_heads = lns._without_shortcuts(starts, tails, heads, n)
    assert kept_tails.size <= tails.size
    assert np.array_equal(_closure(n, tails, heads), _closure(n, kept_tails, kept_heads))


def _node_graph(problem: Problem, a_first: np.ndarray) -> nx.DiGraph:
    """The node graph of directions ``a_first`` (M,): path arcs, each conflict from the
    side passing first."""
    graph = nx.DiGraph()
    graph.add_nodes_from(range(problem.n_nodes))
    along = np.flatnonzero(problem.node_robot[1:] == problem.node_robot[:-1])
    graph.add_edges_from(zip(along.tolist(), (along + 1).tolist(), strict=True))
    tails = np.where(a_first, problem.conf_a, problem.conf_b)
    heads = np.where(a_first, problem.conf_b, problem.conf_a)
    graph.add_edges_from(zip(tails.tolist(), heads.tolist(), strict=True))
    return graph


def _request(family: str, seed: int, robots: int) -> dict:
    if family == "tiny":
        return tiny_request(seed)
    if family == "small":
        return small_problem(seed)
    if family == "stitched":
        return stitched_problem(seed, robots, 3.0)
    names = ["wh_25", "wh_50", "geo_dense_25"]
    return _conformance(names[seed % 3], seed % 4)["request"]


@settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=SLOW)
@given(
    family=st.sampled_from(["tiny", "small", "stitched", "conformance"]),
    seed=st.integers(0, 10_000),
    robots=st.integers(3, 30),
    picked=st.integers(1, 6),
)
def test_the_held_graph_links_each_boundary_node_to_the_first_ones_it_reaches(
    family: str, seed: int, robots: int, picked: int
) -> None:
    """The one sweep over a topological order links each boundary node to exactly the
    boundary nodes a search through held nodes meets first on each way (networkx on the
    held graph), less the arcs two others imply."""
    ctx = _context(_request(family, seed, robots), "avg_completion")
    problem = ctx.problem
    if problem.n_conflicts == 0:
        return
    a_first = plain_start(ctx).a_first[0]
    rank = ctx.orientation.topological_rank(a_first)
    rng = np.random.default_rng(seed)
    robots_picked = rng.choice(problem.n_robots, size=min(picked, problem.n_robots), replace=False)
    picked_node = np.isin(problem.node_robot, robots_picked)  # (V,)
    boundary = ~picked_node & (rng.random(problem.n_nodes) < 0.5)
    starts = np.flatnonzero(boundary)
    walk = ctx.orientation.walk_args(a_first)
    tails, heads = lns._held_reach(starts, boundary, picked_node, rank, *walk)
    held = _node_graph(problem, a_first).subgraph(np.flatnonzero(~picked_node).tolist())
    expected_tails, expected_heads = [], []
    for u in starts.tolist():
        inner = held.subgraph([v for v in held if not boundary[v]] + [u])
        met = set()
        for v in nx.descendants(inner, u) | {u}:
            met |= {w for w in held.successors(v) if boundary[w]}
        expected_tails += [u] * len(met)
        expected_heads += sorted(met)
    pruned = lns._without_shortcuts(
        starts, np.array(expected_tails, dtype=np.int64), np.array(expected_heads, dtype=np.int64),
        problem.n_nodes,
    )  # fmt: skip
    assert sorted(zip(tails.tolist(), heads.tolist(), strict=True)) == sorted(
        zip(pruned[0].tolist(), pruned[1].tolist(), strict=True)
    )


@settings(
    max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)
@given(
    family=st.sampled_from(["tiny", "small", "stitched", "conformance"]),
    seed=st.integers(0, 10_000),
    robots=st.integers(3, 30),
    picked=st.integers(1, 6),
    objective=st.sampled_from(lns.LNS_OBJECTIVES),
    held_in_order=st.booleans(),
    posed=st.sampled_from(lns.LNS_OBJECTIVES),
)
def test_every_sub_problem_answer_is_valid_and_no_worse(
    family: str,
    seed: int,
    robots: int,
    picked: int,
    objective: str,
    held_in_order: bool,
    posed: str,
) -> None:
    """Whatever robots are freed, the sub-problem's answer passes the checker (cycles
    through held robots included: no answer needs rejecting) and costs no more than the
    answer it started from (up to the integer time grid) in the objective it is posed for
    (the request's or another), with the held robots' nodes linked by the held graph or
    kept in the incumbent's order."""
    ctx = _context(_request(family, seed, robots), objective)
    problem = ctx.problem
    if problem.n_conflicts == 0:
        return
    start = plain_start(ctx)
    rng = np.random.default_rng(seed)
    chosen = rng.choice(problem.n_robots, size=min(picked, problem.n_robots), replace=False)
    fleet = lns._Fleet.of(ctx, posed)
    current = lns._Incumbent.start(ctx, fleet, start)
    neighbourhood = lns._Neighbourhood(ctx, fleet, np.sort(chosen), current, held_in_order)
    solved = neighbourhood.solve(5.0, seed)
    assert solved is not None  # the hint is complete and feasible
    found = neighbourhood.onto(current, solved)
    checks = check(problem, ctx.cliques, found)
    assert checks.acyclic[0] and checks.density[0]
    assert ctx.orientation.topological_rank(found.a_first[0]) is not None
    if held_in_order:  # no held node comes to precede one ranked before it
        held = np.flatnonzero(~np.isin(problem.node_robot, chosen))
        closure = nx.transitive_closure_dag(_node_graph(problem, found.a_first[0]))
        ranked = held[np.argsort(current.rank[held])].tolist()  # the incumbent's order
        assert not any(closure.has_edge(v, u) for i, u in enumerate(ranked) for v in ranked[i:])
    both = Assignments(
        np.concatenate([found.a_first, start.a_first]),
        np.concatenate([found.following, start.following]),
    )
    costs = ctx.evaluator.evaluate(both).costs[posed]  # (2,) found, start
    grid = float(problem.tp_time.max()) / 10**5  # the time grid's resolution (TIME_DIGITS)
    assert costs[0] <= costs[1] + grid


@settings(max_examples=30, deadline=None, derandomize=True)
@given(
    family=st.sampled_from(["tiny", "small", "stitched", "conformance"]),
    seed=st.integers(0, 10_000),
    robots=st.integers(3, 30),
)
def test_every_waiting_robot_has_a_binding_wait_with_a_robot_it_meets(
    family: str, seed: int, robots: int
) -> None:
    """The waits a neighbourhood prefers to free together: a robot delayed anywhere on its
    path waits for at least one other robot by a wait that sets its delay, and binding
    waits pair only robots that share a conflict."""
    ctx = _context(_request(family, seed, robots), "avg_completion")
    fleet = lns._Fleet.of(ctx)
    current = lns._Incumbent.start(ctx, fleet, plain_start(ctx))
    waits = current.waits.toarray() > 0  # (R, R)
    assert not (waits & ~(fleet.shared.toarray() > 0)).any()
    delayed = np.zeros(ctx.problem.n_robots, dtype=bool)  # (R,) any event's delay positive
    events = np.flatnonzero(current.grid_delay[:-1] > 0)
    delayed[np.searchsorted(fleet.event_start, events, side="right") - 1] = True
    assert np.array_equal(delayed & waits.any(axis=1), delayed)


@settings(max_examples=20, deadline=None, derandomize=True)
@given(
    family=st.sampled_from(["small", "stitched", "conformance"]),
    seed=st.integers(0, 10_000),
    robots=st.integers(3, 30),
)
def test_only_critical_binding_waits_pair_robots(family: str, seed: int, robots: int) -> None:
    """With CRITICAL_WAITS the pairs are those of the binding waits whose event's latest
    delay (holding each robot's part) is its least: a subset of every binding wait's."""
    ctx = _context(_request(family, seed, robots), "avg_completion")
    fleet = lns._Fleet.of(ctx)
    start = plain_start(ctx)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lns, "CRITICAL_WAITS", False)
        every = lns._Incumbent.start(ctx, fleet, start).waits.toarray() > 0  # (R, R)
    current = lns._Incumbent.start(ctx, fleet, start)
    critical = current.waits.toarray() > 0
    assert not (critical & ~every).any()
    s = fleet.slots
    waited = current.grid_delay[s.target]
    binding = s.active(current.a_first, current.following) & (waited > 0)
    binding &= waited == current.grid_delay[s.source] + s.offset
    binding &= current.grid_latest[s.target] <= waited  # (S,)
    expected = np.zeros_like(critical)
    waiter, blocker = fleet.slot_robots[binding].T
    expected[waiter, blocker] = expected[blocker, waiter] = True
    np.testing.assert_array_equal(critical, expected)


@pytest.mark.parametrize("objective", lns.LNS_OBJECTIVES)
@pytest.mark.parametrize("seed", range(12))
def test_freeing_every_robot_reaches_the_brute_force_optimum(
    seed: int, objective: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    request = tiny_request(seed, objective)
    ctx = _context(request, objective)
    monkeypatch.setattr(lns, "LNS_ROBOTS", ctx.problem.n_robots)
    best = min(c.costs[objective] for c in feasible_assignments(reference_problem(request)))
    found = lns.lns_search(ctx, plain_start(ctx), time.monotonic() + 0.2, seed)
    assert found.steps >= 1
    assert found.cost == pytest.approx(best, rel=1e-6, abs=1e-9)  # proven or not


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("objective", lns.LNS_OBJECTIVES)
def test_a_proof_comes_only_from_a_step_that_freed_every_robot(
    objective: str, workers: int
) -> None:
    """Optimality is claimed, before the deadline, only where a step freed the whole fleet,
    and the claim matches brute force; on tiny problems the growth gets there (with two
    workers too, whose second sub-problem never holds every robot)."""
    proofs = 0
    for seed in range(12):
        request = tiny_request(seed, objective)
        ctx = _context(request, objective, workers=workers)
        best = min(c.costs[objective] for c in feasible_assignments(reference_problem(request)))
        begin = time.monotonic()
        found = lns.lns_search(ctx, plain_start(ctx), begin + 1.0, seed)
        if found.optimal:
            proofs += 1
            assert time.monotonic() - begin < 1.0
            assert found.cost == pytest.approx(best, rel=1e-6, abs=1e-9)
            assert ctx.problem.n_robots <= lns.MAX_ROBOTS
    assert proofs >= 6


def test_posed_for_another_objective_it_keeps_answers_by_the_requests_and_proves_nothing(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """avg_delay's search with its sub-problems posed for avg_completion holds the held
    robots by their completions alone, frees the whole fleet (as the proofs above) yet
    claims no proof, and its answer is valid and no dearer
    in avg_delay than its start, costed by the one evaluator; on some small problems it
    finds a cheaper one (posed for avg_delay, every one of them is proven)."""
    cheaper = 0
    for seed in range(12):
        ctx = _context(small_problem(seed), "avg_delay")
        held = lns._Fleet.of(ctx, "avg_completion").held  # (E+1,) the completions only
        completions = ctx.evaluator.objective_weights("avg_completion") > 0
        np.testing.assert_array_equal(held, completions)
        monkeypatch.setattr(lns, "LNS_ROBOTS", ctx.problem.n_robots)
        start = plain_start(ctx)
        start_cost = float(ctx.evaluator.evaluate(start).costs["avg_delay"][0])
        deadline = time.monotonic() + 0.3
        found = lns.lns_search(ctx, start, deadline, seed, posed_for="avg_completion")
        assert found.steps >= 1 and not found.optimal
        assert found.cost == float(ctx.evaluator.evaluate(found.best).costs["avg_delay"][0])
        assert found.cost <= start_cost
        checks = check(ctx.problem, ctx.cliques, found.best)
        assert checks.acyclic[0] and checks.density[0]
        cheaper += found.cost < start_cost
    assert cheaper >= 2


@pytest.mark.parametrize("source", ["tiny", "small"])
def test_fleets_of_several_components_or_idle_robots_are_proven_whole(source: str) -> None:
    """A step picks every robot once the seed's conflict component runs out, and a step
    that freed every robot in a conflict proves: every problem of 2-8 robots is proven
    within its second (several had conflict components or robots in no conflict, and ran
    to the deadline unproven)."""
    several = 0  # problems whose robots in conflicts are not one component
    for seed in range(12):
        request = tiny_request(seed) if source == "tiny" else small_problem(seed)
        ctx = _context(request, "avg_completion")
        fleet = lns._Fleet.of(ctx)
        involved = np.flatnonzero(np.diff(fleet.robot_conflicts[0]))
        components = nx.connected_components(nx.from_scipy_sparse_array(fleet.shared))
        several += sum(len(c) > 1 for c in components) > 1 or involved.size < ctx.problem.n_robots
        begin = time.monotonic()
        found = lns.lns_search(ctx, plain_start(ctx), begin + 1.0, seed)
        assert found.optimal and time.monotonic() - begin < 1.0
        if source == "tiny":
            best = min(
                c.costs["avg_completion"] for c in feasible_assignments(reference_problem(request))
            )
            assert found.cost == pytest.approx(best, rel=1e-6, abs=1e-9)
    assert several >= 2


def test_a_step_as_large_as_the_fleet_picks_every_free_robot() -> None:
    ctx = _context(small_problem(2), "avg_completion")
    fleet = lns._Fleet.of(ctx)
    current = lns._Incumbent.start(ctx, fleet, plain_start(ctx))
    n = ctx.problem.n_robots
    busy = np.zeros(n, dtype=bool)
    busy[0] = True
    picked = fleet.pick(np.random.default_rng(0), current, n, busy)
    assert sorted(picked.tolist()) == list(range(1, n))


def test_a_plateau_grows_the_neighbourhood(monkeypatch: pytest.MonkeyPatch) -> None:
    """With no sub-problem ever improving, each size is tried until the robots freed cover
    the fleet, then it grows by GROWTH up to MAX_ROBOTS."""
    ctx = _context(_conformance("wh_50")["request"], "avg_completion")
    counts: list[int] = []
    pick = lns._Fleet.pick

    def recorded(
        fleet: lns._Fleet, rng: np.random.Generator, current: lns._Incumbent, count: int, busy
    ) -> np.ndarray:
        counts.append(count)
        return pick(fleet, rng, current, count, busy)

    monkeypatch.setattr(lns._Fleet, "pick", recorded)
    monkeypatch.setattr(lns._Neighbourhood, "solve", lambda *args: None)
    lns.lns_search(ctx, plain_start(ctx), time.monotonic() + 0.5, 0)
    n = ctx.problem.n_robots
    expected, size = [], lns.LNS_ROBOTS
    while len(expected) < len(counts):
        expected += [size] * -(-n // size)  # ceil(n / size) steps cover the fleet
        size = min(int(size * lns.GROWTH) + 1, lns.MAX_ROBOTS)
    assert len(set(counts)) >= 3  # it grew at least twice within the time
    assert counts == expected[: len(counts)]


def test_lns_ends_at_its_deadline_with_a_valid_answer() -> None:
    ctx = _context(_conformance("wh_50")["request"], "avg_completion")
    start = plain_start(ctx)
    begin = time.monotonic()
    found, cost, steps, optimal = lns.lns_search(ctx, start, begin + 0.5, 0)
    elapsed = time.monotonic() - begin
    # Ends at, not far past, its deadline; the last step that was not started had less
    # than MIN_STEP_S beyond the last build's time left (builds take ~10-30 ms here).
    assert 0.5 - lns.MIN_STEP_S - 0.07 <= elapsed <= 0.5 + 0.3
    assert steps >= 1
    assert not optimal  # 50 robots: no step frees them all (MAX_ROBOTS)
    checks = check(ctx.problem, ctx.cliques, found)
    assert checks.acyclic[0] and checks.density[0]
    assert cost <= float(ctx.evaluator.evaluate(start).costs["avg_completion"][0])


def test_with_patience_it_ends_once_as_long_without_improving_as_to_its_last(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``patience_s``: no step ever improving, the search ends after ``patience_s``; every
    step improving for its first 0.6 s, it ends 0.6 s after the last, not at its deadline
    (3 s) either way."""
    ctx = _context(_conformance("wh_50")["request"], "avg_completion")
    start = plain_start(ctx)
    until = [0.0]

    def improving_until(ctx: SolveContext, fleet, current, found, ties):  # noqa: ANN001, ANN202
        """Every step's answer an improvement (kept as the same incumbent) until ``until``,
        none after it (the real comparison improved now and then, late enough on a slow
        machine to keep the search going past the bound)."""
        return current if time.monotonic() < until[0] else None

    monkeypatch.setattr(lns, "_cheaper", improving_until)
    for improving_s, least_s, most_s in ((0.0, 0.2, 0.7), (0.6, 1.0, 2.2)):
        begin = time.monotonic()
        until[0] = begin + improving_s
        found = lns.lns_search(ctx, start, begin + 3.0, 0, patience_s=0.2)
        elapsed = time.monotonic() - begin
        assert least_s <= elapsed <= most_s, improving_s
        assert found.steps >= 1


def test_no_step_starts_whose_build_would_run_past_the_deadline(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A step is built only where the time left exceeds MIN_STEP_S plus the last build's
    time (30-50 ms at 250 robots, where 0.2-s requests ran 0.24 s). With builds of 0.12 s
    and 0.25 s: the first step's sub-problem solved (~20 ms), what is left does not hold
    another build, and none is started."""
    ctx = _context(_conformance("wh_50")["request"], "avg_completion")
    build = lns._Neighbourhood.__init__
    builds: list[float] = []

    def slow_build(self: lns._Neighbourhood, *args: Any) -> None:
        builds.append(time.monotonic())
        time.sleep(0.12)
        build(self, *args)

    monkeypatch.setattr(lns._Neighbourhood, "__init__", slow_build)
    start = plain_start(ctx)
    begin = time.monotonic()
    found = lns.lns_search(ctx, start, begin + 0.25, 0)
    assert (len(builds), found.steps) == (1, 1)
    assert time.monotonic() - begin < 0.25 + 0.05


@pytest.mark.parametrize("objective", lns.LNS_OBJECTIVES)
def test_two_workers_re_plan_disjoint_robots_and_end_valid_by_the_deadline(
    objective: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With two workers a sub-problem is built while another is solved, never from the
    robots that one re-plans; the search ends at its deadline with a valid answer no
    worse than its start, on a congested warehouse."""
    ctx = _context(world_request("wh_two_way", 25, 60), objective, workers=2)
    overlaps: list[bool] = []
    pick = lns._Fleet.pick

    def recorded(
        fleet: lns._Fleet, rng: np.random.Generator, current: lns._Incumbent, count: int, busy
    ) -> np.ndarray:
        robots = pick(fleet, rng, current, count, busy)
        overlaps.append(bool(busy[robots].any()) if busy.any() else None)
        return robots

    monkeypatch.setattr(lns._Fleet, "pick", recorded)
    start = plain_start(ctx)
    begin = time.monotonic()
    found = lns.lns_search(ctx, start, begin + 1.0, 0)
    assert time.monotonic() - begin <= 1.0 + 0.3
    assert False in overlaps and True not in overlaps  # built alongside, from other robots
    checks = check(ctx.problem, ctx.cliques, found.best)
    assert checks.acyclic[0] and checks.density[0]
    costs = ctx.evaluator.evaluate(found.best).costs[objective]
    assert found.cost == pytest.approx(float(costs[0]))
    assert found.cost <= float(ctx.evaluator.evaluate(start).costs[objective][0])


def test_an_answer_over_a_density_budget_is_never_taken() -> None:
    """A sub-problem applied to a later incumbent than its own may break a density budget
    (its held conflicts changed meanwhile): the acceptance check refuses it, however
    cheap."""
    ctx = _context(_conformance("geo_dense_25")["request"], "avg_completion")
    fleet = lns._Fleet.of(ctx)
    start = plain_start(ctx)
    current = lns._Incumbent.start(ctx, fleet, start)
    binding = ctx.cliques.binding()
    assert binding.any()
    crowded = start.following.copy()  # every conflict of a binding clique following
    q = int(np.flatnonzero(binding)[0])
    crowded[0, ctx.cliques.edge[ctx.cliques.start[q] : ctx.cliques.start[q + 1]]] = True
    found = Assignments(start.a_first, crowded)
    assert not check(ctx.problem, ctx.cliques, found).density[0]
    cheap = replace(current, cost=np.inf)  # any answer would be cheaper
    assert lns._cheaper(ctx, fleet, cheap, found, ties=True) is None
    assert lns._cheaper(ctx, fleet, cheap, start, ties=True) is not None


@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("objective", ["avg_completion", "avg_delay"])
def test_auto_runs_lns_instead_of_cp_sat_from_its_threshold(
    objective: str, workers: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """From lns_min_conflicts LNS runs to the deadline instead of CP-SAT, with one worker
    or two (two sub-problems at once): the answer is checked, on time, never below the
    proven optimum. (With 1 s, less than MID_LNS_LEAST_S, the turns would take the budget
    whole: lowered here.)"""
    import service.solvers.portfolio as portfolio

    def no_cp_sat(*args: object, **kwargs: object) -> object:
        raise AssertionError("the CP-SAT stage ran where LNS should")

    searched = []

    def counted(*args: object, **kwargs: object) -> object:
        searched.append(1)
        return lns.lns_search(*args, **kwargs)

    monkeypatch.setattr(portfolio, "improve", no_cp_sat)
    monkeypatch.setattr(portfolio, "lns_search", counted)
    monkeypatch.setattr(portfolio, "MID_LNS_LEAST_S", dict.fromkeys(lns.LNS_OBJECTIVES, 0.0))
    line = _conformance("wh_50")
    body = {
        **line["request"],
        "objective": objective,
        "options": {"solver": "auto", "time_limit_s": 1.0},
    }
    policy = DispatchPolicy(exact_max_conflicts=0, lns_min_conflicts=1, exact_workers=workers)
    begin = time.perf_counter()
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert time.perf_counter() - begin <= 1.1 + 0.15
    assert answer.solver.name == "auto" and not answer.solver.optimal
    assert searched  # every component (wh_50 has several) went to LNS
    assert answer.checks.acyclic and answer.checks.density
    if objective == "avg_completion":
        assert answer.cost >= line["ref_cost"] * (1 - 1e-9)


def test_auto_keeps_cp_sat_for_the_objectives_lns_does_not_search() -> None:
    line = _conformance("wh_25")
    body = {
        **line["request"],
        "objective": "max_completion",
        "options": {"solver": "auto", "time_limit_s": 1.0},
    }
    policy = DispatchPolicy(exact_max_conflicts=0, lns_min_conflicts=1)
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert answer.solver.name == "auto"
    assert "LNS" not in (answer.solver.detail or "")
    assert answer.checks.acyclic and answer.checks.density


@pytest.mark.parametrize("whole_fleet", [True, False])
def test_below_its_threshold_auto_runs_lns_then_cp_sat_and_still_proves(
    whole_fleet: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Below lns_min_conflicts LNS stops at a plateau of its largest neighbourhood (or
    its share of the time) and hands its answer to the CP-SAT stage, which proves it;
    where a step can free every robot (25 here) LNS may prove it first."""
    import service.solvers.portfolio as portfolio

    ran: list[str] = []
    portfolio_improve = portfolio.improve

    def converging(*args: object, **kwargs: object) -> object:
        ran.append("lns" if kwargs.get("converge") else "lns to the deadline")
        return lns.lns_search(*args, **kwargs)

    def cp_sat(*args: object, **kwargs: object) -> object:
        ran.append("cp-sat")
        return portfolio_improve(*args, **kwargs)

    monkeypatch.setattr(portfolio, "lns_search", converging)
    monkeypatch.setattr(portfolio, "improve", cp_sat)
    if not whole_fleet:
        monkeypatch.setattr(lns, "MAX_ROBOTS", 5)
    line = _conformance("wh_25")
    body = {**line["request"], "options": {"solver": "auto", "time_limit_s": 5.0}}
    policy = DispatchPolicy(exact_max_conflicts=0, lns_min_conflicts=10**9)
    begin = time.perf_counter()
    answer = dispatch(ScheduleRequest.model_validate(body), policy)
    assert time.perf_counter() - begin < 5.0  # proven before the deadline
    assert ran[0] == "lns"
    if whole_fleet:
        assert ran[-1] == "cp-sat" or "proven optimal by LNS" in (answer.solver.detail or "")
    else:
        assert ran[-1] == "cp-sat"
    assert answer.solver.optimal
    assert answer.cost == pytest.approx(line["ref_cost"], rel=1e-6)
    assert answer.checks.acyclic and answer.checks.density
