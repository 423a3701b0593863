"""GNN-VAE inference: S latent samples -> S decoded, valid assignments -> the cheapest.

Used by the ``gnn_vae`` solver and by validation during training, so both see
exactly the same decoding. The trunk runs once; the S samples only pass
through the heads. Deterministic for a seed (a private torch.Generator).
"""

from __future__ import annotations

import numpy as np
import torch

from service.core.assignment import Assignments
from service.core.decode import Decoder, decode_candidates
from service.core.evaluate import Evaluator
from service.core.schemas import Objective
from service.learning.features import GraphTensors
from service.learning.model import GnnVae

__all__ = ["BID_NOISE", "best_of", "propose"]

# Largest log-std of the multiplicative bid perturbation (see :func:`propose`);
# picked on validation problems among 0.3, 0.5 and 1.0.
BID_NOISE = 0.5


@torch.inference_mode()
def propose(
    model: GnnVae, graph: GraphTensors, samples: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Bids and following probabilities of ``samples`` draws.

    The draws form a ladder: draw k scales its latent z ~ N(0, I) and a
    log-normal bid perturbation exp(sigma_k * eps) by k / (S - 1), so draw 0
    is the decoder's mode and later draws explore further from it (sigma up to
    ``BID_NOISE``). The perturbation is ours, not the paper's: the trained VAE
    uses its latent little (KL ~0.1 nats), and on held-out validation problems
    the ladder raised the best-of-100 ratio from 0.9885 to 0.9996.

    Shapes: -> bids (S, V) float64 > 0, probabilities (S, M) float64.
    """
    gen = torch.Generator().manual_seed(int(seed))
    ladder = torch.linspace(0.0, 1.0, samples)[:, None] if samples > 1 else torch.zeros(1, 1)
    z = torch.randn(samples, model.config.latent, generator=gen) * ladder  # (S, Z)
    h = model.embed(graph.x, graph.edge_index, graph.edge_attr)  # (V, H)
    bids, logits = model.sample_heads(h, graph.conf.T.contiguous(), z)  # (S, V), (S, M)
    noise = torch.randn(bids.shape, generator=gen) * (BID_NOISE * ladder)  # (S, V)
    return (bids * noise.exp()).double().numpy(), torch.sigmoid(logits).double().numpy()


def best_of(
    model: GnnVae,
    graph: GraphTensors,
    decoder: Decoder,
    evaluator: Evaluator,
    objective: Objective,
    samples: int,
    seed: int,
) -> tuple[Assignments, float]:
    """The cheapest decoded sample (a batch of one) and its cost."""
    bids, probs = propose(model, graph, samples, seed)
    candidates = decode_candidates(decoder, bids, probs, objective)
    costs = evaluator.evaluate(candidates).costs[objective]  # (S,) or (2S,)
    best = int(np.argmin(costs))
    return candidates.take(best), float(costs[best])
