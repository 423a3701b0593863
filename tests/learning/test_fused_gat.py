"""The fused GATv2 kernel serving uses equals PyG's layers (to float rounding)."""

from __future__ import annotations

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch_geometric.nn import GATv2Conv

from service.core.cliques import find_cliques
from service.core.problem import problem_from_request
from service.core.schemas import ScheduleRequest
from service.learning.features import EDGE_DIM, graph_tensors
from service.learning.fused_gat import TargetArcs, fused_gatv2
from service.learning.generate import small_problem, stitched_problem
from service.learning.model import GnnVae, GnnVaeConfig


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    big=st.booleans(),
    heads=st.integers(1, 3),
    hidden=st.sampled_from([8, 16, 64]),
)
def test_fused_embeddings_equal_pyg_on_problem_graphs(
    seed: int, big: bool, heads: int, hidden: int
) -> None:
    request = stitched_problem(seed, 30, 3.0) if big else small_problem(seed)
    problem = problem_from_request(ScheduleRequest.model_validate(request))
    graph = graph_tensors(problem, find_cliques(problem))
    torch.manual_seed(seed)
    config = GnnVaeConfig(hidden=hidden, latent=4, encoder_layers=1, decoder_layers=3, heads=heads)
    model = GnnVae(config).eval()
    with torch.inference_mode():
        expected = model.embed(graph.x, graph.edge_index, graph.edge_attr)  # (V, H)
        arcs = TargetArcs.of(graph.edge_index, graph.edge_attr, graph.x.shape[0])
        fused = model.embed_fused(graph.x, arcs)
    assert fused.shape == expected.shape
    assert torch.allclose(fused, expected, rtol=1e-4, atol=1e-4)


def test_given_self_loops_isolated_nodes_and_negative_scores_match_pyg() -> None:
    torch.manual_seed(1)
    conv = GATv2Conv(6, 5, heads=2, concat=False, edge_dim=EDGE_DIM).eval()
    # Node 3 has no incoming arc; node 1 has a given self loop (PyG replaces it).
    edge_index = torch.tensor([[0, 1, 2, 1, 0, 3], [1, 0, 1, 1, 2, 2]])
    edge_attr = torch.randn(6, EDGE_DIM) * 3.0
    h = torch.randn(4, 6) * 3.0
    with torch.inference_mode():
        expected = conv(h, edge_index, edge_attr)
        fused = fused_gatv2(conv, h, TargetArcs.of(edge_index, edge_attr, 4))
    assert torch.allclose(fused, expected, rtol=1e-5, atol=1e-5)


def test_training_mode_and_other_configurations_are_refused() -> None:
    arcs = TargetArcs.of(torch.tensor([[0], [1]]), torch.zeros(1, EDGE_DIM), 2)
    h = torch.zeros(2, 4)
    with pytest.raises(ValueError, match="eval mode"):
        fused_gatv2(GATv2Conv(4, 4, edge_dim=EDGE_DIM, concat=False).train(), h, arcs)
    with pytest.raises(ValueError, match="eval mode"):
        fused_gatv2(GATv2Conv(4, 4, edge_dim=EDGE_DIM, concat=True).eval(), h, arcs)
    with pytest.raises(ValueError, match="mean"):
        fused_gatv2(GATv2Conv(4, 4, concat=False).eval(), h, arcs)
