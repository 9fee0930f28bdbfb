"""Checkpoints: a model's weights with the metadata to rebuild and judge it, loaded safely.

A checkpoint is ``torch.save`` of a plain dict::

    {"format": "denoisebench-checkpoint", "version": 1,
     "model": "kpcn", "config": {...constructor kwargs...}, "config_name": "small",
     "state_dict": {...}, "optimizer": {...} (absent in shipped weights),
     "meta": {"steps": ..., "seed": ..., "dataset_hash": ..., "validation": {...}, ...}}

and is read back with ``torch.load(weights_only=True)``: only tensors and plain Python containers
unpickle, so a checkpoint from a stranger cannot run code.

Notes
-----
* Writes are atomic (temporary file, then rename): an interrupted save leaves the old checkpoint.
* :func:`load_checkpoint` turns every failure (missing file, not a checkpoint, unpickling refused,
  unknown model) into a one-line :class:`CheckpointError` (a UserInputError: exit 2 in the CLI).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch
from torch import nn

from denoisebench.errors import UserInputError
from denoisebench.models.catalog import MODELS, build_model

FORMAT = "denoisebench-checkpoint"
VERSION = 1


class CheckpointError(UserInputError):
    """A checkpoint that cannot be read or does not fit the model asked for."""


def save_checkpoint(
    path: str | os.PathLike,
    model_name: str,
    config: dict,
    model: nn.Module,
    meta: dict,
    *,
    config_name: str | None = None,
    optimizer: torch.optim.Optimizer | None = None,
) -> Path:
    """Write the checkpoint atomically; float32 weights; the optimiser state only when given (resume)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": FORMAT,
        "version": VERSION,
        "model": model_name,
        "config": dict(config),
        "config_name": config_name,
        "state_dict": {k: v.detach().to(torch.float32).clone() for k, v in model.state_dict().items()},
        # Through JSON: only plain types survive, so weights_only=True can read it back (a
        # TorchVersion or numpy scalar in meta would make the whole checkpoint unloadable).
        "meta": json.loads(json.dumps(meta, default=str)),
    }
    if optimizer is not None:
        payload["optimizer"] = optimizer.state_dict()
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        torch.save(payload, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def load_checkpoint(path: str | os.PathLike, expect_model: str | None = None) -> dict:
    """The checkpoint dict (see the module docstring), checked; ``expect_model`` must match if given."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no checkpoint file {str(path)!r}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # noqa: BLE001 - pickle refusals, truncated files, not a zip
        first = (str(error).strip().splitlines() or [type(error).__name__])[0]
        raise CheckpointError(f"{path}: not a loadable checkpoint ({first[:160]})") from None
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a denoisebench checkpoint")
    if payload.get("model") not in MODELS:
        raise CheckpointError(f"{path}: unknown model {payload.get('model')!r}")
    if expect_model is not None and payload["model"] != expect_model:
        raise CheckpointError(f"{path}: holds a {payload['model']!r} model, not {expect_model!r}")
    return payload


def model_from_checkpoint(payload: dict) -> nn.Module:
    """Rebuild the model a loaded checkpoint describes and load its weights (strict)."""
    model = build_model(payload["model"], payload["config"])
    try:
        model.load_state_dict(payload["state_dict"], strict=True)
    except RuntimeError as error:
        first = str(error).strip().splitlines()[0]
        raise CheckpointError(f"checkpoint weights do not fit model {payload['model']!r}: {first}") from None
    return model
