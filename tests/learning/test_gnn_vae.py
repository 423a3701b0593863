"""GNN-VAE: store round trip, training lowers the loss, decoded samples are valid, determinism."""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from torch_geometric.data import Batch

from service.core.check import check
from service.core.cliques import find_cliques
from service.core.decode import Decoder, decode_candidates
from service.core.evaluate import Evaluator
from service.core.problem import problem_from_request
from service.core.retype import refit_types
from service.core.schemas import OBJECTIVES, ScheduleRequest
from service.datagen.build import DatasetConfig, build_dataset, solve_problem
from service.learning import infer
from service.learning.dataset import examples_from_records, to_data
from service.learning.features import NODE_DIM, graph_tensors
from service.learning.generate import GeneratorConfig, small_problem, stitched_problem
from service.learning.infer import propose, propose_chunks, sample_best
from service.learning.model import GnnVae, GnnVaeConfig
from service.learning.store import ModelLoadError, load_all, load_model, save_model
from service.learning.train import WEIGHTS, TrainConfig, loss_terms, train

TINY = GnnVaeConfig(hidden=16, latent=4, encoder_layers=1, decoder_layers=2, heads=1)
SHIPPED = Path(__file__).resolve().parents[2] / "model_store"


def _problem(request: dict):
    problem = problem_from_request(ScheduleRequest.model_validate(request))
    return problem, find_cliques(problem)


@pytest.fixture(scope="module")
def records() -> list[dict]:
    cfg = DatasetConfig(problems=12, top=3, generator=GeneratorConfig(max_robots=4))
    return [solve_problem(cfg, i) for i in range(cfg.problems)]


def test_store_round_trip_and_corruption(tmp_path: Path) -> None:
    torch.manual_seed(0)
    model = GnnVae(TINY)
    save_model(model, tmp_path, "avg_completion", "t1", {"validation": {"ratio": 0.5}})
    loaded = load_model(tmp_path, "avg_completion")
    assert loaded.version == "t1" and loaded.name == "gnn_vae/avg_completion/t1"
    for key, value in model.state_dict().items():
        assert torch.equal(value, loaded.model.state_dict()[key])
    weights = tmp_path / "avg_completion" / "t1" / "model.safetensors"
    weights.write_bytes(weights.read_bytes()[:-8] + b"corrupt!")
    with pytest.raises(ModelLoadError, match="checksum"):
        load_model(tmp_path, "avg_completion")
    models, errors = load_all(tmp_path, ("avg_completion", "max_completion"))
    assert models == {} and set(errors) == {"avg_completion", "max_completion"}


def test_config_mismatch_is_a_load_error(tmp_path: Path) -> None:
    save_model(GnnVae(TINY), tmp_path, "avg_delay", "t1", {})
    meta_path = tmp_path / "avg_delay" / "t1" / "model.json"
    meta = json.loads(meta_path.read_text())
    meta["config"]["hidden"] = 32
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(ModelLoadError):
        load_model(tmp_path, "avg_delay")


def test_training_steps_lower_the_loss(records: list[dict]) -> None:
    torch.manual_seed(0)
    examples = examples_from_records(records, "avg_completion")
    batch = Batch.from_data_list([to_data(ex, 0) for ex in examples])
    model = GnnVae(TINY)
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)

    def total() -> torch.Tensor:
        torch.manual_seed(1)  # same reparametrization noise each time
        return sum(WEIGHTS[k] * v for k, v in loss_terms(model, batch).items())

    before = total().item()
    for _ in range(40):
        opt.zero_grad()
        total().backward()
        opt.step()
    assert total().item() < 0.8 * before


@pytest.mark.parametrize("node_features", [10, NODE_DIM])
def test_a_model_reads_only_its_own_node_columns(node_features: int) -> None:
    problem, cliques = _problem(small_problem(9))
    graph = graph_tensors(problem, cliques)
    torch.manual_seed(0)
    model = GnnVae(replace(TINY, node_features=node_features)).eval()
    x = graph.x.clone()
    x[:, 10:] += 1.0  # the fleet-level columns added in v5
    h = model.embed(graph.x, graph.edge_index, graph.edge_attr)
    moved = model.embed(x, graph.edge_index, graph.edge_attr)
    assert torch.allclose(h, moved) == (node_features == 10)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), z_seed=st.integers(0, 2**31 - 1), big=st.booleans())
def test_decoded_samples_are_always_valid(seed: int, z_seed: int, big: bool) -> None:
    request = stitched_problem(seed, 30, 3.0) if big else small_problem(seed)
    problem, cliques = _problem(request)
    torch.manual_seed(seed)
    model = GnnVae(TINY).eval()
    bids, probs = propose(model, graph_tensors(problem, cliques), samples=8, seed=z_seed)
    rows = 1 if infer.shares_types(problem.n_conflicts) else 8
    assert bids.shape == (8, problem.n_nodes) and probs.shape == (rows, problem.n_conflicts)
    for objective in OBJECTIVES:
        candidates = decode_candidates(Decoder(problem, cliques), bids, probs, objective)
        assert check(problem, cliques, candidates).ok.all()


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), objective=st.sampled_from(OBJECTIVES))
def test_scoring_only_the_conflicts_the_decoder_reads_decodes_the_same(
    seed: int, objective: str
) -> None:
    """sample_best runs the edge head on Decoder.scored() only: the decoded samples are
    those of all conflicts' probabilities, and some conflicts are left out (zero budget)."""
    problem, cliques = _problem(stitched_problem(seed, 30, 4.0))
    decoder = Decoder(problem, cliques)
    scored = decoder.scored()
    torch.manual_seed(seed)
    model, graph = GnnVae(TINY).eval(), graph_tensors(problem, cliques)
    bids, probs = propose(model, graph, 8, seed=seed)
    bids_s, probs_s = next(propose_chunks(model, graph, 8, seed, rows=8, scored=scored))
    assert np.array_equal(bids, bids_s)
    assert np.allclose(probs[:, scored], probs_s[:, scored], rtol=1e-6, atol=1e-9)
    assert not probs_s[:, np.setdiff1d(np.arange(problem.n_conflicts), scored)].any()
    full = decode_candidates(decoder, bids, probs, objective)
    cut = decode_candidates(decoder, bids_s, probs_s, objective)
    assert np.array_equal(full.a_first, cut.a_first)
    assert np.array_equal(full.following, cut.following)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), objective=st.sampled_from(OBJECTIVES))
def test_large_graphs_share_the_modes_type_probabilities(seed: int, objective: str) -> None:
    """Above SHARED_TYPES_MIN_CONFLICTS the draws keep their own bids but share draw 0's
    (the mode's) following probabilities, decoded once: the same assignments as decoding
    those probabilities for every draw, all valid."""
    problem, cliques = _problem(stitched_problem(seed, 12, 3.0))
    decoder = Decoder(problem, cliques)
    torch.manual_seed(seed)
    model, graph = GnnVae(TINY).eval(), graph_tensors(problem, cliques)
    bids, probs = propose(model, graph, 8, seed=seed)  # (8, V), (8, M): below the threshold
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(infer, "SHARED_TYPES_MIN_CONFLICTS", 0)
        shared_bids, shared = propose(model, graph, 8, seed=seed)  # (8, V), (1, M)
        best = sample_best(model, graph, decoder, Evaluator(problem), objective, 8, seed)
    assert shared.shape == (1, problem.n_conflicts)
    assert np.array_equal(bids, shared_bids)
    assert np.allclose(probs[:1], shared, rtol=1e-6, atol=1e-9)
    once = decode_candidates(decoder, bids, shared, objective)
    each = decode_candidates(decoder, bids, np.repeat(shared, 8, axis=0), objective)
    assert np.array_equal(once.a_first, each.a_first)
    assert np.array_equal(once.following, each.following)
    assert (
        check(problem, cliques, once).ok.all() and check(problem, cliques, best.assignment).ok.all()
    )


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), objective=st.sampled_from(OBJECTIVES))
def test_the_best_sample_gets_the_types_its_directions_gain_most_from(
    seed: int, objective: str
) -> None:
    """sample_best answers the cheapest of the REFIT_TOP cheapest decoded draws with their
    types refitted (refit_types; ties to the cheaper draw, then the lower row), valid,
    its cost the evaluator's, and the same in chunks of 3 draws as in one batch; it names
    those draws' directions, cheapest first."""
    problem, cliques = _problem(stitched_problem(seed, 30, 4.0))
    decoder, evaluator = Decoder(problem, cliques), Evaluator(problem)
    torch.manual_seed(seed)
    model, graph = GnnVae(TINY).eval(), graph_tensors(problem, cliques)
    bids, probs = propose(model, graph, 8, seed=seed)
    candidates = decode_candidates(decoder, bids, probs, objective)
    costs = evaluator.evaluate(candidates).costs[objective]
    top = np.lexsort((np.arange(costs.size), costs))[: infer.REFIT_TOP]  # by cost, then row
    refits = [refit_types(decoder, evaluator, objective, candidates.take(int(r))) for r in top]
    expect, expect_cost = min(refits, key=lambda pair: pair[1])
    best = sample_best(model, graph, decoder, evaluator, objective, 8, seed)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(infer, "chunk_rows", lambda *args: 3)
        chunked = sample_best(model, graph, decoder, evaluator, objective, 8, seed)
    for found in (best, chunked):
        assert np.array_equal(found.assignment.a_first, expect.a_first)
        assert np.array_equal(found.assignment.following, expect.following)
        assert found.cost == pytest.approx(expect_cost, rel=1e-12)
        assert np.array_equal(found.top_directions, candidates.a_first[top])
    assert best.cost <= refits[0][1] + 1e-9 and refits[0][1] <= costs.min() * (1 + 1e-12) + 1e-9
    assert check(problem, cliques, best.assignment).ok.all()


@pytest.mark.parametrize(("deadline_s", "refits"), [(60.0, infer.REFIT_TOP), (-1.0, 1)])
def test_past_the_deadline_only_the_cheapest_draw_is_refitted(
    deadline_s: float, refits: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """With time left every one of the REFIT_TOP cheapest draws is refitted; once the
    deadline has passed (here before the first chunk ends) only the cheapest, so that the
    time limit holds on graphs where a refit takes long."""
    problem, cliques = _problem(stitched_problem(7, 30, 4.0))
    decoder, evaluator = Decoder(problem, cliques), Evaluator(problem)
    torch.manual_seed(7)
    model, graph = GnnVae(TINY).eval(), graph_tensors(problem, cliques)
    refitted: list[float] = []  # the cost of each draw refitted

    def counted(*args: object) -> tuple:
        refitted.append(evaluator.evaluate(args[3]).costs["avg_completion"][0])
        return refit_types(*args)

    monkeypatch.setattr(infer, "refit_types", counted)
    deadline = time.monotonic() + deadline_s
    best = sample_best(model, graph, decoder, evaluator, "avg_completion", 8, 7, deadline=deadline)
    assert len(refitted) == refits and refitted[0] == min(refitted)
    assert check(problem, cliques, best.assignment).ok.all()


def test_gain_types_improve_a_tiny_models_best_draw_somewhere() -> None:
    """The retyping is not idle: on some congested graph it beats every decoded draw."""
    found = []
    for seed in range(6):
        problem, cliques = _problem(stitched_problem(seed, 30, 4.0))
        decoder, evaluator = Decoder(problem, cliques), Evaluator(problem)
        torch.manual_seed(seed)
        model, graph = GnnVae(TINY).eval(), graph_tensors(problem, cliques)
        bids, probs = propose(model, graph, 8, seed=seed)
        candidates = decode_candidates(decoder, bids, probs, "avg_completion")
        drawn = float(evaluator.evaluate(candidates).costs["avg_completion"].min())
        best = sample_best(model, graph, decoder, evaluator, "avg_completion", 8, seed)
        found.append(best.cost < drawn - 1e-9)
    assert any(found)


def test_some_conflicts_go_unscored_on_a_dense_graph() -> None:
    problem, cliques = _problem(stitched_problem(3, 30, 4.0))
    assert 0 < Decoder(problem, cliques).scored().size < problem.n_conflicts


def test_inference_is_deterministic_for_a_seed() -> None:
    problem, cliques = _problem(small_problem(7))
    model = GnnVae(TINY).eval()
    graph = graph_tensors(problem, cliques)
    first = propose(model, graph, 16, seed=3)
    again = propose(model, graph, 16, seed=3)
    other = propose(model, graph, 16, seed=4)
    assert np.array_equal(first[0], again[0]) and np.array_equal(first[1], again[1])
    assert not np.array_equal(first[0], other[0])


def test_features_do_not_depend_on_time_scale() -> None:
    a, ca = _problem(small_problem(11))
    b, cb = _problem(small_problem(11, cfg=GeneratorConfig(time_scale=3600.0)))
    ga, gb = graph_tensors(a, ca), graph_tensors(b, cb)
    assert torch.allclose(ga.x, gb.x, atol=1e-5)
    assert torch.allclose(ga.edge_attr, gb.edge_attr, atol=1e-5)


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_shipped_models_load_and_answer(objective: str) -> None:
    manifest = json.loads((SHIPPED / "manifest.json").read_text())
    assert objective in manifest["default"]
    stored = load_model(SHIPPED, objective)
    problem, cliques = _problem(small_problem(5))
    best = sample_best(
        stored.model,
        graph_tensors(problem, cliques),
        Decoder(problem, cliques),
        Evaluator(problem),
        objective,
        samples=10,
        seed=0,
    )
    assignment, cost = best.assignment, best.cost
    assert check(problem, cliques, assignment).ok.all()
    assert np.isfinite(cost)


def test_training_resumes_and_refuses_a_checkpoint_of_other_flags(tmp_path: Path) -> None:
    cfg = DatasetConfig(problems=8, top=2, shard_size=4, generator=GeneratorConfig(max_robots=3))
    build_dataset(cfg, tmp_path / "data", workers=1)
    run_dir = tmp_path / "run"

    def run(epochs: int, model_cfg: GnnVaeConfig = TINY) -> dict:
        train_cfg = TrainConfig(epochs=epochs, batch_size=4, val_samples=2)
        return train([tmp_path / "data"], "avg_completion", run_dir, model_cfg, train_cfg, None, 2)

    assert run(1)["state"]["epoch"] == 1
    with pytest.raises(SystemExit, match="another setup"):
        run(1, replace(TINY, hidden=8))
    assert run(2)["state"]["epoch"] == 2  # more epochs: resumed, not restarted


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_every_default_model_has_a_card(objective: str) -> None:
    """Issue 13: each shipped default says what it was trained on, what it measured and
    where it falls short, in its own metadata (``model.json``, key ``card``)."""
    manifest = json.loads((SHIPPED / "manifest.json").read_text())
    version = manifest["default"][objective]
    card = json.loads((SHIPPED / objective / version / "model.json").read_text()).get("card")
    assert card is not None, f"{objective} {version} has no card"
    assert {"status", "data", "figures", "limits"} <= set(card)
    assert all(card[k] for k in ("status", "data", "figures", "limits"))
