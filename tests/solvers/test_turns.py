"""Re-insertion search in turns: the turns return a valid answer no worse than their
start, within their deadline (hypothesis over tiny, fixed-direction, small, stitched and
conformance problems), each turn from the best so far, its chains one per core of the
solve's share of the machine, read at each turn."""

from __future__ import annotations

import json
import threading
import time
from contextlib import ExitStack
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.assignment import Assignments
from service.core.check import check
from service.core.threads import available_cores, solving
from service.solvers import turns
from service.solvers.registry import SolveContext
from service.solvers.reinsert import ReinsertResult, planned_starts, reinsert_search
from service.solvers.tabu import plain_start
from service.solvers.turns import TurnsConfig, take_turns
from service.solvers.turns import _reinsertion as turns_reinsertion
from tests.solvers.test_reinsert import CONTEXTS, DATA, SLOW, _context


def _assert_valid(ctx: SolveContext, answer: Assignments, cost: float) -> None:
    """``answer`` passes the checker and costs ``cost`` by the one evaluator."""
    checks = check(ctx.problem, ctx.cliques, answer)
    assert checks.acyclic[0] and checks.density[0] and checks.forced[0]
    assert cost == float(ctx.evaluator.evaluate(answer).costs[ctx.objective][0])


@settings(max_examples=15, deadline=None, derandomize=True, suppress_health_check=SLOW)
@given(ctx=CONTEXTS, seed=st.integers(0, 1000))
def test_turns_return_a_valid_answer_no_worse_than_their_start(
    ctx: SolveContext, seed: int
) -> None:
    if ctx.problem.n_conflicts == 0:
        return
    start = plain_start(ctx)
    start_cost = float(ctx.evaluator.evaluate(start).costs[ctx.objective][0])
    config = TurnsConfig(turn_s=0.02, turn_share=1.0)
    found = take_turns(ctx, start, start_cost, time.monotonic() + 0.1, seed, config)
    assert found.cost <= start_cost
    _assert_valid(ctx, found.best, found.cost)


def test_turns_stop_at_their_deadline_and_take_several() -> None:
    line = (DATA / "wh_50.jsonl").read_text().splitlines()[0]
    ctx = _context(json.loads(line)["request"], "avg_completion")
    start = plain_start(ctx)
    cost = float(ctx.evaluator.evaluate(start).costs["avg_completion"][0])
    begin = time.monotonic()
    found = take_turns(ctx, start, cost, begin + 0.4, 0)
    assert time.monotonic() - begin < 0.4 + 0.1
    assert found.turns >= 3  # turns of at most a quarter of the time given


def test_reinsertion_cools_over_the_first_share_of_the_turns(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Every re-insertion search of the turns gets the same cooling span: from the turns'
    start over cooling_share of their time (then it searches cold to the deadline)."""
    begin, warm_from, cold_at = _cooling_span(monkeypatch, TurnsConfig(cooling_share=0.25))
    assert begin <= warm_from < begin + 0.01
    assert abs((cold_at - warm_from) - 0.25 * (begin + 0.4 - warm_from)) < 1e-9


def test_reinsertion_searches_cold_for_most_cold_s_at_most(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Where cooling_share would leave more than most_cold_s to search cold, the turns
    cool until most_cold_s before the deadline."""
    config = TurnsConfig(cooling_share=0.25, most_cold_s=0.1)
    begin, warm_from, cold_at = _cooling_span(monkeypatch, config)
    assert begin <= warm_from < begin + 0.01
    assert abs(cold_at - (begin + 0.4 - 0.1)) < 1e-9


def _cooling_span(
    monkeypatch: pytest.MonkeyPatch, config: TurnsConfig
) -> tuple[float, float, float]:
    """Turns of ``config`` for 0.4 s on a wh_50 problem -> (their start, the cooling span
    every re-insertion search of them got: it must be one)."""
    spans: list[tuple[float, float]] = []

    def recorded(*args, cooling, **kwargs):
        spans.append(cooling)
        return reinsert_search(*args, cooling=cooling, **kwargs)

    monkeypatch.setattr(turns, "reinsert_search", recorded)
    ctx, start, cost = _wh50()
    begin = time.monotonic()
    take_turns(ctx, start, cost, begin + 0.4, 0, config)
    assert len(spans) >= 3 and len(set(spans)) == 1
    return begin, *spans[0]


def _wh50() -> tuple[SolveContext, Assignments, float]:
    line = (DATA / "wh_50.jsonl").read_text().splitlines()[0]
    ctx = _context(json.loads(line)["request"], "avg_completion")
    start = plain_start(ctx)
    return ctx, start, float(ctx.evaluator.evaluate(start).costs["avg_completion"][0])


def test_each_turn_starts_from_the_best_answer_so_far(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A turn's re-insertion starts from the answer the last turn returned (the best so
    far: a search returns the cheapest it saw), with the next seed; the turns return the
    last one."""
    ctx, start, cost = _wh50()
    starts: list[Assignments] = []
    seeds: list[int] = []

    def recorded(ctx, begin, until, seed, **kwargs):
        starts.append(begin)
        seeds.append(seed)
        return reinsert_search(ctx, begin, until, seed, **kwargs)

    monkeypatch.setattr(turns, "reinsert_search", recorded)
    returned: list[ReinsertResult] = []

    def one_chain(*args):
        (result,) = turns_reinsertion(*args)
        returned.append(result)
        return [result]

    monkeypatch.setattr(turns, "_reinsertion", one_chain)
    config = TurnsConfig(turn_s=0.05, chains=1)
    found = take_turns(ctx, start, cost, time.monotonic() + 0.3, 11, config)
    assert found.turns == len(starts) == len(returned) >= 3
    assert starts[0] is start
    for turn in range(1, found.turns):
        assert starts[turn] is returned[turn - 1].best
    assert seeds == [11 + turn for turn in range(found.turns)]
    assert (found.best, found.cost) == (returned[-1].best, returned[-1].cost)
    assert found.cost <= cost
    _assert_valid(ctx, found.best, found.cost)


CORES = available_cores()


@pytest.mark.parametrize(
    ("workers", "chains", "solves", "expected"),
    [
        (1, None, 0, CORES),  # alone: every core
        (1, None, 1, CORES),
        (1, None, 2, max(1, CORES // 2)),  # another solve under way: its share
        (2, None, 2 * CORES, 2),  # never fewer than the solve's own workers
        (2, 1, 0, 1),
        (1, 3, 2, 3),
    ],
)
def test_a_turn_runs_a_reinsertion_chain_per_core_it_may_take_each_with_its_own_seed(
    workers: int, chains: int | None, solves: int, expected: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One chain per core of the solve's share while ``solves`` solves are under way
    (:func:`~service.core.threads.cores_per_solve`), never fewer than its ``ctx.workers``,
    unless the config says how many; chain 0 has the turn's seed (one chain: the single
    search's), the others seeds of their own; the turns still return a valid answer no
    worse than their start."""
    seeds: list[int] = []

    def recorded(ctx, start, until, seed, **kwargs):
        seeds.append(seed)
        return reinsert_search(ctx, start, until, seed, **kwargs)

    monkeypatch.setattr(turns, "reinsert_search", recorded)
    ctx, start, cost = _wh50()
    ctx = replace(ctx, workers=workers)
    config = TurnsConfig(turn_s=0.05, cooling_share=1.0, chains=chains)
    with ExitStack() as under_way:
        for _ in range(solves):
            under_way.enter_context(solving())
        found = take_turns(ctx, start, cost, time.monotonic() + 0.3, 7, config)
    assert found.cost <= cost
    _assert_valid(ctx, found.best, found.cost)
    assert len(seeds) == expected * found.turns
    by_turn = [sorted(seeds[k : k + expected]) for k in range(0, len(seeds), expected)]
    stride = turns.CHAIN_SEED_STRIDE
    assert by_turn == [[7 + t + k * stride for k in range(expected)] for t in range(found.turns)]


@pytest.mark.skipif(CORES < 2, reason="one core: one chain whatever runs")
def test_a_solve_arriving_during_the_turns_takes_its_share_from_the_next_turn(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The turns read the cores they may take at each turn: every core while alone, the
    solve's share once another solve is under way, every core again once it ended."""
    chains_by_turn: list[int] = []
    under_way = ExitStack()

    def recorded(ctx, starts, until, seed, cooling, pool, stop):
        chains_by_turn.append(len(starts))
        if len(chains_by_turn) == 2:
            under_way.enter_context(solving())  # this solve's count
            under_way.enter_context(solving())  # another arrives
        if len(chains_by_turn) == 4:
            under_way.close()
        return turns_reinsertion(ctx, starts, until, seed, cooling, pool, stop)

    monkeypatch.setattr(turns, "_reinsertion", recorded)
    ctx, start, cost = _wh50()
    take_turns(ctx, start, cost, time.monotonic() + 0.4, 0, TurnsConfig(turn_s=0.05))
    under_way.close()
    share = CORES // 2
    assert chains_by_turn[:5] == [CORES, CORES, share, share, CORES]


def test_each_chain_goes_on_from_its_own_best_and_the_cheapest_lineage_is_the_answer(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """With ``meet_stalled`` off, chains never meet: a chain's next turn starts from what
    its own last turn returned, not from the cheapest of the turn; the turns answer the
    cheapest lineage's best (the first of equals)."""
    ctx, start, cost = _wh50()
    starts: list[list[Assignments]] = []
    returned: list[list[ReinsertResult]] = []

    def fake(ctx, starts_, until, seed, cooling, pool, stop):
        time.sleep(max(0.0, until - time.monotonic()))
        turn = len(starts)
        starts.append(starts_)
        # chain 0 cheaper on the first turn, chain 1 from then on, equal on the last ones
        costs = [10.0 - turn, 11.0 - 2 * turn]
        results = [
            ReinsertResult(Assignments(start.a_first.copy(), start.following.copy()), c, k)
            for k, c in enumerate(costs[: len(starts_)])
        ]
        returned.append(results)
        return results

    monkeypatch.setattr(turns, "_reinsertion", fake)
    config = TurnsConfig(turn_s=0.05, meet_stalled=False)
    found = take_turns(ctx, start, cost, time.monotonic() + 0.25, 0, config)
    assert len(starts) == found.turns >= 3
    chains = len(starts[0])
    assert all(first is start for first in starts[0])
    for turn in range(1, found.turns):
        assert len(starts[turn]) == chains
        for k in range(chains):
            assert starts[turn][k] is returned[turn - 1][k].best  # its own lineage's
    last = returned[-1]
    cheapest = min(last, key=lambda line: line.cost)  # the first of equals
    assert (found.best, found.cost) == (cheapest.best, cheapest.cost)


def test_a_lineage_that_stalled_goes_on_from_the_cheapest_lineage(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A chain whose turn returned nothing cheaper than its start begins its next turn
    from the cheapest lineage's best, the others from their own (none lagging: ``behind``
    inf), and so does one that lags the cheapest by more than ``behind``; with
    ``meet_stalled`` off, every chain from its own."""
    ctx, start, cost = _wh50()
    # what each chain's turn takes off its start's cost: chain 0 stalls on turn 1, chain 1
    # on turns 2, 3, ...
    gains = [[1.0, 3.0], [0.0, 1.0]] + [[0.5, 0.0]] * 100

    def run(config: TurnsConfig) -> tuple[list[list[Assignments]], list[list[ReinsertResult]]]:
        starts: list[list[Assignments]] = []
        returned: list[list[ReinsertResult]] = []
        costs = {id(start): cost}

        def fake(ctx, starts_, until, seed, cooling, pool, stop):
            time.sleep(max(0.0, until - time.monotonic()))
            results = []
            for k, s in enumerate(starts_):
                found = Assignments(s.a_first.copy(), s.following.copy())
                costs[id(found)] = costs[id(s)] - gains[len(starts)][k]
                results.append(ReinsertResult(found, costs[id(found)], 1))
            starts.append(starts_)
            returned.append(results)
            return results

        monkeypatch.setattr(turns, "_reinsertion", fake)
        found = take_turns(ctx, start, cost, time.monotonic() + 0.2, 0, config)
        assert found.cost == min(line.cost for line in returned[-1])
        return starts, returned

    starts, returned = run(TurnsConfig(turn_s=0.05, chains=2, behind=np.inf))
    assert len(starts) >= 4
    own = [[line.best for line in lines] for lines in returned]
    assert _same(starts[1], own[0])  # both found cheaper: their own
    assert _same(starts[2], [own[1][1], own[1][1]])  # chain 0 stalled: the cheapest, chain 1's
    assert _same(starts[3], [own[2][0], own[2][0]])  # chain 1 stalled: the cheapest, chain 0's
    starts, returned = run(TurnsConfig(turn_s=0.05, chains=2, meet_stalled=False))
    assert all(_same(starts[t], [line.best for line in returned[t - 1]]) for t in range(1, 4))
    starts, returned = run(TurnsConfig(turn_s=0.05, chains=2, behind=0.01))
    assert returned[0][0].cost > 1.01 * returned[0][1].cost  # chain 0 lags after turn 0
    assert _same(starts[1], [returned[0][1].best] * 2)


@pytest.mark.parametrize("chains", [1, 2, 3, 5])
def test_the_first_lineages_start_from_the_cheapest_of_the_starts_given(
    chains: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With other starts (``auto``'s other plans), the first turn's chains start from the
    cheapest ``chains`` of all the starts, in the order given (the start first), and where
    there are fewer starts than chains, the rest from copies of the cheapest; the answer is
    valid and no dearer than the cheapest start."""
    ctx, _, _ = _wh50()
    plans = planned_starts(ctx, 3, 0, np.inf)  # cheapest first
    assert len(plans) == 3 and plans[0][1] < plans[1][1] < plans[2][1]
    (cheapest, least), middle, (start, cost) = plans  # the dearest plan the start
    first_turn: list[list[Assignments]] = []

    def recorded(ctx, starts, until, seed, cooling, pool, stop):
        if not first_turn:
            first_turn.append(starts)
        return turns_reinsertion(ctx, starts, until, seed, cooling, pool, stop)

    monkeypatch.setattr(turns, "_reinsertion", recorded)
    others = [middle, (cheapest, least)]  # dearest first: the lineages keep the order given
    config = TurnsConfig(turn_s=0.05, chains=chains)
    found = take_turns(ctx, start, cost, time.monotonic() + 0.2, 0, config, others=others)
    expected = {1: [cheapest], 2: [middle[0], cheapest], 3: [start, middle[0], cheapest],
                5: [start, middle[0], cheapest, cheapest, cheapest]}  # fmt: skip
    assert _same(first_turn[0], expected[chains])
    assert found.cost <= least
    _assert_valid(ctx, found.best, found.cost)


@pytest.mark.parametrize(
    ("chains", "race", "turn_s"),
    [
        (1, 2, 0.05),
        (2, 2, 0.05),
        (1, 3, 0.05),
        (3, 2, 0.05),
        (2, 1, 0.05),
        (2, 2, 0.04),
        (5, 2, 0.05),
    ],
)
def test_a_long_enough_first_turn_races_the_cheapest_starts_in_turns_of_their_own(
    chains: int, race: int, turn_s: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A first turn of ``race_least_s`` at least starts a race: the cheapest ``race`` times
    ``chains`` starts (as many as there are at most), ``chains`` a turn, cheapest first,
    each turn from starts of its own (no meeting between them); the turn after them goes
    on from the cheapest ``chains`` of all that those turns ended with, in the order they
    ran. With ``race`` 1, a shorter first turn or no more starts than chains, nothing
    races: the first turn starts from the cheapest starts in the order given, the next
    from their meeting."""
    ctx, start, cost = _wh50()
    every = [(start, cost), *planned_starts(ctx, 4, 0, np.inf)]  # five starts
    by_turn: list[list[Assignments]] = []
    ended: list[list[ReinsertResult]] = []

    races = race > 1 and turn_s >= 0.05 and len(every) > chains  # 0.05: race_least_s

    def recorded(ctx, starts, until, seed, cooling, pool, stop):
        by_turn.append(starts)
        if races and len(by_turn) == 2:  # the race's second turn finds nothing: starts back
            ended.append([ReinsertResult(a, cost_of[id(a)], 0) for a in starts])
        else:
            ended.append(turns_reinsertion(ctx, starts, until, seed, cooling, pool, stop))
        return ended[-1]

    cost_of = {id(answer): of for answer, of in every}
    monkeypatch.setattr(turns, "_reinsertion", recorded)
    config = TurnsConfig(turn_s=turn_s, turn_share=1.0, chains=chains, race=race, race_least_s=0.05)
    found = take_turns(ctx, start, cost, time.monotonic() + 0.4, 0, config, others=every[1:])
    by_cost = sorted(range(len(every)), key=lambda k: every[k][1])
    if not races:
        assert _same(by_turn[0], [every[k][0] for k in sorted(by_cost[:chains])])
        began = [ReinsertResult(every[k][0], every[k][1], 0) for k in sorted(by_cost[:chains])]
        met = turns._met(began, ended[0], config.behind)
        assert _same(by_turn[1], [line.best for line in met])
    else:
        racing = -(-min(race * chains, len(every)) // chains)  # turns of the race
        assert len(by_turn) > racing
        for turn in range(racing):
            racers = by_cost[turn * chains : min((turn + 1) * chains, race * chains)]
            assert _same(by_turn[turn], [every[k][0] for k in racers])
        raced = [line for lines in ended[:racing] for line in lines]
        going_on = sorted(range(len(raced)), key=lambda k: raced[k].cost)[:chains]
        assert _same(by_turn[racing], [raced[k].best for k in sorted(going_on)])
    _assert_valid(ctx, found.best, found.cost)


def _same(xs: list[Assignments], ys: list[Assignments]) -> bool:
    """The same answers (the very objects), in the same order."""
    return len(xs) == len(ys) and all(x is y for x, y in zip(xs, ys, strict=True))


def test_stalled_and_lagging_lineages_are_replaced_by_the_cheapest_the_others_kept() -> None:
    """After a turn, each lineage that ended no cheaper than it began, or more than
    ``behind`` dearer than the cheapest, is the cheapest lineage (the first of equals);
    the others are their own."""

    def line(cost: float) -> ReinsertResult:
        return ReinsertResult(Assignments.single(*FLAGS), cost, 0)

    a0, b0, c0 = line(5.0), line(4.0), line(3.0)
    a1, b1, c1 = line(5.0), line(2.0), line(2.0)
    assert turns._met([a0, b0, c0], [a1, b1, c1], np.inf) == [b1, b1, c1]
    assert turns._met([a0, b0], [a1, b1], np.inf)[0] is b1
    assert turns._met([a0], [a1], np.inf) == [a1]
    a2, b2 = line(4.1), line(4.0)  # a improved, lagging by 2.5 %
    assert turns._met([a0, b0], [a2, b2], 0.03) == [a2, b2]  # b stalled, the cheapest
    assert turns._met([a0, c0], [a2, c1], 0.03) == [c1, c1]  # a lags by 105 %
    assert turns._met([a0, c0], [line(2.06), c1], 0.03)[0].cost == 2.06  # by 3 %: kept
    assert turns._met([a0, c0], [line(2.061), c1], 0.03)[0] is c1  # just past


FLAGS = (np.zeros(1, dtype=bool), np.zeros(1, dtype=bool))  # a one-conflict answer


def test_lineages_stop_dearest_first_and_new_ones_start_from_the_cheapest() -> None:
    """Fewer cores: the cheapest lineages go on, in their order; more: every lineage goes
    on and new ones start from the cheapest answer."""
    a, b, c = (ReinsertResult(Assignments.single(*FLAGS), cost, 0) for cost in (3.0, 1.0, 2.0))
    assert turns._as_many([a, b, c], 2) == [b, c]
    assert turns._as_many([a, b, c], 1) == [b]
    assert turns._as_many([a, b], 4) == [a, b, b, b]
    assert turns._as_many([a], 1) == [a]


def test_turns_end_once_stopped() -> None:
    """A ``stop`` set while the turns search ends them at the next step, long before their
    deadline, with a valid answer no worse than the start; set before, no step is taken."""
    ctx, start, cost = _wh50()
    stop = threading.Event()
    timer = threading.Timer(0.15, stop.set)
    begin = time.monotonic()
    timer.start()
    found = take_turns(ctx, start, cost, begin + 3.0, 0, stop=stop)
    timer.join()
    assert time.monotonic() - begin < 0.15 + 0.2
    assert found.turns >= 1 and found.cost <= cost
    _assert_valid(ctx, found.best, found.cost)
    stopped = reinsert_search(ctx, start, time.monotonic() + 1.0, 0, stop=stop)
    assert stopped.steps == 0 and stopped.best is start


@pytest.mark.parametrize(("held", "expected"), [(0, [2, 2]), (1, [1, 1]), (2, [])])
def test_turns_leave_the_cores_held_for_other_work(
    monkeypatch: pytest.MonkeyPatch, held: int, expected: list[int]
) -> None:
    """With ``held`` cores kept for other work of the solve (``auto``'s exact stages), a turn
    runs one lineage per core the solve may take less those, and none where none is left
    (the start comes back); with none held, one per core."""
    chains_by_turn: list[int] = []

    def recorded(ctx, starts, until, seed, cooling, pool, stop):
        chains_by_turn.append(len(starts))
        return turns_reinsertion(ctx, starts, until, seed, cooling, pool, stop)

    monkeypatch.setattr(turns, "_reinsertion", recorded)
    monkeypatch.setattr(turns, "cores_per_solve", lambda: 2)
    ctx, start, cost = _wh50()
    config = TurnsConfig(turn_s=0.05, turn_share=1.0)
    found = take_turns(ctx, start, cost, time.monotonic() + 0.1, 0, config, held=held)
    assert chains_by_turn[:2] == expected
    assert found.turns == len(chains_by_turn)
    if not expected:
        assert found.best is start and found.cost == cost
