"""The GNN-VAE: a GATv2 encoder of (problem, assignment) and a latent-conditioned decoder.

Differences from the published model, for CPU serving: the decoder's GATv2
trunk sees only the skeleton graph and runs *once* per request; the latent
vector enters in the two heads (bid per node, following-type logit per
conflict), whose first layer is split as A u + B z so a batch of S samples
costs one (S, N, H) add and a (S, N, H) -> (S, N) projection instead of S
message-passing passes (at 250 robots and S = 100 that is the difference
between ~10^5 and ~10^3 graph nodes through the GATv2 layers).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import torch
from torch import nn
from torch.nn import functional as F
from torch_geometric.nn import GATv2Conv, global_max_pool

from service.learning.features import EDGE_DIM, NODE_DIM
from service.learning.fused_gat import TargetArcs, fused_gatv2

__all__ = ["GnnVae", "GnnVaeConfig", "LatentHead", "chain_ranks"]

# Smallest bid: keeps ranks strictly increasing along paths.
MIN_BID = 1e-3


@dataclass(frozen=True)
class GnnVaeConfig:
    """Hyper-parameters (stored beside the weights)."""

    hidden: int = 128
    latent: int = 16
    encoder_layers: int = 3
    decoder_layers: int = 4
    heads: int = 2
    node_features: int = NODE_DIM  # leading node columns read (models before v5: 10)

    def to_dict(self) -> dict[str, int]:
        return asdict(self)


class GatStack(nn.Module):
    """Input projection of the first ``features`` node columns, then residual GATv2 layers.

    Shapes: x (V, NODE_DIM), edge_index (2, E), edge_attr (E, EDGE_DIM) -> (V, hidden).
    """

    def __init__(self, hidden: int, layers: int, heads: int, features: int = NODE_DIM) -> None:
        super().__init__()
        self.hidden, self.layers, self.heads = hidden, layers, heads
        self.features = features
        self.inp = nn.Linear(features, hidden)
        self.convs = nn.ModuleList(
            GATv2Conv(hidden, hidden, heads=heads, concat=False, edge_dim=EDGE_DIM)
            for _ in range(layers)
        )
        self.norms = nn.ModuleList(nn.LayerNorm(hidden) for _ in range(layers))
        self.reset_parameters()

    def reset_parameters(self) -> None:
        self.inp.reset_parameters()
        for conv, norm in zip(self.convs, self.norms, strict=True):
            conv.reset_parameters()
            norm.reset_parameters()

    def forward(
        self, x: torch.Tensor, edge_index: torch.Tensor, edge_attr: torch.Tensor
    ) -> torch.Tensor:
        return self._layers(x, lambda conv, h: conv(h, edge_index, edge_attr))

    def infer(self, x: torch.Tensor, arcs: TargetArcs) -> torch.Tensor:
        """:meth:`forward` in eval mode, each layer by the fused kernel
        (:func:`~service.learning.fused_gat.fused_gatv2`: 4 layers at 250 robots in ~25 ms, not
        140-680 ms).

        Shapes: x (V, NODE_DIM), arcs of the same graph -> (V, hidden).
        """
        return self._layers(x, lambda conv, h: fused_gatv2(conv, h, arcs))

    def _layers(
        self, x: torch.Tensor, message: Callable[[GATv2Conv, torch.Tensor], torch.Tensor]
    ) -> torch.Tensor:
        """Input projection, then each residual layer with ``message(conv, h)`` as its GATv2
        pass. Shapes: x (V, NODE_DIM) -> (V, hidden)."""
        h = F.relu(self.inp(x[:, : self.features]))
        for conv, norm in zip(self.convs, self.norms, strict=True):
            h = norm(h + F.relu(message(conv, h)))
        return h

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(hidden={self.hidden}, layers={self.layers}, "
            f"heads={self.heads}, features={self.features})"
        )


class LatentHead(nn.Module):
    """Scalar head on [u, z] with the first layer split as A u + B z.

    Shapes: u (N, D_in) and z (N, Z) -> (N,); or u (N, D_in) and z (S, Z) with
    ``per_sample=True`` -> (S, N).
    """

    def __init__(self, d_in: int, latent: int, hidden: int) -> None:
        super().__init__()
        self.a = nn.Linear(d_in, hidden)
        self.b = nn.Linear(latent, hidden, bias=False)
        self.out = nn.Sequential(
            nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 1)
        )

    def forward(self, u: torch.Tensor, z: torch.Tensor, per_sample: bool = False) -> torch.Tensor:
        # (S, N, H) with one latent per sample, else (N, H) with one latent per row
        pre = self.a(u)[None] + self.b(z)[:, None] if per_sample else self.a(u) + self.b(z)
        return self.out(pre).squeeze(-1)


def chain_ranks(bids: torch.Tensor, first_of_robot: torch.Tensor) -> torch.Tensor:
    """Rank r_v = b_v + bids of v's predecessors on its path.

    Nodes of a robot are contiguous and in path order. Shapes: bids (..., V),
    first_of_robot (V,) index of the first node of v's robot -> (..., V).
    """
    cs = torch.cumsum(bids.double(), dim=-1)
    base = cs.index_select(-1, first_of_robot) - bids.double().index_select(-1, first_of_robot)
    return (cs - base).to(bids.dtype)


class GnnVae(nn.Module):
    """Encoder q(z | graph, assignment) and decoder p(assignment | graph, z)."""

    def __init__(self, config: GnnVaeConfig) -> None:
        super().__init__()
        self.config = config
        h, z = config.hidden, config.latent
        self.encoder = GatStack(h, config.encoder_layers, config.heads, config.node_features)
        self.to_mu = nn.Linear(h, z)
        self.to_logstd = nn.Linear(h, z)
        self.trunk = GatStack(h, config.decoder_layers, config.heads, config.node_features)
        self.bid_head = LatentHead(h, z, h)
        self.edge_head = LatentHead(2 * h, z, h)

    def encode(
        self,
        x: torch.Tensor,
        edge_index: torch.Tensor,
        edge_attr: torch.Tensor,
        batch: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Posterior mean and log-std per graph. Shapes: -> (G, Z), (G, Z)."""
        pooled = global_max_pool(self.encoder(x, edge_index, edge_attr), batch)  # (G, H)
        return self.to_mu(pooled), self.to_logstd(pooled).clamp(-6.0, 3.0)

    def embed(
        self, x: torch.Tensor, edge_index: torch.Tensor, edge_attr: torch.Tensor
    ) -> torch.Tensor:
        """Skeleton-graph node embeddings. Shapes: -> (V, H)."""
        return self.trunk(x, edge_index, edge_attr)

    def embed_fused(self, x: torch.Tensor, arcs: TargetArcs) -> torch.Tensor:
        """:meth:`embed` for serving (eval mode, no gradient), by the fused kernel.

        Shapes: x (V, NODE_DIM) -> (V, H).
        """
        return self.trunk.infer(x, arcs)

    @staticmethod
    def pair_features(h: torch.Tensor, conf: torch.Tensor) -> torch.Tensor:
        """Order-free features of each conflict's two nodes. Shapes: conf (2, M) -> (M, 2H)."""
        ha, hb = h[conf[0]], h[conf[1]]
        return torch.cat([ha + hb, ha * hb], dim=-1)

    def sample_bids(self, h: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """Bids for S latent samples of one graph. Shapes: h (V, H), z (S, Z) -> (S, V) > 0."""
        return F.softplus(self.bid_head(h, z, per_sample=True)) + MIN_BID

    def sample_logits(self, h: torch.Tensor, conf: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """Following-type logits for S latent samples of one graph.

        Shapes: h (V, H), conf (2, M), z (S, Z) -> (S, M).
        """
        return self.edge_head(self.pair_features(h, conf), z, per_sample=True)

    def train_heads(
        self, h: torch.Tensor, conf: torch.Tensor, z_graph: torch.Tensor, batch: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Heads with one latent per graph. Shapes: z_graph (G, Z) -> bids (V,), logits (M,)."""
        bids = F.softplus(self.bid_head(h, z_graph[batch])) + MIN_BID
        conf_graph = batch[conf[0]]  # (M,)
        logits = self.edge_head(self.pair_features(h, conf), z_graph[conf_graph])
        return bids, logits
