"""Training CLI for one objective's GNN-VAE, resumable, with per-epoch validation.

``python -m service.learning.train --data data/small-v1 --objective avg_completion``
(``--data`` takes several datasets, e.g. ``data/small-v1 data/medium-v1``.)

Losses (published weights 1, 1, 0.01): hinge on chain ranks
sum_c max(r_first - r_second + gamma, 0) with gamma = 0.1 (averaged over the
batch's conflicts), binary cross-entropy on the following-type label, and the
KL divergence of q(z | graph, assignment) to N(0, I). Every epoch the held-out
problems (the dataset's last ``--val`` problems) are solved by the same
inference code the service uses, and the mean optimality ratio
(opt / cost; for avg_delay, whose optimum is often 0, the mean gap) is logged.
The best epoch by mean normalized gap (cost - opt) / time span is kept; training
stops early after ``--patience`` epochs without improvement. A checkpoint
(state dicts only, loaded with ``weights_only=True``) is written every epoch
and picked up again by the same command (a checkpoint left by other flags is refused, not mixed in).

Fine-tuning: ``--init model_store/avg_completion/v4`` starts from that model's config
and weights (loaded as the service loads models: safetensors, checksum checked) instead
of random ones; the model flags may then be left out (given, they must match);
``--freeze trunk encoder`` keeps those parts' weights as they were and trains the rest
(:data:`PARTS`, or a module inside one by its dotted name, e.g. ``trunk.convs.0``: the
trunk's first GATv2 layer). ``--max-gap G`` trains only on targets whose recorded
relative gap to CP-SAT's bound is at most G (proven optima have 0), ``--proven-only``
also drops targets of unknown gap (:class:`service.learning.dataset.TargetFilter`);
validation problems keep every target. ``--max-gap`` takes one gap for every dataset or
one per ``--data`` folder, ``none`` for any gap: a CP-SAT gap means little where its
bound is weak (50-100 robots), so labels of a longer solve may be kept whatever their
gap while 1-s labels are filtered, e.g. ``--data data/scenario-v1 data/scenario-large-v1
--max-gap 0.05 none``. The result is saved as ``--version`` and, as every trained model,
becomes the store's default: train candidates into their own ``--store`` and compare
them with ``python -m bench.generalization --candidate``.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.nn import functional as F
from torch_geometric.data import Batch
from tqdm import tqdm

from service.core.schemas import OBJECTIVES
from service.learning.data import iter_problems, load_manifest
from service.learning.dataset import (
    KEEP_ALL,
    Example,
    TargetFilter,
    examples_from_records,
    to_data,
)
from service.learning.infer import sample_best
from service.learning.model import GnnVae, GnnVaeConfig, chain_ranks
from service.learning.store import ModelLoadError, StoredModel, load_model_dir, save_model

__all__ = ["TrainConfig", "loss_terms", "train", "validate"]

GAMMA = 0.1  # hinge margin on ranks (published)
WEIGHTS = {"hinge": 1.0, "bce": 1.0, "kl": 0.01}  # published loss weights
# The GnnVae's parts, by attribute, that --freeze can hold fixed while fine-tuning (or a
# module inside one, by its dotted name: ``trunk.convs.3``, ``trunk.norms.3``, ``trunk.inp``).
PARTS = ("encoder", "to_mu", "to_logstd", "trunk", "bid_head", "edge_head")
PART_HINT = f"parts are {', '.join(PARTS)}, or a module inside one by dotted name (trunk.convs.0)"


@dataclass(frozen=True)
class TrainConfig:
    """Optimization settings (the published ones where given)."""

    epochs: int = 40
    batch_size: int = 128
    lr: float = 3e-4
    patience: int = 6
    val_samples: int = 20
    seed: int = 0
    targets: int = 10  # best exact assignments per problem trained on (the data has up to --top)


def loss_terms(model: GnnVae, batch: Batch) -> dict[str, torch.Tensor]:
    """The three loss terms on a batch of graphs, each with one target assignment."""
    h = model.embed(batch.x, batch.edge_index, batch.edge_attr)  # (V, H)
    mu, logstd = model.encode(batch.x, batch.edge_index, batch.enc_attr, batch.batch)  # (G, Z)
    z = mu + torch.randn_like(mu) * logstd.exp()
    bids, logits = model.train_heads(h, batch.conf_index, z, batch.batch)  # (V,), (M,)
    ranks = chain_ranks(bids, batch.first_index)
    ra, rb = ranks[batch.conf_index[0]], ranks[batch.conf_index[1]]
    first_minus_second = torch.where(batch.y_a_first > 0.5, ra - rb, rb - ra)
    kl = -0.5 * (1 + 2 * logstd - mu.pow(2) - (2 * logstd).exp()).sum(dim=1)
    return {
        "hinge": F.relu(first_minus_second + GAMMA).mean(),
        "bce": F.binary_cross_entropy_with_logits(logits, batch.y_following),
        "kl": kl.mean(),
    }


def validate(
    model: GnnVae, examples: list[Example], objective: str, samples: int
) -> dict[str, float]:
    """Mean optimality ratio and normalized gap of the service's inference on ``examples``."""
    model.eval()
    ratios, gaps = [], []
    for i, ex in enumerate(examples):
        best = sample_best(model, ex.graph, ex.decoder, ex.evaluator, objective, samples, seed=i)
        cost = best.cost
        span = float(np.ptp(ex.problem.tp_time)) or 1.0
        gaps.append((cost - ex.opt_cost) / span)
        ratios.append(ex.opt_cost / cost if cost > 0 else 1.0)
    return {
        "ratio": float(np.mean(ratios)),
        "gap": float(np.mean(gaps)),
        "exact_share": float(np.mean(np.asarray(gaps) <= 1e-9)),
    }


def _epoch(
    model: GnnVae,
    opt: torch.optim.Optimizer,
    examples: list[Example],
    cfg: TrainConfig,
    rng: np.random.Generator,
    desc: str,
) -> dict[str, float]:
    """One pass over the training problems, one random target each."""
    model.train()
    order = rng.permutation(len(examples))
    sums = dict.fromkeys(WEIGHTS, 0.0)
    steps = range(0, len(order), cfg.batch_size)
    for start in tqdm(steps, desc=desc, unit="batch", leave=False):
        chunk = order[start : start + cfg.batch_size]
        batch = Batch.from_data_list(
            [to_data(examples[i], int(rng.integers(len(examples[i].targets)))) for i in chunk]
        )
        terms = loss_terms(model, batch)
        loss = sum(WEIGHTS[k] * v for k, v in terms.items())
        opt.zero_grad()
        loss.backward()
        opt.step()
        for k, v in terms.items():
            sums[k] += v.item() / len(steps)
    return sums


def init_record(init: StoredModel) -> dict[str, str]:
    """How a run names the model it started from: its name and its weights' SHA-256."""
    return {"name": init.name, "sha256": init.metadata["sha256"]}


def initial_model(model_cfg: GnnVaeConfig, init: StoredModel | None) -> GnnVae:
    """A model of ``model_cfg``: randomly initialized, or ``init``'s weights (fine-tuning).

    Raises:
        SystemExit: ``init``'s config is not ``model_cfg``.
    """
    model = GnnVae(model_cfg)
    if init is not None:
        if init.model.config != model_cfg:
            raise SystemExit(f"--init {init.name} has config {init.model.config}, not {model_cfg}")
        model.load_state_dict(init.model.state_dict(), strict=True)
    return model


def train(
    data: list[Path],
    objective: str,
    run_dir: Path,
    model_cfg: GnnVaeConfig,
    cfg: TrainConfig,
    n_train: int | None,
    n_val: int,
    init: StoredModel | None = None,
    keep: TargetFilter | Sequence[TargetFilter] = KEEP_ALL,
    frozen: Sequence[str] = (),
) -> dict[str, Any]:
    """Train (or resume) and return the best epoch's validation figures and state.

    ``init``: the model to start from (None: random weights); ``keep``: which targets of
    the training problems to train on, one filter for every dataset or one per dataset
    (validation problems keep all of theirs); ``frozen``: the model's parts
    (:data:`PARTS`) whose weights stay as ``init`` left them.
    """
    keeps = per_dataset(keep, len(data))
    torch.manual_seed(cfg.seed)
    train_ex, val_ex = [], []
    for path, kept in zip(data, keeps, strict=True):  # the last n_val of each are held out
        records = list(iter_problems(path, None if n_train is None else n_train + n_val))
        train_ex += examples_from_records(records[:-n_val], objective, cfg.targets, kept)
        val_ex += examples_from_records(records[-n_val:], objective)
    model = initial_model(model_cfg, init)
    opt = torch.optim.Adam(trainable(model, frozen), lr=cfg.lr)
    run_dir.mkdir(parents=True, exist_ok=True)
    ckpt_path = run_dir / "checkpoint.pt"
    # What a checkpoint must share with the command resuming it (the stopping rules may change).
    learning = {k: v for k, v in asdict(cfg).items() if k not in ("epochs", "patience")}
    setup = {"model": asdict(model_cfg), "train": learning, "data": [str(d) for d in data]}
    # Named only when used, so that checkpoints from before these options still resume.
    if init is not None:
        setup["init"] = init_record(init)
    if any(k != KEEP_ALL for k in keeps):
        setup["target_filter"] = filter_record(keeps)
    if frozen:
        setup["frozen"] = sorted(frozen)
    state: dict[str, Any] = {
        "setup": setup,
        "epoch": 0,
        "best_gap": float("inf"),
        "best_epoch": -1,
        "since_best": 0,
        "history": [],
    }
    if ckpt_path.exists():
        saved = json.loads((run_dir / "state.json").read_text()).get("setup")
        if saved != setup:
            raise SystemExit(
                f"{run_dir} holds a run with another setup ({saved}); resume it with the same "
                "flags, or train under a new --version"
            )
        ckpt = torch.load(ckpt_path, weights_only=True)
        model.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
        state = json.loads((run_dir / "state.json").read_text())
    rng = np.random.default_rng([cfg.seed, state["epoch"]])
    while state["epoch"] < cfg.epochs and state["since_best"] < cfg.patience:
        t0 = time.perf_counter()
        losses = _epoch(model, opt, train_ex, cfg, rng, f"{objective} epoch {state['epoch'] + 1}")
        val = validate(model, val_ex, objective, cfg.val_samples)
        state["epoch"] += 1
        state["history"].append(
            {"epoch": state["epoch"], **losses, **val, "seconds": time.perf_counter() - t0}
        )
        tqdm.write(json.dumps(state["history"][-1]))
        if val["gap"] < state["best_gap"]:
            state.update(best_gap=val["gap"], best_epoch=state["epoch"], since_best=0, best_val=val)
            torch.save(model.state_dict(), run_dir / "best.pt")
        else:
            state["since_best"] += 1
        torch.save({"model": model.state_dict(), "optimizer": opt.state_dict()}, ckpt_path)
        (run_dir / "state.json").write_text(json.dumps(state, indent=1))
    model.load_state_dict(torch.load(run_dir / "best.pt", weights_only=True))
    state["n_train"], state["n_val"] = len(train_ex), len(val_ex)
    return {"model": model, "state": state}


def trainable(model: GnnVae, frozen: Sequence[str]) -> list[torch.nn.Parameter]:
    """The parameters outside the ``frozen`` parts, which are set not to need gradients.

    A part is one of :data:`PARTS` or a module inside one by its dotted name
    (``trunk.convs.0``), so that a fine-tune can keep the first graph layers and adapt
    the last. Fine-tuning every weight on scenario data cost the small random problems
    ~0.003 of cost ratio with one sample (v8, v11, v12); freezing the graph layers keeps
    what they learned there and adapts the heads only.

    Raises:
        ValueError: a name that is not a part or a module inside one.
    """
    unknown = unknown_parts(model, frozen)
    if unknown:
        raise ValueError(f"unknown model parts {unknown}; {PART_HINT}")
    for name in frozen:
        model.get_submodule(name).requires_grad_(False)
    return [p for p in model.parameters() if p.requires_grad]


def unknown_parts(model: GnnVae, names: Sequence[str]) -> list[str]:
    """The ``names`` (sorted) that are neither one of :data:`PARTS` nor a module inside one."""

    def known(name: str) -> bool:
        try:
            model.get_submodule(name)
        except AttributeError:
            return False
        return name.split(".")[0] in PARTS

    return sorted(name for name in names if not known(name))


def per_dataset(keep: TargetFilter | Sequence[TargetFilter], n: int) -> list[TargetFilter]:
    """One filter per dataset: ``keep`` repeated, or ``keep`` itself if it has ``n``."""
    keeps = [keep] * n if isinstance(keep, TargetFilter) else list(keep)
    if len(keeps) != n:
        raise ValueError(f"{len(keeps)} target filters for {n} datasets")
    return keeps


def filter_record(keeps: Sequence[TargetFilter]) -> dict[str, Any] | list[dict[str, Any]]:
    """How checkpoints and manifests name the filters: one dict when they are all the same
    (as before per-dataset filters existed), else one per dataset."""
    if all(k == keeps[0] for k in keeps):
        return asdict(keeps[0])
    return [asdict(k) for k in keeps]


def _gap(text: str) -> float | None:
    """A ``--max-gap`` value: a relative gap >= 0, or ``none`` (any gap)."""
    if text.lower() == "none":
        return None
    gap = float(text)
    if not gap >= 0:
        raise argparse.ArgumentTypeError(f"a gap is >= 0 or 'none', not {text}")
    return gap


def _parser() -> argparse.ArgumentParser:
    """The training flags; the model's (``--hidden`` ...) and the optimizer's from their configs."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--data", type=Path, nargs="+", required=True, help="dataset folders (trained on together)"
    )
    p.add_argument("--objective", choices=OBJECTIVES, required=True)
    p.add_argument(
        "--runs", type=Path, default=Path("runs"), help="checkpoints go to RUNS/objective/version"
    )
    p.add_argument("--store", type=Path, default=Path("model_store"))
    p.add_argument("--version", default="v1")
    p.add_argument("--train-problems", type=int, default=None)
    p.add_argument("--val", type=int, default=300)
    p.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's)")
    p.add_argument("--init", type=Path, help="a stored model's folder to start from (fine-tune)")
    p.add_argument(
        "--max-gap",
        type=_gap,
        nargs="+",
        default=[None],
        help="drop targets of a larger relative gap: one for all --data, or one per folder "
        "('none': any gap)",
    )
    p.add_argument("--proven-only", action="store_true", help="drop targets of unknown gap")
    p.add_argument(
        "--freeze",
        nargs="+",
        default=[],
        metavar="PART",
        help=f"model parts whose weights stay as --init's (fine-tune the rest); {PART_HINT}",
    )
    for f, v in asdict(GnnVaeConfig()).items():  # default None: --init's, else the config's
        p.add_argument(f"--{f.replace('_', '-')}", type=int, help=f"default {v}")
    for f, v in asdict(TrainConfig()).items():
        p.add_argument(f"--{f.replace('_', '-')}", type=type(v), default=v)
    return p


def _model_setup(
    p: argparse.ArgumentParser, args: argparse.Namespace
) -> tuple[GnnVaeConfig, StoredModel | None]:
    """The model config and the model to start from: ``--init``'s (whose config the model
    flags given must match), else the flags' over the defaults."""
    given = {k: v for k in asdict(GnnVaeConfig()) if (v := getattr(args, k)) is not None}
    if args.init is None:
        return GnnVaeConfig(**given), None
    try:
        init = load_model_dir(args.init)
    except ModelLoadError as exc:
        p.error(f"--init: {exc}")
    differ = {k: v for k, v in given.items() if getattr(init.model.config, k) != v}
    if differ:
        p.error(f"--init {init.name} fixes the model's config; {differ} differ from it")
    if (args.store / args.objective / args.version).resolve() == args.init.resolve():
        p.error(f"--init {args.init}: saving as --version {args.version} would overwrite it")
    return init.model.config, init


def main(argv: list[str] | None = None) -> None:
    """CLI entry: train one objective and write it to the model store."""
    p = _parser()
    args = p.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    model_cfg, init = _model_setup(p, args)
    if args.freeze and init is None:
        p.error("--freeze keeps weights of --init: give the model to start from")
    unknown = unknown_parts(GnnVae(model_cfg), args.freeze)
    if unknown:
        p.error(f"--freeze: unknown model parts {unknown}; {PART_HINT}")
    cfg = TrainConfig(**{k: getattr(args, k) for k in asdict(TrainConfig())})
    if len(args.max_gap) not in (1, len(args.data)):
        p.error(f"--max-gap: {len(args.max_gap)} gaps for {len(args.data)} --data folders")
    gaps = args.max_gap * len(args.data) if len(args.max_gap) == 1 else args.max_gap
    keeps = [TargetFilter(g, args.proven_only) for g in gaps]
    result = train(
        args.data,
        args.objective,
        args.runs / args.objective / args.version,
        model_cfg,
        cfg,
        args.train_problems,
        args.val,
        init,
        keeps,
        args.freeze,
    )
    state = result["state"]
    folder = save_model(
        result["model"],
        args.store,
        args.objective,
        args.version,
        {
            "datasets": [
                {"path": str(path), "sha256": m.get("sha256"), "config": m["config"]}
                for path, m in ((p, load_manifest(p)) for p in args.data)
            ],
            "train_problems": state["n_train"],
            "val_problems": state["n_val"],
            "init": None if init is None else init_record(init),
            "training": {
                **asdict(cfg),
                "target_filter": filter_record(keeps),
                "frozen": sorted(args.freeze),
                "best_epoch": state["best_epoch"],
                "epochs_run": state["epoch"],
            },
            "validation": state.get("best_val", {}),
        },
    )
    print(f"saved {folder}")


if __name__ == "__main__":
    main()
