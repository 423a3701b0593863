"""The GNN-VAE solver: S latent samples decoded into valid assignments, cheapest returned.

Every sample goes through the shared constraint-guaranteed decoder, so every
candidate is acyclic and density-feasible by construction. Without a loaded
model for the request's objective it answers ``None`` and the dispatcher
degrades to the exact solver (then FCFS).
"""

from __future__ import annotations

import time

import numpy as np

from service.core.assignment import Assignments
from service.core.retype import descend_types
from service.learning.features import graph_tensors
from service.learning.infer import Sampled, sample_best
from service.learning.store import StoredModel
from service.solvers.registry import SolveContext, SolverOutput, register
from service.solvers.reinsert import REINSERT_OBJECTIVES, cheapest_plan

__all__ = [
    "DEFAULT_SAMPLES",
    "EMBED_S_PER_EDGE",
    "PLANNED_DRAWS",
    "PLANNED_MIN_CONFLICTS",
    "descended_draws",
    "embed_fits",
    "gnn_vae",
    "least_request_s",
    "model_answer",
    "planned_draws",
    "plans_serve",
    "sample_model",
]

# Samples per request when the request does not say: the published default.
DEFAULT_SAMPLES = 100
# The least a request of the model costs, per graph edge: the trunk (once, and it cannot
# stop part-way), the first chunk of draws decoded and evaluated, the cheapest refitted,
# the answer checked and rendered. Measured (session 43, 2-vCPU Xeon, one process, seven
# seeds, a 1-ms limit so that only the first chunk runs; ``solve_case`` of ``bench.cases``):
# p50 3.3e-6 s per edge on generated warehouses of 100-250 robots (143 ms for the 43,670
# edges of 250 two-way robots, 79 ms for 23,234 two-lane; slowest 3.7e-6), ~6 ms at 25
# robots. Since the fused trunk (session 17) this is ~4x less than the 1.5e-5 calibrated
# on the PyG trunk, which kept the model from every 250-robot request below ~1 s (FCFS
# answered instead). Under heavy load a request may overrun by the excess of this
# least part; the model is not dropped where it serves.
EMBED_S_PER_EDGE = 4e-6
# From this many conflicts the model's draws are also decoded by prioritized planning:
# each of PLANNED_DRAWS draws, spread along the sample ladder, gives the robots' order
# (its bids of their first nodes), each robot is placed on its cheapest passage past those
# before it (reinsert.cheapest_plan), and the cheapest plan answers where it beats the
# decoded draws. The rank decoder sets every conflict's direction by comparing two ranks,
# blind to when the robots arrive. Measured (session 43, docs/benchmarks.md; seed 0,
# avg_completion v14): on generated warehouses of 100-250 robots (2,000-22,000 conflicts)
# any single plan cost about half of the best of 100 decoded draws (with the plans, on
# the 16 worlds of 100 and 250 robots of bench.generalization: 0.34-0.69 of the decoded
# draws' cost, +10-110 ms at 250 robots), and on its held-out 250-robot worlds the best of
# 4 plans in the model's orders cost 0.90-0.96 of the best of 4 in the orders ``auto``
# starts from (shortest route, earliest finish, two random; on the trained kinds
# 0.96-1.06). Below, the decoded draws stand (issue 3's small-problem figures were
# measured so), or their types by descent (next); avg_completion and avg_delay only, the
# sums plans minimise.
PLANNED_MIN_CONFLICTS = 1_000
PLANNED_DRAWS = 4
# Below PLANNED_MIN_CONFLICTS conflicts (every objective) the cheapest draws' directions
# (infer.REFIT_TOP of them) also get the types a descent from all-exclusive reaches
# (``retype.descend_types``, until the time limit), the cheapest answering where cheaper
# than the best draw: the decoder's types, refitted by the waits following spares, sit in
# local optima no single flip leaves. The four draws' descents against the best draw's
# alone (`/tmp/s44/topk.py`, held-out seeds of 25-50-robot warehouses, 15 worlds): 1.027x
# cheaper on average, up to 1.17x, 7-190 ms for all four. The best draw's alone
# (session 44, `/tmp/s44/mtypes2.py`, not committed; avg_completion v14, the best of 100
# draws, seed 0; cost of the draw over the answer's): generated warehouses of 25 robots
# (130-300 conflicts) one-way 1.14-1.48 (27-44 ms), two-way 1.04-1.19, wh_mixed 1.00-1.04,
# wh_parked 1.00-1.03, two-lane 1.00; of 50 robots two-way 1.08-1.20 (800-900 conflicts,
# 29-71 ms), one-way 1.29-1.48 (1,000-1,030, 160-409 ms); floors and the conformance sets
# (wh_25, wh_50, geo_dense_25, geo_10) 1.000-1.002 in 0-5 ms. From PLANNED_MIN_CONFLICTS
# the cheaper of the best draw and the plans gets types by descent on its directions (every
# objective; for max_completion and sync_completion, which have no plans, the best draw's):
# the planner keeps following-type wherever the exclusive wait would not hold while a
# clique has room, first come first served, and its types cost 1.03-1.22x a descent's
# on its own directions. Measured (session 45, `/tmp/s45/big2.py`, not committed;
# avg_completion v14, seed 0, held-out seeds of generated warehouses): plan / descended,
# 100 robots (3,000-4,000 conflicts) two-way 205.7 / 173.7 (0.14 s), 236.4 / 216.1 (0.11 s),
# two-lane 152.2 / 135.8 (0.29 s), 160.9 / 155.5 (0.25 s), wh_mixed 369.5 / 302.2 (0.35 s),
# 179.3 / 179.3 (1.0 s); 250 robots (18,500-24,000) two-way 686.4 / 616.5 (1.5 s), 681.9 /
# 601.8 (2.4 s), two-lane 533.4 / 433.2 (3.3 s), 612.3 / 561.6 (3.2 s), wh_mixed 1230.3 /
# 996.4 (8.2 s), 521.6 / 497.6 (~30 s). max_completion and sync_completion, the best draw
# descended (bench.generalization, the same 16 worlds, before / after on one yardstick,
# docs/benchmarks.md session 45): max 100 robots 0.56-0.62 -> 0.83-0.86, 250 robots
# 0.65-0.66 -> 0.97-1.00 (1.2-27 s); sync 0.54-0.57 -> 0.74-0.90, 0.58 -> 0.90-0.92. The
# descent runs until the time limit: at 250 robots a request takes seconds. Descending from
# the plan's own types instead stalled after 0-11 rounds, 0-3 % cheaper; the best draw's
# directions descended cost 1.03-2.2x the plan's; more flips a round (32, 128) were 2-3x
# faster and up to 20 % dearer; re-costing only the flips cheapest when last costed 2-3x
# faster and up to 16 % dearer.


def least_request_s(ctx: SolveContext) -> float:
    """The least a model request is expected to take on ``ctx``'s graph (EMBED_S_PER_EDGE
    per edge: one per consecutive node pair of a robot, two per conflict)."""
    p = ctx.problem
    return EMBED_S_PER_EDGE * (p.n_nodes - p.n_robots + 2 * p.n_conflicts)


def embed_fits(ctx: SolveContext, seconds: float) -> bool:
    """Whether the least part of a model request (the trunk, the first draws; see
    :func:`least_request_s`) is expected to finish within ``seconds``."""
    return least_request_s(ctx) <= seconds


@register("gnn_vae")
def gnn_vae(ctx: SolveContext) -> SolverOutput | None:
    """Best of ``ctx.samples`` (default 100) decoded samples of the objective's model.

    Samples are decoded in memory-bounded chunks; once the time limit has passed no
    further chunk starts, and the answer says how many samples it is the best of. A
    graph whose least model request (:func:`embed_fits`) would outlast the time limit
    gets no answer (None). Below PLANNED_MIN_CONFLICTS conflicts the cheapest draws'
    directions with types by descent, from there a plan in a draw's robot order, answer
    where cheaper (:func:`model_answer`, within the time limit).
    """
    stored = ctx.models.get(ctx.objective)
    if stored is None or not embed_fits(ctx, ctx.time_limit_s):
        return None  # the dispatcher falls back rather than overrun the time limit
    samples = ctx.samples or DEFAULT_SAMPLES
    deadline = time.monotonic() + ctx.time_limit_s
    best = sample_model(ctx, stored, samples, deadline)
    notes = []
    if best.samples < samples:
        notes.append(f"time limit reached after {best.samples} of {samples} samples")
    answer, replaced = model_answer(ctx, best, deadline)
    if replaced is not None:
        notes.append(f"answered by {replaced}: cheaper than the decoded draws")
    return SolverOutput(
        answer,
        optimal=False,
        model=stored.name,
        samples=best.samples,
        detail="; ".join(notes) or None,
    )


def model_answer(
    ctx: SolveContext, sampled: Sampled, deadline: float, descend: bool = True
) -> tuple[Assignments, str | None]:
    """``sampled``'s best decoded draw, or what is cheaper, made until ``deadline``: below
    PLANNED_MIN_CONFLICTS conflicts the cheapest draws' directions with the types a
    descent from all-exclusive reaches (:func:`descended_draws`); from there the cheaper
    of the best draw and the cheapest plan in the draws' robot orders
    (:func:`planned_draws`), and, if ``descend``, its directions with types by descent
    where cheaper still -> (answer, what replaced the draw, or None)."""
    if ctx.problem.n_conflicts < PLANNED_MIN_CONFLICTS:
        descended = descended_draws(ctx, sampled.top_directions, deadline)
        if descended is not None and descended[1] < sampled.cost:
            return descended[0], "a cheap draw's directions with types by descent"
        return sampled.assignment, None
    answer, cost, replaced = sampled.assignment, sampled.cost, None
    planned = planned_draws(ctx, sampled, deadline)
    if planned is not None and planned[1] < cost:
        (answer, cost), replaced = planned, "a plan in a draw's robot order"
    descended = descended_draws(ctx, answer.a_first, deadline) if descend else None
    if descended is not None and descended[1] < cost:
        return descended[0], f"{replaced or 'the best draw'}, its types by descent"
    return answer, replaced


def descended_draws(
    ctx: SolveContext, rows: np.ndarray, deadline: float
) -> tuple[Assignments, float] | None:
    """The cheapest of the types by descent (``retype.descend_types``) on the directions
    ``rows`` (T, M) (each distinct once, in order: the cheapest draws' or one answer's),
    made until ``deadline`` -> (answer, cost); None where none was started in time."""
    found: tuple[Assignments, float] | None = None
    seen: list[np.ndarray] = []
    for directions in rows:  # (M,) each
        if time.monotonic() >= deadline:
            break
        if any(np.array_equal(directions, done) for done in seen):
            continue
        seen.append(directions)
        answer, cost, _ = descend_types(
            ctx.orientation, ctx.evaluator, ctx.objective, directions[None], deadline
        )
        if found is None or cost < found[1]:
            found = (answer, cost)
    return found


def plans_serve(ctx: SolveContext) -> bool:
    """Whether the draws are also decoded by planning on ``ctx``: from
    PLANNED_MIN_CONFLICTS conflicts, for the objectives plans minimise."""
    return ctx.problem.n_conflicts >= PLANNED_MIN_CONFLICTS and ctx.objective in REINSERT_OBJECTIVES


def planned_draws(
    ctx: SolveContext, sampled: Sampled, deadline: float
) -> tuple[Assignments, float] | None:
    """The cheapest prioritized plan (:func:`~service.solvers.reinsert.cheapest_plan`) in
    the robot orders of PLANNED_DRAWS of ``sampled``'s draws spread along its ladder, made
    until ``deadline`` -> (answer, cost); None below PLANNED_MIN_CONFLICTS, for the
    objectives plans do not serve, or where none was made in time."""
    if not plans_serve(ctx):
        return None
    rows = np.unique(np.linspace(0, len(sampled.priorities) - 1, PLANNED_DRAWS).astype(np.int64))
    orders = [np.argsort(sampled.priorities[row], kind="stable") for row in rows]
    return cheapest_plan(ctx, orders, deadline)


def sample_model(ctx: SolveContext, stored: StoredModel, samples: int, deadline: float) -> Sampled:
    """The best of ``samples`` decoded draws of ``stored``'s model for ``ctx``'s problem, or
    of those decoded by ``deadline`` (``time.monotonic()``)."""
    graph = graph_tensors(ctx.problem, ctx.cliques)
    return sample_best(
        stored.model,
        graph,
        ctx.decoder,
        ctx.evaluator,
        ctx.objective,
        samples,
        ctx.seed,
        deadline=deadline,
    )
