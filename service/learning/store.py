"""The model store: versioned GNN-VAE weights per objective, loaded safely.

Layout::

    model_store/manifest.json                 {"default": {objective: version}}
    model_store/<objective>/<version>/model.safetensors
    model_store/<objective>/<version>/model.json
        {"name", "version", "objective", "config", "dataset", "validation", "sha256"}

Weights are safetensors (no pickles); the SHA-256 of the weights file is
checked before loading, and the config is checked against the weights by a
strict ``load_state_dict``. Any failure is reported per objective so the
service can degrade to the exact solver instead of failing.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from safetensors.torch import load_file, save_file

from service.learning.model import GnnVae, GnnVaeConfig

__all__ = [
    "ModelLoadError",
    "StoredModel",
    "load_all",
    "load_model",
    "load_model_dir",
    "save_model",
]

MANIFEST = "manifest.json"
WEIGHTS = "model.safetensors"
METADATA = "model.json"


class ModelLoadError(RuntimeError):
    """A stored model is missing, corrupt, or does not match its config."""


@dataclass(eq=False)
class StoredModel:
    """A loaded model with its metadata."""

    objective: str
    version: str
    model: GnnVae
    metadata: dict[str, Any]

    @property
    def name(self) -> str:
        return f"gnn_vae/{self.objective}/{self.version}"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def save_model(
    model: GnnVae,
    root: Path,
    objective: str,
    version: str,
    extra: dict[str, Any],
    make_default: bool = True,
) -> Path:
    """Write weights and metadata; optionally make this version the objective's default."""
    folder = root / objective / version
    folder.mkdir(parents=True, exist_ok=True)
    weights = folder / WEIGHTS
    state = {k: v.detach().contiguous() for k, v in model.state_dict().items()}
    save_file(state, str(weights))
    metadata = {
        "name": f"gnn_vae/{objective}/{version}",
        "version": version,
        "objective": objective,
        "config": model.config.to_dict(),
        **extra,
        "sha256": _sha256(weights),
    }
    (folder / METADATA).write_text(json.dumps(metadata, indent=1) + "\n")
    if make_default:
        manifest_path = root / MANIFEST
        manifest = (
            json.loads(manifest_path.read_text()) if manifest_path.exists() else {"default": {}}
        )
        manifest["default"][objective] = version
        manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return folder


def load_model(root: Path, objective: str, version: str | None = None) -> StoredModel:
    """Load one model (the objective's default version unless given).

    Raises:
        ModelLoadError: missing files, checksum mismatch, or weights not matching the config.
    """
    try:
        if version is None:
            version = json.loads((root / MANIFEST).read_text())["default"][objective]
        folder = root / objective / str(version)
        metadata = json.loads((folder / METADATA).read_text())
        weights = folder / WEIGHTS
        if _sha256(weights) != metadata["sha256"]:
            raise ModelLoadError(f"{weights}: checksum mismatch")
        model = GnnVae(GnnVaeConfig(**metadata["config"]))
        model.load_state_dict(load_file(str(weights)), strict=True)
    except ModelLoadError:
        raise
    except (OSError, KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise ModelLoadError(f"{objective}: {type(exc).__name__}: {exc}") from exc
    model.eval()
    return StoredModel(objective, str(version), model, metadata)


def load_model_dir(folder: Path) -> StoredModel:
    """Load the model stored in ``folder``, a store's ``<root>/<objective>/<version>``.

    For commands that name one model rather than a store and an objective (fine-tuning
    from it, benchmarking it beside the shipped one).

    Raises:
        ModelLoadError: as :func:`load_model`.
    """
    folder = folder.resolve()
    return load_model(folder.parent.parent, folder.parent.name, folder.name)


def load_all(
    root: Path, objectives: tuple[str, ...]
) -> tuple[dict[str, StoredModel], dict[str, str]]:
    """Every objective's default model, plus an error message per objective that failed."""
    models: dict[str, StoredModel] = {}
    errors: dict[str, str] = {}
    for objective in objectives:
        try:
            models[objective] = load_model(root, objective)
        except ModelLoadError as exc:
            errors[objective] = str(exc)
    return models, errors
