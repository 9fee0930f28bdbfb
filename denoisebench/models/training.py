"""The training loop behind ``denoisebench train``: where a run starts, optimisation, validation,
checkpoints, resume.

The command's options and their defaults are :mod:`~denoisebench.models.training_options`; the data,
its crops and the order of the batches are :mod:`~denoisebench.models.training_data`. Validation runs
on whole frames of the ``val`` split, the way a denoiser wrapper runs them (frames in order,
``reset()`` between sequences).

Determinism: the model is initialised after ``torch.manual_seed(seed)`` and the batches are fixed by
``(seed, epoch)`` (training_data), so a run resumed from its checkpoint at step *s* continues exactly
as the uninterrupted run would have (tested bit for bit).

Notes
-----
* ``torch.use_deterministic_algorithms`` is not switched on: the CPU kernels these models use are
  deterministic already (the resume test compares weights bit for bit), and the switch costs a
  13 s import of torch._dynamo and made KPCN's backward pass 4× slower.
* A step whose loss or gradient is not finite is skipped (counted in ``meta["skipped_steps"]``)
  rather than allowed to poison the weights; gradients are clipped to norm 1.
* Validation relMSE is computed here with torch (:func:`~denoisebench.models.losses.relmse`)
  because ``models`` may not import ``metrics`` (docs/architecture.md's import table); it follows the
  metric's definition exactly.
* The checkpoint written during training carries the optimiser state (for ``--resume``);
  :func:`strip_for_shipping` drops it.
* On CUDA the loader uses ``workers`` processes and pinned memory so the GPU is not starved; the
  batches and their crops are the same on any device and any worker count, though CUDA kernels are
  not bit-exact with the CPU's.
* Every stage (one command) of a run is recorded in ``meta["stages"]`` (the model card lists them).
* ``--resume`` continues a run on its own dataset only: with ``--steps`` > 0 on another dataset
  the card would list that dataset's scenes as though every step had been trained on them.
  ``--init-from`` fine-tunes instead: the checkpoint's weights, configuration and step count with a
  fresh optimiser on the new data; the earlier run's record moves into ``meta["earlier_runs"]``
  (:mod:`~denoisebench.models.provenance`) and the batch order continues from its step count.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from denoisebench.dataset.reader import Dataset, open_dataset
from denoisebench.errors import UserInputError
from denoisebench.models.catalog import build_model, get_spec, model_config
from denoisebench.models.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint
from denoisebench.models.features import frame_tensors
from denoisebench.models.losses import pcn_loss, rae_sequence_loss, relmse
from denoisebench.models.provenance import run_record
from denoisebench.models.training_data import (
    EpochItems,
    available_buffers,
    batch_plan,
    batches,
    make_dataset,
    to_device,
    train_spp,
)
from denoisebench.models.training_options import (
    LR_SCHEDULES,
    TrainOptions,
    apply_overrides,
    command_line,
    lr_factor,
    max_threads,
    resolve_device,
    resolve_loss,
)


def _loss(model, spec, batch: dict[str, torch.Tensor], kind: str = "log") -> dict[str, torch.Tensor]:
    if not spec.temporal:
        return pcn_loss(model(batch), batch, kind)
    frames = batch["color"].shape[1]
    model.reset()
    preds, refs = [], []
    for t in range(frames):
        out = model({name: value[:, t] for name, value in batch.items()})
        preds.append(out["color"])
        refs.append(batch["reference"][:, t])
    model.reset()
    return rae_sequence_loss(preds, refs, kind)


@torch.no_grad()
def validate(model, spec, ds: Dataset, scenes: list[str], spp: list[int], max_frames: int = 8) -> dict:
    """Mean relMSE of the model and of the noisy input over whole val frames (empty dict: no val scenes)."""
    if not scenes:
        return {}
    device = next(model.parameters()).device
    model.eval()
    ours, noisy, count = [], [], 0
    for scene in scenes:
        for s in spp:
            if spec.temporal:
                model.reset()
            frames = min(ds.scene(scene).frame_count, max_frames)
            for index in range(frames):
                frame = ds.frame(scene, s, index, reference=True, samples=False)
                out = model(to_device(frame_tensors(frame), device))["color"].cpu()
                ref = torch.from_numpy(np.moveaxis(frame.reference, -1, 0).copy())[None]
                ours.append(relmse(out, ref))
                noisy.append(relmse(frame_tensors(frame, ("color",))["color"], ref))
                count += 1
    if spec.temporal:
        model.reset()
    model.train()
    mean_ours, mean_noisy = float(np.mean(ours)), float(np.mean(noisy))
    return {
        "relmse": mean_ours,
        "relmse_noisy": mean_noisy,
        "relmse_ratio": mean_ours / mean_noisy if mean_noisy > 0 else math.inf,
        "frames": count,
        "scenes": list(scenes),
        "spp": list(spp),
    }


@dataclass
class _Start:
    """Where a run starts: the model, its optimiser and configuration, and the metadata carried in.

    ``rescoring``: ``--steps 0`` on another dataset than the checkpoint's; the run scores the
    weights and keeps the training run's record as it was. ``payload``: the checkpoint read, if any.
    """

    config: dict
    model: torch.nn.Module
    optimizer: torch.optim.Optimizer
    meta: dict
    rescoring: bool = False
    payload: dict | None = None


#: Metadata a resumed run carries over from its checkpoint.
_RESUMED_KEYS = (
    "steps",
    "seconds",
    "skipped_steps",
    "history",
    "commands",
    "threads",
    "stages",
    "validation_history",
    "devices",
    "earlier_runs",
    "machines",
)


def machine_description(device: str) -> str:
    """The machine a stage trained on, for its card: core count and accelerator (``"8-core machine, no GPU"``)."""
    cores = os.cpu_count() or 1
    if device == "cuda" and torch.cuda.is_available():
        accelerator = torch.cuda.get_device_name(0)
    else:
        accelerator = "no GPU"
    return f"a {cores}-core machine, {accelerator}"


def _new_meta() -> dict:
    return {"steps": 0, "seconds": 0.0, "skipped_steps": 0, "history": []}


def _adam(model: torch.nn.Module, lr: float) -> torch.optim.Optimizer:
    return torch.optim.Adam(model.parameters(), lr=lr)


def _fresh_start(spec, options: TrainOptions, device: torch.device) -> _Start:
    """A new run: the named configuration with ``--set`` overrides, weights from ``--seed``."""
    config = apply_overrides(spec, model_config(spec.name, options.config), options.overrides)
    torch.manual_seed(options.seed)
    model = build_model(spec.name, config).to(device)
    return _Start(config, model, _adam(model, options.lr), _new_meta())


def _resume_start(spec, options: TrainOptions, device: torch.device, ds: Dataset) -> _Start:
    """``--resume``: continue a run on its own dataset (optimiser state included), or score its weights."""
    # Seeded and drawn as a new run (the checkpoint's model is then drawn and overwritten), so torch's
    # generator is where --init-from leaves it too.
    start = _fresh_start(spec, options, device)
    config = start.config
    payload = load_checkpoint(options.resume, expect_model=spec.name)
    if not options.overrides and (options.steps == 0 or payload.get("config_name") in (None, options.config)):
        # scored, or continued, as it was made: its --set keys, or a shape kept by --init-from from
        # before the named configuration changed (the shipped dpcn_small.pt: 5 layers of 3x3)
        config = payload["config"]
    if payload["config"] != config:
        raise UserInputError(f"{options.resume}: trained with config {payload['config']}, not {config}")
    trained_on = payload["meta"].get("dataset_hash")
    if options.steps > 0 and trained_on not in (None, ds.config_hash):
        raise UserInputError(
            f"{options.resume}: trained on another dataset (config hash {trained_on[:12]}…, "
            f"this one {ds.config_hash[:12]}…); --resume continues a run on its own data: "
            "--init-from fine-tunes the weights on this one, --steps 0 scores them"
        )
    if "optimizer" not in payload and options.steps > 0:
        raise UserInputError(
            f"{options.resume}: has no optimiser state (shipped weights cannot be resumed; "
            "--init-from fine-tunes them, --steps 0 scores them)"
        )
    model = model_from_checkpoint(payload).to(device)
    optimizer = _adam(model, options.lr)
    if "optimizer" in payload:
        optimizer.load_state_dict(payload["optimizer"])
    for group in optimizer.param_groups:  # load_state_dict restored the old rate; --lr wins
        group["lr"] = options.lr
    meta, rescoring = _new_meta(), False
    if options.steps == 0 and trained_on not in (None, ds.config_hash):
        rescoring = True
        meta = dict(payload["meta"])  # the training run's record stays as it was
    meta.update({k: payload["meta"][k] for k in _RESUMED_KEYS if k in payload["meta"]})
    return _Start(config, model, optimizer, meta, rescoring, payload)


def _init_from_start(spec, options: TrainOptions, device: torch.device) -> _Start:
    """``--init-from``: fine-tune a checkpoint's weights (its own shape) with a fresh optimiser."""
    # Draw the named configuration's model from the seed, as --resume does, then overwrite it with the
    # checkpoint's: torch's generator is left where it leaves it.
    torch.manual_seed(options.seed)
    build_model(spec.name, apply_overrides(spec, model_config(spec.name, options.config), options.overrides))
    payload = load_checkpoint(options.init_from, expect_model=spec.name)
    if options.steps < 1:
        raise UserInputError("--init-from fine-tunes: give --steps >= 1 (--steps 0 --resume scores weights)")
    if options.overrides:
        raise UserInputError("--init-from keeps the checkpoint's configuration: --set cannot change it")
    if payload.get("config_name") not in (None, options.config):
        raise UserInputError(
            f"{options.init_from}: weights of the {payload['config_name']!r} configuration; "
            f"add --config {payload['config_name']}"
        )
    model = model_from_checkpoint(payload).to(device)
    earlier = payload["meta"]
    meta = _new_meta()
    meta.update(
        {
            "steps": int(earlier.get("steps", 0)),  # the batch order continues from here
            "seconds": float(earlier.get("seconds", 0.0)),  # the weights' whole training time
            "threads": list(earlier.get("threads", [])),
            "machines": list(earlier.get("machines", [])),
            "devices": list(earlier.get("devices", [])),
            "earlier_runs": [
                *earlier.get("earlier_runs", []),
                run_record(earlier, options.init_from, lambda name: resolve_loss(spec, name, None)),
            ],
        }
    )
    # the weights' own shape (the shipped dpcn_small.pt predates the small config)
    return _Start(payload["config"], model, _adam(model, options.lr), meta, payload=payload)


def _record_run(start: _Start, spec, options: TrainOptions, ds: Dataset, run: dict, out: Path) -> None:
    """Write this command's provenance into ``start.meta``: data, recipe, command line, stage.

    ``run``: what the run resolved (``spp``, ``crop``, ``frames``, ``buffers``, ``targets``,
    ``loss``, ``threads``, ``device``, ``play_backward``, ``val_scenes``, ``train_scenes``).
    """
    meta = start.meta
    data_fields = {
        "dataset": str(Path(options.data).resolve()),
        "dataset_hash": ds.config_hash,
        "dataset_config": ds.config,
        "val_scenes": run["val_scenes"],
    }
    if start.rescoring:
        meta["evaluated_on"] = data_fields  # the training run's own fields stay as they were
    else:
        meta.update(
            {
                **data_fields,
                "model": spec.name,
                "config_name": options.config if isinstance(options.config, str) else None,
                "seed": options.seed,
                "train_scenes": run["train_scenes"],
                "spp": run["spp"],
                "crop": run["crop"],
                "play_backward": run["play_backward"],
                "sequence_length": run["frames"],
                "batch_size": options.batch_size,
                "lr": options.lr,
                "loss": run["loss"],
                "lr_schedule": options.lr_schedule,
                "buffers": list(run["buffers"]),
                "targets": list(run["targets"]),
                "torch": str(torch.__version__),
            }
        )
    if int(meta["steps"]) > 0 and not meta.get("commands") and options.resume:
        # A checkpoint from before commands were recorded: rebuild its command from its metadata.
        recorded = start.payload["meta"]
        earlier = TrainOptions(
            model=spec.name,
            data=options.data,
            config=start.payload.get("config_name") or options.config,
            steps=int(meta["steps"]),
            seed=int(recorded.get("seed", 0)),
            batch_size=int(recorded.get("batch_size", options.batch_size)),
            crop=int(recorded.get("crop", run["crop"])),
            lr=float(recorded.get("lr", options.lr)),
            sequence_length=int(recorded.get("sequence_length", options.sequence_length)),
        )
        meta["commands"] = [command_line(earlier, str(options.resume))]
    meta.setdefault("commands", []).append(command_line(options, str(out)))
    # Every torch thread count the training ran with (the card's training time depends on it).
    if not start.rescoring and options.steps > 0:  # threads, devices and stages describe training; scoring is no stage
        meta["threads"] = sorted(set(meta.get("threads", [])) | {run["threads"]})
        meta["devices"] = sorted(set(meta.get("devices", [])) | {run["device"]})
        meta["machines"] = [*meta.get("machines", []), machine_description(run["device"])]
        # One record per command (stage) of a multi-stage run: what the card lists.
        meta.setdefault("stages", []).append(
            {
                "steps": int(options.steps),
                "from_step": int(meta["steps"]),
                "lr": options.lr,
                "lr_schedule": options.lr_schedule,
                "loss": run["loss"],
                "batch_size": options.batch_size,
                "crop": run["crop"],
                "spp": run["spp"],
                "device": run["device"],
                "threads": run["threads"],
                "dataset_hash": ds.config_hash,
            }
        )


class _Checkpointer:
    """Writes the checkpoint and keeps the training clock: seconds accrue between writes, scoring excluded."""

    def __init__(self, start: _Start, spec, out: Path):
        self.start, self.spec, self.out = start, spec, out
        self.since = time.perf_counter()

    def __call__(self, step: int, validation: dict | None = None) -> None:
        start, meta = self.start, self.start.meta
        meta["steps"] = step
        if not start.rescoring:  # training time only
            meta["seconds"] = round(meta["seconds"] + time.perf_counter() - self.since, 3)
        self.since = time.perf_counter()
        if validation is not None:
            (meta["evaluated_on"] if start.rescoring else meta)["validation"] = validation
        save_checkpoint(
            self.out,
            self.spec.name,
            start.config,
            start.model,
            meta,
            config_name=meta["config_name"],
            optimizer=start.optimizer,
        )


def _optimise(start: _Start, spec, options, dataset, device, loss_kind, checkpoint, validation) -> float | None:
    """Run this command's steps from ``start.meta['steps']``; returns the smoothed last loss.

    ``validation()`` scores the val split (for ``--val-every``); ``checkpoint(step)`` writes.
    """
    model, optimizer, meta = start.model, start.optimizer, start.meta
    start_step = int(meta["steps"])
    total = start_step + int(options.steps)
    per_epoch = len(batches(len(dataset), options.batch_size, options.seed, 0))
    workers = (
        options.workers if options.workers is not None else (min(4, max_threads()) if device.type == "cuda" else 0)
    )
    model.train()
    bar = tqdm(total=options.steps, desc=f"train {spec.name}", unit="step", disable=not options.progress)
    step, running = start_step, None
    try:
        # One loader for the whole run (its workers start once, not every epoch); items are
        # addressed as (epoch, index), so every worker draws the crops the single process would.
        plan = batch_plan(len(dataset), options.batch_size, options.seed, per_epoch, step, total)
        loader = torch.utils.data.DataLoader(
            EpochItems(dataset), batch_sampler=plan, num_workers=workers, pin_memory=device.type == "cuda"
        )
        if step < total:
            for batch in loader:
                for group in optimizer.param_groups:
                    group["lr"] = options.lr * lr_factor(options.lr_schedule, step - start_step, options.steps)
                loss = _loss(model, spec, to_device(batch, device), loss_kind)["loss"]
                optimizer.zero_grad(set_to_none=True)
                if torch.isfinite(loss):
                    loss.backward()
                    norm = torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
                    if torch.isfinite(norm):
                        optimizer.step()
                    else:
                        meta["skipped_steps"] += 1
                else:
                    meta["skipped_steps"] += 1
                step += 1
                value = float(loss.detach())
                running = value if running is None or not math.isfinite(running) else 0.9 * running + 0.1 * value
                bar.update(1)
                bar.set_postfix(loss=f"{running:.4f}")
                if step % 10 == 0 or step == total:
                    meta["history"].append([step, round(running, 6)])
                if options.val_every and step % options.val_every == 0 and step < total:
                    meta.setdefault("validation_history", []).append([step, validation().get("relmse")])
                if options.checkpoint_every and step % options.checkpoint_every == 0 and step < total:
                    checkpoint(step)
                if step >= total:
                    break
    finally:
        bar.close()
    meta["steps"] = step
    return running


def chosen_train_scenes(ds: Dataset, names, val_scenes: list[str]) -> list[str]:
    """``names`` (``TrainOptions.train_scenes``) checked against the dataset, sorted: an unknown
    scene or one of the val split is a UserInputError (validation must stay on unseen scenes)."""
    names = sorted(dict.fromkeys(names))
    unknown = [name for name in names if name not in ds.scenes]
    if unknown:
        raise UserInputError(f"{ds.root}: no scene {unknown[0]!r} to train on ({len(unknown)} unknown)")
    validated = sorted(set(names) & set(val_scenes))
    if validated:
        raise UserInputError(f"{validated[0]}: a val-split scene cannot be trained on (it validates the run)")
    return names


def train(options: TrainOptions) -> dict:
    """Train (or resume) and write the checkpoint; returns its metadata. Raises UserInputError on bad input.

    Three ways in (:func:`_fresh_start`, :func:`_resume_start`, :func:`_init_from_start`), then the
    same steps: record the run's provenance, optimise, validate, write the checkpoint.
    """
    spec = get_spec(options.model)
    if options.steps < 0:
        raise UserInputError(f"--steps must be >= 0 (got {options.steps})")
    loss_kind = resolve_loss(spec, options.config, options.loss)
    if options.lr_schedule not in LR_SCHEDULES:
        raise UserInputError(
            f"unknown learning-rate schedule {options.lr_schedule!r}; schedules: {', '.join(LR_SCHEDULES)}"
        )
    device = resolve_device(options.device)
    threads = max(1, min(int(options.threads), max_threads()))
    torch.set_num_threads(threads)
    ds = open_dataset(options.data)
    train_scenes, val_scenes = ds.split("train"), ds.split("val")
    if options.train_scenes is not None:
        train_scenes = chosen_train_scenes(ds, options.train_scenes, val_scenes)
    if not train_scenes:
        raise UserInputError(f"{options.data}: the train split is empty (the dataset needs more scenes)")
    spp = train_spp(ds, train_scenes, options.spp)
    if not ds.scene(train_scenes[0]).has_reference:
        raise UserInputError(f"{options.data}: no reference frames; training needs them")
    buffers, targets = available_buffers(ds, train_scenes[0], spp[0], spec.buffers, spec.targets)

    if options.resume and options.init_from:
        raise UserInputError("--resume continues a run, --init-from starts a new one from its weights: give one")
    if options.resume:
        start = _resume_start(spec, options, device, ds)
    elif options.init_from:
        start = _init_from_start(spec, options, device)
    else:
        start = _fresh_start(spec, options, device)

    dataset, crop, frames = make_dataset(spec, ds, train_scenes, spp, options, buffers, targets)
    out = Path(
        options.out or f"checkpoints/{spec.name}_{options.config if isinstance(options.config, str) else 'custom'}.pt"
    )
    run = {
        "spp": spp,
        "crop": crop,
        "frames": frames,
        "buffers": buffers,
        "targets": targets,
        "loss": loss_kind,
        "threads": threads,
        "device": device.type,
        "play_backward": bool(getattr(dataset, "play_backward", False)),
        "train_scenes": train_scenes,
        "val_scenes": val_scenes,
    }
    _record_run(start, spec, options, ds, run, out)

    def validation() -> dict:
        return validate(start.model, spec, ds, val_scenes, spp, options.val_frames)

    checkpoint = _Checkpointer(start, spec, out)
    running = _optimise(start, spec, options, dataset, device, loss_kind, checkpoint, validation)
    start.meta["last_loss"] = running
    checkpoint(int(start.meta["steps"]), validation())
    start.meta["checkpoint"] = str(out)
    return start.meta


def strip_for_shipping(src: str | Path, dst: str | Path) -> Path:
    """Copy a training checkpoint without its optimiser state (and the loss history), for shipping."""
    payload = load_checkpoint(src)
    model = model_from_checkpoint(payload)
    meta = {k: v for k, v in payload["meta"].items() if k != "history"}
    return save_checkpoint(
        dst, payload["model"], payload["config"], model, meta, config_name=payload.get("config_name")
    )
