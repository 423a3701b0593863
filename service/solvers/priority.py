"""Robot-priority search: an evolution strategy over one rank offset per robot.

Tabu search changes one conflict per iteration; on a congested warehouse of 100-250
robots the blended start (:func:`~service.solvers.tabu.plain_start`) is thousands of
conflicts from a good schedule, and tabu search spends seconds walking there. Here a
move shifts one robot's whole priority: node ranks are the cheapest blend's ranks
(V,) plus an offset per robot (constant along its path, so ranks stay non-decreasing
along every path and every decoded answer is acyclic and valid); a candidate adds
N(0, (``step`` x time span)^2) to one random robot's offset, which reverses every conflict
whose order against that robot the shift crosses, at once. Each round decodes and
evaluates ``candidates`` of them that reorder something (a third of the shifts cross no
other robot's rank where they meet, and are skipped) in one batched call and keeps the
cheapest if it beats the current (a (1 + lambda) strategy). Types start as the start's
(FCFS's greedy fill, or the one by the wait each following-type conflict spares under
the start's directions, :func:`~service.core.decode.following_gain`: with the latter,
the same search ended 4-8 % lower on 100-robot warehouses), and every
``refit_every`` rounds the best's types are refitted to its directions at the waits
its schedule has (:func:`~service.core.retype.refit_types`, kept only when cheaper):
types chosen for the start's directions spend the density budgets where the moved
robots no longer wait. That lifted ``auto`` on generated warehouses of 25-250 robots
from 0.951-0.954 to 0.975 of the best known at 5 s, and from 0.872-0.880 to 0.891 at
1 s (docs/benchmarks.md, "Types refitted during priority search").

Measured (docs/benchmarks.md, "Anytime auto"): as ``auto``'s first stage it beat tabu
search alone on every generated warehouse and floor at 0.3-3 s (``wh_two_lane`` of 100
robots: 0.92 against 0.77 of the best known at 1 s). On warehouses of 100 robots it
stalls after a few hundred rounds, and :func:`priority_tabu` hands over to tabu search,
which then still finds single-conflict improvements; at 250 robots it was still
improving after 10 s. Costing candidates incrementally (as groups of reversals) was
tried and measured no faster: a shift reverses 5-300 conflicts, and on a two-way
warehouse of 250 robots their propagation costs as much as the full evaluation.
Decoding a shift looks only at the conflicts of the nodes whose rank it moved
(:class:`RankFlips`), and the candidates are costed as reversals of the best
(:meth:`~service.core.evaluate.Evaluator.evaluate_flips`: its arcs grouped once, each
candidate's walk whole): rounds per second at 250 robots rose from 180-200 to
400-470 (two-way) and from 280-310 to 400-580 (two-lane), and the best after 1 s fell
by 8 % summed over six such worlds and two seeds (7,052 -> 6,456).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numba
import numpy as np

from service.core.assignment import Assignments
from service.core.problem import Problem
from service.core.retype import refit_types
from service.solvers.fcfs import cheapest_blend
from service.solvers.registry import SolveContext, SolverOutput, register
from service.solvers.tabu import tabu_search

__all__ = [
    "PriorityConfig",
    "RankFlips",
    "priority_search",
    "priority_tabu",
    "reversed_in",
    "shifted_flips",
]


@dataclass(frozen=True)
class PriorityConfig:
    """Candidates per round, step size and the stopping rule."""

    candidates: int = 8  # robots shifted per round, one each (a batched evaluation)
    step: float = 0.1  # offset standard deviation, as a share of the problem's time span
    # The step from wide_from conflicts (the 250-robot warehouses: 11,000-23,000; where
    # ``auto`` gives the search its whole budget, above exact_stage_max_conflicts).
    # Measured (session 23; ``auto``, cost ratio against the best known, 0.1 -> 0.2): six
    # 250-robot warehouses of the bench 1 s 0.8876 -> 0.9040 (three seeds; 0.05: 0.8459,
    # 0.3: 0.8774 where 0.2 had 0.8958), 5 s 0.9608 -> 0.9807 (two seeds, better on all
    # six); eight 250-robot worlds of kinds not tuned on (wh_one_way, wh_mixed, wh_parked)
    # 1 s 0.9341 -> 0.9641 (three seeds, better on six). Below it 0.1 stays: 100-robot
    # warehouses 1 s +0.008, 5 s -0.007 (noise, LNS decides there), 25-50 robots 1 s
    # -0.005 to -0.007.
    wide_step: float = 0.2
    wide_from: int = 10_000
    # Rounds without a cheaper candidate before stopping (and tabu search taking over in
    # priority_tabu). 30 until session 22; with the types refitted the search goes on
    # improving after such stalls: ``auto`` at 5 s on six 250-robot warehouses (two seeds)
    # 0.9489 -> 0.9869 of the best known with 100, better on all six; at 1 s +0.006, on
    # 100-robot warehouses (LNS after it) +0.005 at 5 s and +0.002 at 1 s (noise); at 5 s
    # on the 250-robot ones against 100: 60 rounds -0.011, 300 rounds -0.034.
    patience: int = 100
    max_rounds: int = 100_000
    # Rounds between refits of the best's types to its directions (0: never), in searches
    # given at least refit_min_s seconds. Measured (docs/benchmarks.md, "Types refitted
    # during priority search"; ``auto`` on generated warehouses, mean cost ratio): with
    # 1-5 s of search, 250 robots +0.02-0.05, 100 robots +0.01-0.03; with 0.3 s (100
    # robots at a 1-s budget, LNS after it) -0.01 to -0.03: early on the directions move
    # fast and types fitted to them go stale. Every 100 rounds: as good at 250 robots,
    # no gain at 100. (At a 1-s budget, 250 robots' search gets ~0.9 s: above 0.5.)
    refit_every: int = 50
    refit_min_s: float = 0.5


class RankFlips:
    """The conflicts that new ranks reverse against the current best's, found from the
    conflicts of the nodes whose (repaired) rank changed.

    Decoding ranks whole gathers and compares (D, M) ranks per round, 40 % of a round at
    250 robots once the evaluator had become leaner; a robot's shift changes the ranks of
    its own nodes and of the few nodes the decoder's repair pushes behind them (fixed
    directions), so only their conflicts need a look. Equal to
    :meth:`~service.core.decode.Decoder.directions` by construction: the same repaired
    ranks, the same comparison, and every other conflict keeps the best's direction,
    which was decoded from the best's ranks.
    """

    @classmethod
    def of(cls, ctx: SolveContext) -> RankFlips:
        """``ctx``'s, built once per context (~3 ms at 22,000 conflicts)."""
        cached = ctx.__dict__.get("_rank_flips")
        if cached is None:
            cached = ctx.__dict__["_rank_flips"] = cls(ctx.problem)
        return cached

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        nodes = np.concatenate([problem.conf_a, problem.conf_b])  # (2M,) node of each side
        order = np.argsort(nodes, kind="stable")
        self.conflicts = order % problem.n_conflicts  # (2M,) conflicts grouped by node
        self.start = np.searchsorted(nodes[order], np.arange(problem.n_nodes + 1))  # (V+1,)

    def flips(
        self,
        trial: np.ndarray,  # (D, V) repaired ranks of each draw
        ranks: np.ndarray,  # (V,) the current best's repaired ranks
        a_first: np.ndarray,  # (M,) bool, the current best's directions
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each draw's reversed conflicts as a CSR: (D+1,) starts into (K,) conflicts."""
        p = self.problem
        return _flips(
            trial, ranks, self.start, self.conflicts, p.conf_a, p.conf_b, a_first.view(np.uint8)
        )


@numba.njit(cache=True, nogil=True)
def _flips(
    trial: np.ndarray,  # (D, V) float
    ranks: np.ndarray,  # (V,) float
    start: np.ndarray,  # (V+1,) int, CSR into conflicts
    conflicts: np.ndarray,  # (2M,) int, conflicts by node
    conf_a: np.ndarray,  # (M,) int
    conf_b: np.ndarray,  # (M,) int
    a_first: np.ndarray,  # (M,) uint8
) -> tuple[np.ndarray, np.ndarray]:  # (D+1,) int starts, (K,) int reversed conflicts
    n_draws, n_nodes = trial.shape
    seen = np.full(a_first.size, -1, dtype=np.int64)  # the last draw that looked at c
    out_start = np.zeros(n_draws + 1, dtype=np.int64)
    out = np.empty(16, dtype=np.int64)
    n = 0
    for k in range(n_draws):
        r = trial[k]
        for v in range(n_nodes):
            if r[v] == ranks[v]:
                continue
            for i in range(start[v], start[v + 1]):
                c = conflicts[i]
                if seen[c] == k:
                    continue
                seen[c] = k
                a, b = conf_a[c], conf_b[c]
                first = r[a] < r[b] or (r[a] == r[b] and a < b)
                if first != (a_first[c] == 1):
                    if n == out.size:
                        out = np.concatenate((out, np.empty(n, dtype=np.int64)))
                    out[n] = c
                    n += 1
        out_start[k + 1] = n
    return out_start, out[:n]


def priority_search(
    ctx: SolveContext,
    budget_s: float,
    seed: int,
    cfg: PriorityConfig = PriorityConfig(),
) -> tuple[Assignments, float, int]:
    """Search robot offsets from the cheapest blend -> (best, its cost, rounds run).

    Stops after ``cfg.patience`` rounds without improvement, after ``cfg.max_rounds`` or
    after ``budget_s`` seconds; deterministic for a seed when it stops on one of the first
    two. Given at least ``cfg.refit_min_s``, it refits the best's types every
    ``cfg.refit_every`` rounds and once at the end.
    """
    deadline = time.perf_counter() + budget_s
    p, decoder, evaluator = ctx.problem, ctx.decoder, ctx.evaluator
    rng = np.random.default_rng(seed)
    base, best, best_cost = cheapest_blend(ctx)
    flips = RankFlips.of(ctx)
    offsets = np.zeros(p.n_robots)  # (R,) the current (best) offsets
    ranks = decoder.repair(base[None])[0]  # (V,) the current best's repaired ranks
    step = cfg.wide_step if p.n_conflicts >= cfg.wide_from else cfg.step
    sigma = step * float(p.node_exit.max() - p.node_enter.min())
    draws = 2 * cfg.candidates  # a third of single-robot shifts reorder nothing: drawn over
    refit_every = cfg.refit_every if budget_s >= cfg.refit_min_s else 0
    refit_s = 0.0  # the last refit's seconds: the search stops that much early for the final one
    stale = rounds = 0
    while (
        stale < cfg.patience
        and rounds < cfg.max_rounds
        and time.perf_counter() < deadline - refit_s
    ):
        rounds += 1
        stale += 1
        if refit_every and rounds % refit_every == 0:
            started = time.perf_counter()
            best, best_cost = refit_types(decoder, evaluator, ctx.objective, best)
            refit_s = time.perf_counter() - started
        robot = rng.integers(p.n_robots, size=draws)  # (D,)
        shifted = offsets[robot] + rng.normal(0.0, sigma, draws)  # (D,)
        moved, start, flipped, moved_ranks = shifted_flips(
            ctx, flips, robot, shifted, base, offsets, ranks, best, cfg.candidates
        )  # (C,), (C+1,), (K,), (C, V)
        if moved.size == 0:
            continue
        cost = evaluator.evaluate_flips(best, start, flipped).costs[ctx.objective]  # (C,)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best, best_cost = reversed_in(best, flipped[start[k] : start[k + 1]]), float(cost[k])
            offsets[robot[moved[k]]] = shifted[moved[k]]
            ranks = moved_ranks[k]
            stale = 0
    if refit_every:
        best, best_cost = refit_types(decoder, evaluator, ctx.objective, best)
    return best, best_cost, rounds


def shifted_flips(
    ctx: SolveContext,
    flips: RankFlips,
    robot: np.ndarray,  # (D,)
    shifted: np.ndarray,  # (D,)
    base: np.ndarray,  # (V,)
    offsets: np.ndarray,  # (R,)
    ranks: np.ndarray,  # (V,)
    best: Assignments,
    limit: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The first ``limit`` draws that reverse something -> their indices (C,), the
    conflicts each reverses against the best as a CSR ((C+1,) starts into (K,)
    conflicts; :meth:`Evaluator.evaluate_flips` costs them without building them) and
    their repaired ranks (C, V)."""
    trial = np.repeat(offsets[None], robot.size, axis=0)  # (D, R)
    trial[np.arange(robot.size), robot] = shifted
    repaired = ctx.decoder.repair(base[None] + trial[:, ctx.problem.node_robot])  # (D, V)
    start, flipped = flips.flips(repaired, ranks, best.a_first[0])  # (D+1,), (K,)
    counts = np.diff(start)  # (D,)
    moved = np.flatnonzero(counts)[:limit]  # (C,)
    is_moved = np.zeros(robot.size, dtype=bool)  # (D,)
    is_moved[moved] = True
    taken = np.repeat(is_moved, counts)  # (K,)
    kept_start = np.concatenate([[0], np.cumsum(counts[moved])])  # (C+1,)
    return moved, kept_start, flipped[taken], repaired[moved]


def reversed_in(best: Assignments, conflicts: np.ndarray) -> Assignments:
    """``best`` (a batch of one) with ``conflicts`` (K,) reversed."""
    a_first = best.a_first.copy()  # (1, M)
    a_first[0, conflicts] ^= True
    return Assignments(a_first, best.following)


@register("priority_tabu")
def priority_tabu(ctx: SolveContext) -> SolverOutput:
    """Robot-priority search until it stalls, then tabu search from the cheaper of its
    best and a re-schedule's previous answer, in the request's time limit (the search
    starts at the cheapest blend and never returns worse)."""
    deadline = time.perf_counter() + ctx.time_limit_s
    found, cost, rounds = priority_search(ctx, ctx.time_limit_s, ctx.seed)
    warm = ctx.warm
    if warm is not None and float(ctx.evaluator.evaluate(warm).costs[ctx.objective][0]) < cost:
        found = warm
    left = deadline - time.perf_counter()
    best, _, iterations = tabu_search(ctx, found, budget_s=max(left, 0.0))
    return SolverOutput(best, detail=f"{rounds} priority rounds, {iterations} tabu iterations")
