"""GNN-VAE inference: S latent samples -> S decoded, valid assignments -> the cheapest.

Used by the ``gnn_vae`` solver and by validation during training, so both see
exactly the same decoding. The trunk runs once; the S samples only pass
through the heads. Deterministic for a seed (a private torch.Generator).
"""

from __future__ import annotations

import time
from collections.abc import Generator
from dataclasses import dataclass

import numpy as np
import torch

from service.core.assignment import Assignments
from service.core.decode import Decoder, decode_candidates
from service.core.evaluate import Evaluator
from service.core.problem import Problem
from service.core.retype import refit_types
from service.core.schemas import Objective
from service.learning.features import GraphTensors
from service.learning.fused_gat import TargetArcs
from service.learning.model import GnnVae

__all__ = [
    "BID_NOISE",
    "CHUNK_BYTES",
    "SHARED_TYPES_MIN_CONFLICTS",
    "Sampled",
    "chunk_rows",
    "propose",
    "propose_chunks",
    "sample_best",
]

# Working memory of one chunk of samples, the bound that keeps a request's peak memory
# independent of its sample count. Per sample, the heads hold about three float32
# (V + M, hidden) activations, and the decoder lays the bids out per robot, padded to
# the longest path (two float64 arrays of robots x longest-path cells: the padding and
# its running sum). So a fleet with one long robot costs far more than its node count:
# 1,000 robots with one of 10,000 nodes take ~180 MB a sample, and 40 samples in one
# batch took the server to 7.2 GB (issue 14).
CHUNK_BYTES = 256 * 1024 * 1024
HEAD_BYTES_PER_CELL = 12  # per node or conflict and hidden unit
# Draws of the first chunk when sampling has a deadline: enough to measure the rate of a
# large graph (a 17,000-conflict path graph: ~0.05 s per draw) and size the next chunks
# to the time left, instead of one 100-draw chunk running seconds past the deadline.
FIRST_TIMED_ROWS = 8
# Cheapest draws whose types are refitted (retype.refit_types), the cheapest result kept.
# Measured (session 23, bench.generalization, avg_completion v14, the model alone,
# held-out kinds 25 / 100 / 250 robots, cost ratio; gnn_vae p50 at 250 robots): 1 draw
# 0.7491 / 0.4719 / 0.5365 (156 ms), 4 draws 0.7591 / 0.5015 / 0.5571 (141 ms), 12 draws
# 0.7622 / 0.5062 / 0.5602 (213 ms): 4 takes most of the gain for little time. Once the
# sampling's deadline has passed only the cheapest is refitted, so that the time limit
# holds: on wh_mixed/250/500030 (18,585 conflicts; the decoder's greedy fill ~14 ms a call
# there) the four refits ran 0.33 s past a 0.25-s deadline (session 45). `gnn_vae_refined`
# at 1 s on the eight 250-robot generalization worlds, three seeds, interleaved: even
# (old / new cost 1.0015 on average, 4 cheaper, 6 dearer of 24).
REFIT_TOP = 4
DECODE_BYTES_PER_CELL = 16  # per robot and position along the longest path

# Above this many conflicts every draw shares the mode's (z = 0) following-type
# probabilities, and the decoder fills the clique budgets once: per-draw type logits were
# most of a request's time there (the edge head is a (draws, M, hidden) pass: ~0.8 s of
# 1.5-2 s for 100 draws at 21,000 conflicts) and bought nothing, since the trained VAE uses
# its latent little. Measured on ten held-out worlds of 100-250 robots (wh_two_lane,
# wh_mixed, wh_two_way; avg_completion, best of 100): summed cost 11,151.2 per draw and
# 11,150.9 shared (per world -1.5 % to +0.5 %), 2-5x faster (250 robots 1.5-3.9 s ->
# 0.4-1.3 s). Small problems keep per-draw types (issue 3's figures were measured so).
SHARED_TYPES_MIN_CONFLICTS = 1_000

# Largest log-std of the multiplicative bid perturbation (see :func:`propose`);
# picked on validation problems among 0.3, 0.5 and 1.0.
BID_NOISE = 0.5


@dataclass(frozen=True)
class Sampled:
    """The cheapest decoded sample, types refitted (a batch of one), its cost, how many
    were decoded, each decoded draw's bids of the robots' first nodes (the robots'
    priorities in that draw: a robot's first node's rank is its bid), and the directions
    of the REFIT_TOP cheapest draws, cheapest first (the ones whose types were refitted)."""

    assignment: Assignments
    cost: float
    samples: int
    priorities: np.ndarray  # (samples, R) float > 0, lower: the robot passes first
    top_directions: np.ndarray  # (T, M) bool, T <= REFIT_TOP


def chunk_rows(problem: Problem, hidden: int) -> int:
    """Samples handled at once: as many as fit :data:`CHUNK_BYTES`, at least one."""
    longest = int(np.diff(problem.robot_start).max())
    per_draw = 0 if shares_types(problem.n_conflicts) else problem.n_conflicts
    heads = HEAD_BYTES_PER_CELL * hidden * (problem.node_density.size + per_draw)
    decode = DECODE_BYTES_PER_CELL * problem.n_robots * longest
    return max(1, CHUNK_BYTES // (heads + decode))


def shares_types(n_conflicts: int) -> bool:
    """Whether every draw of a graph with ``n_conflicts`` shares the mode's following-type
    probabilities (see :data:`SHARED_TYPES_MIN_CONFLICTS`)."""
    return n_conflicts > SHARED_TYPES_MIN_CONFLICTS


def propose(
    model: GnnVae, graph: GraphTensors, samples: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Bids and following probabilities of ``samples`` draws, in one batch.

    Shapes: -> bids (S, V) float64 > 0, probabilities (S, M) float64, or (1, M) shared
    by every draw (:func:`shares_types`).
    """
    return next(propose_chunks(model, graph, samples, seed, rows=samples))


@torch.inference_mode()
def propose_chunks(
    model: GnnVae,
    graph: GraphTensors,
    samples: int,
    seed: int,
    rows: int,
    first: int | None = None,
    scored: np.ndarray | None = None,
) -> Generator[tuple[np.ndarray, np.ndarray], float | None, None]:
    """Bids and following probabilities of ``samples`` draws, ``rows`` draws at a time.

    The draws form a ladder: draw k scales its latent z ~ N(0, I) and a
    log-normal bid perturbation exp(sigma_k * eps) by k / (S - 1), so draw 0
    is the decoder's mode and later draws explore further from it (sigma up to
    ``BID_NOISE``). The perturbation is ours, not the paper's: the trained VAE
    uses its latent little (KL ~0.1 nats), and on held-out validation problems
    the ladder raised the best-of-100 ratio from 0.9885 to 0.9996.
    The trunk runs once, the heads once per chunk of ``rows`` draws, only when the
    chunk is asked for; the random draws do not depend on ``rows``. The first chunk
    has ``first`` draws (default ``rows``); ``send(n)`` instead of ``next()`` asks
    for a next chunk of n draws, at most ``rows`` (a time-sized chunk).
    ``scored`` (M',) int: the only conflicts whose probability is computed (the ones the
    decoder reads, :meth:`Decoder.scored`); the others get 0. Default: all. Above
    SHARED_TYPES_MIN_CONFLICTS conflicts they are computed once, at the mode (draw 0's
    z = 0), and shared by every draw.

    Shapes: -> per chunk of n draws: bids (n, V) float64 > 0, probabilities (n, M)
    float64, or (1, M) shared by the n draws.
    """
    gen = torch.Generator().manual_seed(int(seed))
    ladder = torch.linspace(0.0, 1.0, samples)[:, None] if samples > 1 else torch.zeros(1, 1)
    z = torch.randn(samples, model.config.latent, generator=gen) * ladder  # (S, Z)
    noise = torch.randn(samples, graph.x.shape[0], generator=gen) * (BID_NOISE * ladder)  # (S, V)
    arcs = TargetArcs.of(graph.edge_index, graph.edge_attr, graph.x.shape[0])
    h = model.embed_fused(graph.x, arcs)  # (V, H)
    n_conf = graph.conf.shape[0]
    scored = np.arange(n_conf) if scored is None else scored  # (M',)
    conf = graph.conf[torch.from_numpy(scored)].T.contiguous()  # (2, M')
    shared = _probabilities(model, h, conf, z[:1], scored, n_conf) if shares_types(n_conf) else None
    lo, n = 0, rows if first is None else max(1, min(first, rows))
    while lo < samples:
        bids = model.sample_bids(h, z[lo : lo + n]) * noise[lo : lo + n].exp()  # (n, V)
        if shared is None:
            probs = _probabilities(model, h, conf, z[lo : lo + n], scored, n_conf)  # (n, M)
        else:
            probs = shared  # (1, M)
        lo += n
        asked = yield bids.double().numpy(), probs
        n = rows if asked is None else max(1, min(int(asked), rows))


def _probabilities(
    model: GnnVae,
    h: torch.Tensor,  # (V, H)
    conf: torch.Tensor,  # (2, M')
    z: torch.Tensor,  # (n, Z)
    scored: np.ndarray,  # (M',)
    n_conf: int,
) -> np.ndarray:  # (n, M) float64, 0 where not scored
    """Following-type probabilities of n latents, laid out over all M conflicts."""
    probs = np.zeros((len(z), n_conf))
    probs[:, scored] = torch.sigmoid(model.sample_logits(h, conf, z)).double().numpy()
    return probs


def sample_best(
    model: GnnVae,
    graph: GraphTensors,
    decoder: Decoder,
    evaluator: Evaluator,
    objective: Objective,
    samples: int,
    seed: int,
    *,
    deadline: float | None = None,
) -> Sampled:
    """The cheapest of ``samples`` decoded samples, in memory-bounded chunks.

    Samples pass the heads, the decoder and the evaluator :func:`chunk_rows` at a
    time, so the working memory stays near :data:`CHUNK_BYTES` whatever the sample
    count; the answer is the one a single batch would give (ties go to the lower
    row of the unchunked order: thresholded rows first, then filled ones, see
    :func:`service.core.decode.decode_candidates`). Past ``deadline``
    (``time.monotonic()``), no further chunk starts: the first always runs. With a
    deadline the first chunk is small (FIRST_TIMED_ROWS draws) and later ones are
    sized to the time left at the rate measured so far, so that a chunk of a large
    graph does not run far past the deadline.

    The REFIT_TOP cheapest samples' directions then get the types they gain most from
    where that is cheaper (:func:`~service.core.retype.refit_types`: on the
    generalization worlds of 100 and 250 robots 10-14 % cheaper on average, in 1-33 ms
    each), and the cheapest of those is the answer (ties to the cheaper draw, then the
    lower row: independent of the chunking).
    """
    rows = chunk_rows(decoder.problem, model.config.hidden)
    timed = deadline is not None
    first = FIRST_TIMED_ROWS if timed else None
    chunks = propose_chunks(model, graph, samples, seed, rows, first, decoder.scored())
    best: list[tuple[float, int, Assignments]] = []  # the REFIT_TOP cheapest so far
    priorities = []  # per chunk (n, R)
    decoded, started = 0, time.monotonic()
    bids, probs = next(chunks)
    while True:
        priorities.append(bids[:, decoder.problem.robot_start[:-1]])
        candidates = decode_candidates(decoder, bids, probs, objective)
        costs = evaluator.evaluate(candidates).costs[objective]  # (n,) or (2n,)
        for row in np.argsort(costs, kind="stable")[:REFIT_TOP].tolist():
            unchunked = _unchunked_row(row, decoded, len(bids), samples)
            best.append((float(costs[row]), unchunked, candidates.take(row)))
        best = sorted(best, key=lambda draw: draw[:2])[:REFIT_TOP]
        decoded += len(bids)
        now = time.monotonic()
        if decoded >= samples or (deadline is not None and now >= deadline):
            break
        # Time-sized next chunk: the draws that fit the time left at the rate so far.
        fit = None if deadline is None else (deadline - now) * decoded / (now - started)
        bids, probs = chunks.send(fit)
    refitted = []
    for _, _, draw in best:  # cheapest first
        if refitted and deadline is not None and time.monotonic() >= deadline:
            break  # past the deadline only the cheapest draw is refitted (see REFIT_TOP)
        refitted.append(refit_types(decoder, evaluator, objective, draw))
    found, cost = min(refitted, key=lambda pair: pair[1])  # first of equals: the cheaper draw
    top = np.concatenate([draw.a_first for _, _, draw in best])  # (T, M)
    return Sampled(found, cost, decoded, np.concatenate(priorities), top)


def _unchunked_row(row: int, lo: int, n: int, samples: int) -> int:
    """Row ``row`` of the candidates of samples lo..lo+n-1, as a row of all samples' candidates.

    Non-monotone objectives decode every sample twice (rows n.. of a chunk repeat
    its samples); in the full batch those repeats start at row ``samples``.
    """
    return lo + row if row < n else samples + lo + row - n
