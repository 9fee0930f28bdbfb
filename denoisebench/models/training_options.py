"""What a ``denoisebench train`` command asks for: its options, ``--set`` overrides, recipe defaults,
device, threads, learning-rate schedule and loss, and the command line that repeats it.

:class:`TrainOptions` is the command's options; a configuration's recipe (catalog ``recipes``) fills
what it leaves None (:func:`recipe_value`, :func:`resolve_loss`: else ``log``; ``lobes`` for DPCN/KPCN
is the paper's separate L1 per branch). Learning-rate schedules (:func:`lr_factor`): ``constant``,
``cosine`` (from ``lr`` down to ``lr/100`` over this command's steps) or ``step`` (×0.1 at half and
three quarters of them); a schedule spans one command, so a resumed run is a new stage with its own.
Device (:func:`resolve_device`): ``auto`` takes CUDA when torch sees it, else the CPU; threads are
capped at the cores this process may use (:func:`max_threads`). :func:`command_line` is recorded in
checkpoints for the model cards.
"""

from __future__ import annotations

import inspect
import json
import math
import os
import shlex
from dataclasses import dataclass, field

import torch

from denoisebench.errors import UserInputError
from denoisebench.models.catalog import get_spec
from denoisebench.models.losses import PCN_KINDS, SPATIAL


@dataclass
class TrainOptions:
    model: str
    data: str
    config: str = "small"
    steps: int = 200
    out: str | None = None
    resume: str | None = None
    #: fine-tune: start from these weights (shipped ones too) with a fresh optimiser, on ``data``
    init_from: str | None = None
    seed: int = 0
    batch_size: int = 8
    crop: int | None = None  # None: the configuration's recipe, else 32
    lr: float = 1e-3
    spp: list[int] | None = None  # None: every noisy spp of the dataset
    sequence_length: int = 7
    loss: str | None = (
        None  # losses.SPATIAL name or one of losses.PCN_KINDS; None: the configuration's recipe, else "log"
    )
    val_every: int = 0  # 0: validate once, at the end
    val_frames: int = 8  # per val scene and spp
    checkpoint_every: int = 100
    threads: int = 1
    device: str = "auto"  # auto | cpu | cuda
    workers: int | None = None  # loader processes; None: 0 on the CPU, min(4, cores) on CUDA
    lr_schedule: str = "constant"  # constant | cosine | step
    play_backward: bool | None = None  # temporal models: windows reversed half the time; None: recipe
    progress: bool = True
    #: configuration keys replaced for this run (``--set KEY=VALUE``: ablations such as rae
    #: ``residual=false``); the checkpoint records the resulting configuration, so it loads as trained
    overrides: dict = field(default_factory=dict)
    #: train on these scenes of the dataset instead of its train split (None: the train split); a
    #: val-split scene among them is refused, so validation stays on scenes the model never saw
    train_scenes: tuple[str, ...] | None = None


LR_SCHEDULES = ("constant", "cosine", "step")


def resolve_device(name: str) -> torch.device:
    """``auto`` → CUDA when torch sees a GPU, else CPU; ``cuda`` without one is a UserInputError."""
    if name not in ("auto", "cpu", "cuda"):
        raise UserInputError(f"--device must be auto, cpu or cuda (got {name!r})")
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise UserInputError("--device cuda: torch sees no CUDA device (this torch build or machine has none)")
    return torch.device(name)


def max_threads() -> int:
    """CPU cores this process may use (affinity-aware where the OS says)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def lr_factor(schedule: str, done: int, steps: int) -> float:
    """Multiplier of the base rate after ``done`` of this command's ``steps`` (see the module Notes)."""
    if schedule == "constant" or steps <= 0:
        return 1.0
    progress = min(max(done / steps, 0.0), 1.0)
    if schedule == "cosine":
        floor = 0.01
        return floor + (1.0 - floor) * 0.5 * (1.0 + math.cos(math.pi * progress))
    if schedule == "step":
        return 1.0 if progress < 0.5 else 0.1 if progress < 0.75 else 0.01
    raise UserInputError(f"unknown learning-rate schedule {schedule!r}; schedules: {', '.join(LR_SCHEDULES)}")


def resolve_loss(spec, config, loss: str | None) -> str:
    """The loss a run uses: the one asked for, else the configuration's recipe, else ``log``."""
    loss = recipe_value(spec, config, "loss", loss, "log")
    allowed = set(SPATIAL) | (set(PCN_KINDS) if spec.name in ("dpcn", "kpcn") else set())
    if loss not in allowed:
        raise UserInputError(f"unknown loss {loss!r} for {spec.name}; losses: {', '.join(sorted(allowed))}")
    return loss


def parse_override(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` → (key, value); VALUE is JSON (``false``, ``3``, ``[12, 18]``), else the plain string."""
    key, sep, value = text.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise UserInputError(f"--set expects KEY=VALUE, e.g. residual=false (got {text!r})")
    value = value.strip()
    lowered = value.lower()
    if lowered in ("true", "false"):
        return key, lowered == "true"
    try:
        return key, json.loads(value)
    except ValueError:
        return key, value


def apply_overrides(spec, config: dict, overrides: dict) -> dict:
    """``config`` with ``overrides`` applied; a key the configuration does not have and the model's
    constructor does not take, or a value of another type than the configuration's, is a UserInputError."""
    if not overrides:
        return config

    accepted = set(config) | {name for name in inspect.signature(spec.build).parameters if name != "self"}
    out = dict(config)
    for key, value in overrides.items():
        if key not in accepted:
            raise UserInputError(
                f"--set {key}: not a {spec.name} configuration key (keys: {', '.join(sorted(accepted))})"
            )
        if key in config and config[key] is not None and isinstance(config[key], bool) != isinstance(value, bool):
            raise UserInputError(f"--set {key}={value!r}: expected a value like {config[key]!r}")
        out[key] = value
    return out


def recipe_value(spec, config, key: str, given, default):
    """``given`` unless None, else the configuration's recipe value for ``key``, else ``default``."""
    if given is not None:
        return given
    recipe = spec.recipes.get(config, {}) if isinstance(config, str) else {}
    return recipe.get(key, default)


def command_line(options: TrainOptions, out: str) -> str:
    """The ``denoisebench train`` command that runs ``options`` (recorded in the checkpoint for model cards)."""
    parts = [
        "denoisebench",
        "train",
        "--model",
        options.model,
        "--data",
        str(options.data),
        "--config",
        str(options.config),
        "--steps",
        str(options.steps),
        "--out",
        out,
    ]
    if options.resume:
        parts += ["--resume", str(options.resume)]
    if options.init_from:
        parts += ["--init-from", str(options.init_from)]
    parts += ["--seed", str(options.seed), "--batch-size", str(options.batch_size)]
    if options.crop is not None:
        parts += ["--crop", str(options.crop)]
    parts += ["--lr", str(options.lr)]
    if options.play_backward is not None:
        parts.append("--play-backward" if options.play_backward else "--no-play-backward")
    if options.spp:
        parts += ["--spp", ",".join(str(s) for s in options.spp)]
    if get_spec(options.model).temporal:
        parts += ["--sequence-length", str(options.sequence_length)]
    if options.loss is not None and options.loss != "log":
        parts += ["--loss", options.loss]
    if options.train_scenes is not None:
        parts += ["--train-scenes", ",".join(options.train_scenes)]
    for key, value in sorted(options.overrides.items()):
        parts += ["--set", f"{key}={json.dumps(value)}"]
    if options.lr_schedule != "constant":
        parts += ["--lr-schedule", options.lr_schedule]
    if options.val_every:
        parts += ["--val-every", str(options.val_every)]
    if int(options.threads) != 1:
        parts += ["--threads", str(options.threads)]
    if options.device != "auto":
        parts += ["--device", options.device]
    return shlex.join(parts)
