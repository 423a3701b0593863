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
# The model's trunk runs once per request and cannot stop part-way: 0.6-0.8 s for 43,670
# graph edges (250 robots, 21,835 conflicts) on the 2-core machine lightly loaded, up to
# 1.8 s under a load of 3. Calibrated on the light load: at heavy load a request may
# overrun by the trunk's excess, but the model is not dropped where it serves.
EMBED_S_PER_EDGE = 1.5e-5


def embed_fits(ctx: SolveContext, seconds: float) -> bool:
    """Whether the model's trunk is expected to finish within ``seconds`` on ``ctx``'s graph
    (edges: one per consecutive node pair of a robot, two per conflict)."""
    p = ctx.problem
    edges = p.n_nodes - p.n_robots + 2 * p.n_conflicts
    return EMBED_S_PER_EDGE * edges <= seconds


@register("gnn_vae")
def gnn_vae(ctx: SolveContext) -> SolverOutput | None:
    """Best of ``ctx.samples`` (default 100) decoded samples of the objective's model.

    Samples are decoded in memory-bounded chunks; once the time limit has passed no
    further chunk starts, and the answer says how many samples it is the best of. A
    graph whose trunk alone would outlast the time limit gets no answer (None).
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
