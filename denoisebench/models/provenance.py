"""How a checkpoint was made, across datasets: the record a fine-tune (``train --init-from``) keeps.

A checkpoint's ``meta`` describes the run that trained it on *one* dataset: its hash, config,
train/val scenes, the ``denoisebench train`` commands (``meta["commands"]``) and one record per
command (``meta["stages"]``). Weights fine-tuned on another dataset have two such histories; the
earlier one moves, frozen, into ``meta["earlier_runs"]`` (oldest first) and the top-level fields
describe the fine-tuning data. The model card lists every run's data, commands and stages, and
checks held-out scenes against the train scenes of *every* run.

Notes
-----
* Only commands that trained count (``--steps`` > 0): a ``--steps 0`` command validated or scored
  weights without changing them (one that scored them on another dataset would otherwise appear
  as though it were part of that run's recipe).
* Checkpoints written before stages were recorded carry commands only; :func:`stages_from_commands`
  reads each one back (steps, learning rate, schedule, loss, batch, crop, spp, threads), with the
  configuration's recipe for a loss left out. Such old runs were CPU-only (``--device`` did not exist).
"""

from __future__ import annotations

import shlex

#: The dataset fields of a run (top level of ``meta``), copied into its record.
DATA_FIELDS = ("dataset", "dataset_hash", "dataset_config", "train_scenes", "val_scenes", "spp")


def _flags(command: str) -> dict[str, str]:
    """``--flag value`` pairs of a recorded command line (value-less flags map to '')."""
    parts = shlex.split(command)
    flags: dict[str, str] = {}
    for i, part in enumerate(parts):
        if part.startswith("--"):
            following = parts[i + 1] if i + 1 < len(parts) else ""
            flags[part] = "" if following.startswith("--") else following
    return flags


def command_steps(command: str) -> int:
    """The ``--steps`` of a recorded train command (0 when absent or unreadable)."""
    try:
        return int(_flags(command).get("--steps", "0"))
    except ValueError:
        return 0


def stages_from_commands(commands: list[str], meta: dict, default_loss) -> list[dict]:
    """One stage record per training command (``--steps`` > 0), as ``meta["stages"]`` holds them.

    ``default_loss(config_name)`` gives the loss of a command that names none (its recipe).
    """
    stages, done = [], 0
    for command in commands:
        flags = _flags(command)
        steps = command_steps(command)
        if steps <= 0:
            continue
        spp = flags.get("--spp")
        stages.append(
            {
                "steps": steps,
                "from_step": done,
                "lr": float(flags.get("--lr", "0.001")),
                "lr_schedule": flags.get("--lr-schedule", "constant"),
                "loss": flags.get("--loss") or default_loss(flags.get("--config", "small")),
                "batch_size": int(flags.get("--batch-size", meta.get("batch_size", 8))),
                "crop": int(flags.get("--crop", meta.get("crop", 32))),
                "spp": [int(s) for s in spp.split(",")] if spp else meta.get("spp"),
                "device": flags.get("--device", "cpu"),
                "threads": int(flags.get("--threads", "1")),
            }
        )
        done += steps
    return stages


def run_record(meta: dict, checkpoint: str, default_loss) -> dict:
    """A finished run's data, training commands, stages, time and validation, for ``earlier_runs``."""
    commands = [c for c in meta.get("commands", []) if command_steps(c) > 0]
    stages = meta.get("stages") or stages_from_commands(commands, meta, default_loss)
    record = {key: meta[key] for key in DATA_FIELDS if key in meta}
    record.update(
        {
            "checkpoint": str(checkpoint),
            "steps": int(meta.get("steps", 0)),
            "seconds": float(meta.get("seconds", 0.0)),
            "commands": commands,
            "stages": [
                dict(stage, dataset_hash=stage.get("dataset_hash", meta.get("dataset_hash"))) for stage in stages
            ],
            "validation": meta.get("validation"),
        }
    )
    return record


def all_train_scenes(meta: dict) -> set[str]:
    """Train scenes of the run and of every earlier run it was fine-tuned from."""
    scenes = set(meta.get("train_scenes", []))
    for run in meta.get("earlier_runs", []):
        scenes |= set(run.get("train_scenes", []))
    return scenes
