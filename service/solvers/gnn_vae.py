"""The GNN-VAE solver: S latent samples decoded into valid assignments, cheapest returned.

Every sample goes through the shared constraint-guaranteed decoder, so every
candidate is acyclic and density-feasible by construction. Without a loaded
model for the request's objective it answers ``None`` and the dispatcher
degrades to the exact solver (then FCFS).
"""

from __future__ import annotations

import time

from service.learning.features import graph_tensors
from service.learning.infer import Sampled, sample_best
from service.learning.store import StoredModel
from service.solvers.registry import SolveContext, SolverOutput, register

__all__ = ["DEFAULT_SAMPLES", "EMBED_S_PER_EDGE", "embed_fits", "gnn_vae", "sample_model"]

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


def embed_fits(ctx: SolveContext, seconds: float) -> bool:
    """Whether the least part of a model request (the trunk, the first draws; see
    EMBED_S_PER_EDGE) is expected to finish within ``seconds`` on ``ctx``'s graph (edges:
    one per consecutive node pair of a robot, two per conflict)."""
    p = ctx.problem
    edges = p.n_nodes - p.n_robots + 2 * p.n_conflicts
    return EMBED_S_PER_EDGE * edges <= seconds


@register("gnn_vae")
def gnn_vae(ctx: SolveContext) -> SolverOutput | None:
    """Best of ``ctx.samples`` (default 100) decoded samples of the objective's model.

    Samples are decoded in memory-bounded chunks; once the time limit has passed no
    further chunk starts, and the answer says how many samples it is the best of. A
    graph whose least model request (:func:`embed_fits`) would outlast the time limit
    gets no answer (None).
    """
    stored = ctx.models.get(ctx.objective)
    if stored is None or not embed_fits(ctx, ctx.time_limit_s):
        return None  # the dispatcher falls back rather than overrun the time limit
    samples = ctx.samples or DEFAULT_SAMPLES
    best = sample_model(ctx, stored, samples, time.monotonic() + ctx.time_limit_s)
    detail = None
    if best.samples < samples:
        detail = f"time limit reached after {best.samples} of {samples} samples"
    return SolverOutput(
        best.assignment, optimal=False, model=stored.name, samples=best.samples, detail=detail
    )


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
