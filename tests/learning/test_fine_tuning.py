"""Fine-tuning (``--init``) and the target filter (``--max-gap``, ``--proven-only``)."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import pytest
import torch

from service.datagen.build import DatasetConfig, build_dataset
from service.learning.data import iter_problems
from service.learning.dataset import KEEP_ALL, TargetFilter, examples_from_records, target_gap
from service.learning.generate import GeneratorConfig
from service.learning.model import GnnVae, GnnVaeConfig
from service.learning.store import StoredModel, load_model_dir, save_model
from service.learning.train import (
    PARTS,
    TrainConfig,
    filter_record,
    initial_model,
    main,
    per_dataset,
    train,
    trainable,
)

TINY = GnnVaeConfig(hidden=16, latent=4, encoder_layers=1, decoder_layers=2, heads=1)
OBJECTIVE = "avg_completion"


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> Path:
    cfg = DatasetConfig(problems=8, top=2, shard_size=4, generator=GeneratorConfig(max_robots=3))
    path = tmp_path_factory.mktemp("data")
    build_dataset(cfg, path, workers=1)
    return path


def _source(store: Path, version: str, seed: int) -> StoredModel:
    """A randomly initialized tiny model, stored and loaded back as --init loads it."""
    torch.manual_seed(seed)
    save_model(GnnVae(TINY), store, OBJECTIVE, version, {}, make_default=False)
    return load_model_dir(store / OBJECTIVE / version)


def _forward(model: GnnVae, data: Path) -> tuple[torch.Tensor, ...]:
    """A first forward pass: node embeddings (V, H), then bids (1, V) and logits (1, M) for
    a fixed latent (1, Z)."""
    graph = examples_from_records(iter_problems(data, 1), OBJECTIVE)[0].graph
    with torch.no_grad():
        h = model.embed(graph.x, graph.edge_index, graph.edge_attr)
        z = torch.ones(1, TINY.latent)
        bids, logits = model.sample_bids(h, z), model.sample_logits(h, graph.conf.T, z)
    return h, bids, logits


def _train(
    data: Path, run_dir: Path, init: StoredModel | None, frozen: tuple[str, ...] = (), **train_cfg
) -> dict:
    cfg = TrainConfig(**{"epochs": 1, "batch_size": 4, "val_samples": 2, **train_cfg})
    return train([data], OBJECTIVE, run_dir, TINY, cfg, None, 2, init=init, frozen=frozen)


def test_init_starts_from_the_source_weights_exactly(tmp_path: Path, data: Path) -> None:
    source = _source(tmp_path / "store", "src", seed=1)
    expected = _forward(source.model, data)
    for got, want in zip(_forward(initial_model(TINY, source), data), expected, strict=True):
        assert torch.equal(got, want)
    assert not torch.equal(_forward(initial_model(TINY, None), data)[0], expected[0])
    # Through training with a zero learning rate the weights stay the source's, bit for bit.
    trained = _train(data, tmp_path / "run", source, lr=0.0)["model"]
    for got, want in zip(_forward(trained, data), expected, strict=True):
        assert torch.equal(got, want)


def test_resume_refuses_a_checkpoint_of_another_init(tmp_path: Path, data: Path) -> None:
    first = _source(tmp_path / "store", "a", seed=1)
    other = _source(tmp_path / "store", "b", seed=2)
    run_dir = tmp_path / "run"
    assert _train(data, run_dir, first)["state"]["epoch"] == 1
    for init in (other, None):
        with pytest.raises(SystemExit, match="another setup"):
            _train(data, run_dir, init, epochs=2)
    assert _train(data, run_dir, first, epochs=2)["state"]["epoch"] == 2  # resumed


def test_the_filter_keeps_targets_by_their_recorded_gap(data: Path) -> None:
    (record,) = iter_problems(data, 1)
    base = record["targets"][OBJECTIVE][0]
    targets = [
        {**base, "cost": 1.0, "optimal": True},  # proven (old and new datasets)
        {**base, "cost": 2.0, "optimal": False, "gap": 0.02},
        {**base, "cost": 3.0, "optimal": False, "gap": 0.2},
        {**base, "cost": 4.0, "optimal": False, "gap": None},  # CP-SAT found nothing
        {**base, "cost": 5.0, "optimal": False},  # an old dataset's unproven target
    ]
    assert [target_gap(t) for t in targets] == [0.0, 0.02, 0.2, None, None]

    def kept(keep: TargetFilter) -> list[float]:
        return [t["cost"] for t in targets if keep.keeps(t)]

    assert kept(KEEP_ALL) == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert kept(TargetFilter(max_gap=0.05)) == [1.0, 2.0, 4.0, 5.0]
    assert kept(TargetFilter(proven_only=True)) == [1.0, 2.0, 3.0]
    assert kept(TargetFilter(max_gap=0.0, proven_only=True)) == [1.0]

    rec = {**record, "targets": {OBJECTIVE: targets[1:]}}
    (example,) = examples_from_records([rec], OBJECTIVE, keep=TargetFilter(max_gap=0.05))
    assert len(example.targets) == 3 and example.opt_cost == 2.0
    dropped = {**record, "targets": {OBJECTIVE: targets[2:3]}}
    assert examples_from_records([dropped], OBJECTIVE, keep=TargetFilter(max_gap=0.05)) == []


def test_cli_fine_tunes_into_a_new_version(tmp_path: Path, data: Path) -> None:
    source = _source(tmp_path / "store", "src", seed=1)
    src_dir = tmp_path / "store" / OBJECTIVE / "src"
    flags = ["--data", str(data), "--objective", OBJECTIVE, "--runs", str(tmp_path / "runs"),
             "--init", str(src_dir), "--epochs", "1", "--batch-size", "4", "--val", "2",
             "--val-samples", "2"]  # fmt: skip
    out = tmp_path / "candidates"
    main([*flags, "--store", str(out), "--version", "ft", "--max-gap", "0.1"])
    tuned = load_model_dir(out / OBJECTIVE / "ft")
    assert tuned.model.config == TINY
    meta = json.loads((out / OBJECTIVE / "ft" / "model.json").read_text())
    assert meta["init"] == {"name": source.name, "sha256": source.metadata["sha256"]}
    assert meta["training"]["target_filter"] == {"max_gap": 0.1, "proven_only": False}
    with pytest.raises(SystemExit):  # the model flags must match --init's config
        main([*flags, "--store", str(out), "--version", "ft2", "--hidden", "8"])
    with pytest.raises(SystemExit):  # never over the model it starts from
        main([*flags, "--store", str(tmp_path / "store"), "--version", "src"])


def test_each_dataset_gets_its_own_filter(
    tmp_path: Path, data: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[TargetFilter] = []

    def spy(records, objective, max_targets=None, keep=KEEP_ALL):  # noqa: ANN001, ANN202
        seen.append(keep)
        return examples_from_records(records, objective, max_targets, keep)

    monkeypatch.setattr("service.learning.train.examples_from_records", spy)
    strict, loose = TargetFilter(max_gap=0.05), TargetFilter()
    cfg = TrainConfig(epochs=1, batch_size=4, val_samples=2)
    state = train(
        [data, data], OBJECTIVE, tmp_path / "run", TINY, cfg, None, 2, keep=[strict, loose]
    )
    assert seen == [strict, KEEP_ALL, loose, KEEP_ALL]  # train then validation, per dataset
    assert state["state"]["setup"]["target_filter"] == [asdict(strict), asdict(loose)]
    with pytest.raises(ValueError, match="3 target filters for 2 datasets"):
        per_dataset([strict] * 3, 2)
    assert filter_record([strict, strict]) == asdict(strict)  # as before per-dataset filters


def test_cli_takes_one_gap_per_dataset(tmp_path: Path, data: Path) -> None:
    flags = ["--data", str(data), str(data), "--objective", OBJECTIVE, "--runs",
             str(tmp_path / "runs"), "--store", str(tmp_path / "store"), "--epochs", "1",
             "--batch-size", "4", "--val", "2", "--val-samples", "2", "--hidden", "8",
             "--latent", "2", "--encoder-layers", "1", "--decoder-layers", "1",
             "--heads", "1"]  # fmt: skip
    main([*flags, "--version", "a", "--max-gap", "0.1", "none"])
    meta = json.loads((tmp_path / "store" / OBJECTIVE / "a" / "model.json").read_text())
    assert meta["training"]["target_filter"] == [
        {"max_gap": 0.1, "proven_only": False},
        {"max_gap": None, "proven_only": False},
    ]
    for bad in (["0.1", "0.2", "0.3"], ["-1"], ["x"]):
        with pytest.raises(SystemExit):
            main([*flags, "--version", "b", "--max-gap", *bad])


def test_frozen_parts_keep_the_source_weights_and_the_rest_learn(
    tmp_path: Path, data: Path
) -> None:
    source = _source(tmp_path / "store", "src", seed=1)
    before = {k: v.clone() for k, v in source.model.state_dict().items()}
    frozen = ("encoder", "trunk")
    result = _train(data, tmp_path / "run", source, frozen, lr=0.01)
    after = result["model"].state_dict()
    for name, weight in after.items():
        if name.split(".")[0] in frozen:
            assert torch.equal(weight, before[name]), name
    assert any(not torch.equal(w, before[k]) for k, w in after.items() if k.startswith("bid_head"))
    assert result["state"]["setup"]["frozen"] == ["encoder", "trunk"]
    with pytest.raises(SystemExit, match="another setup"):  # a resume must freeze the same
        _train(data, tmp_path / "run", source, ("trunk",), epochs=2)


def test_trainable_refuses_unknown_parts_and_lists_the_rest() -> None:
    model = GnnVae(TINY)
    assert len(trainable(model, ())) == len(list(model.parameters()))
    kept = trainable(model, PARTS[:-1])  # every part but the edge head frozen
    assert {id(p) for p in kept} == {id(p) for p in model.edge_head.parameters()}
    for bad in ("decoder", "trunk.convs.99", "trunk.inp.weight", "convs.0", ""):
        with pytest.raises(ValueError, match="unknown model parts"):
            trainable(GnnVae(TINY), (bad,))


def test_a_module_inside_a_part_freezes_alone() -> None:
    model = GnnVae(TINY)
    last = TINY.decoder_layers - 1
    names = ["trunk.inp", *(f"trunk.{k}.{i}" for k in ("convs", "norms") for i in range(last))]
    kept = {id(p) for p in trainable(model, names)}
    frozen = {id(p) for name in names for p in model.get_submodule(name).parameters()}
    everything = {id(p) for p in model.parameters()}
    assert kept == everything - frozen
    assert {id(p) for p in model.trunk.convs[last].parameters()} <= kept


def test_cli_freezes_only_with_an_init(tmp_path: Path, data: Path) -> None:
    _source(tmp_path / "store", "src", seed=1)
    flags = ["--data", str(data), "--objective", OBJECTIVE, "--runs", str(tmp_path / "runs"),
             "--epochs", "1", "--batch-size", "4", "--val", "2", "--val-samples", "2",
             "--store", str(tmp_path / "out")]  # fmt: skip
    init = ["--init", str(tmp_path / "store" / OBJECTIVE / "src")]
    main([*flags, *init, "--version", "ft", "--freeze", "trunk", "encoder"])
    meta = json.loads((tmp_path / "out" / OBJECTIVE / "ft" / "model.json").read_text())
    assert meta["training"]["frozen"] == ["encoder", "trunk"]
    with pytest.raises(SystemExit):  # nothing to keep without --init
        main([*flags, "--version", "b", "--freeze", "trunk"])
    for bad in ("decoder", "trunk.convs.99"):
        with pytest.raises(SystemExit):
            main([*flags, *init, "--version", "c", "--freeze", bad])
