"""The lecture's DPCN-vs-KPCN convergence comparison in one command: train both on the same data
with the same configuration shape, seed, batches, loss and learning rate, validate every
``--val-every`` steps, and plot their training and validation curves side by side.

    .venv/bin/python bench/pcn_convergence.py --data DATA [--config small] [--steps 2000]
        [--val-every 100] [--loss lobes] [--lr 1e-3] [--device auto] [--threads 1] [--out bench_out/pcn]

DPCN and KPCN share every configuration (``denoisebench.models.pcn``: equal depth, width and
receptive field), so the curves differ by the output form alone: a colour (DPCN) or a softmax
kernel applied to the noisy input (KPCN). The lecture reports KPCN converging 5–6× faster (Bako
et al. 2017, fig. 7); this script measures it on your data. Writes ``OUT/curves.json`` (both
runs' loss and validation histories, their commands and seconds), ``OUT/curves.png`` and prints
two speed-ups, each the ratio of the steps DPCN and KPCN need to reach DPCN's end point: its
final training loss (running mean, the paper's loss; what Bako et al. plot) and its best
validation relMSE (the benchmark's figure). ``None`` when a model never gets there within ``--steps``.

Measured (small configuration, 300 steps of batch 8 × 32² on 27 scenes of 64 px, lobes loss,
one thread; DPCN 106 s, KPCN 282 s): KPCN's training loss reached DPCN's final 0.056 at step 40
(7.5× fewer steps, the lecture's order), but its validation relMSE rose from 0.35 at step 100 to
0.86 at 300 while DPCN's fell to 0.32: at this length the log-L1 lobe loss and relMSE disagree.

Both runs go through :func:`denoisebench.models.training.train`, the code behind
``denoisebench train``; their checkpoints land in ``OUT/dpcn.pt`` and ``OUT/kpcn.pt`` (resume
them with ``denoisebench train --resume``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.models.training import train  # noqa: E402
from denoisebench.models.training_options import TrainOptions, command_line  # noqa: E402

MODELS = ("dpcn", "kpcn")


def steps_to_reach(history: list[list[float]], target: float) -> int | None:
    """First step of a ``[[step, value], ...]`` history whose value is at or below ``target`` (None: never)."""
    for step, value in history:
        if value is not None and value <= target:
            return int(step)
    return None


def _speedup(runs: dict, key: str, target: float | None) -> tuple[dict, float | None]:
    """Steps each model needs for its ``key`` history to reach ``target``, and DPCN's over KPCN's."""
    reach = {m: (steps_to_reach(runs[m][key], target) if target is not None else None) for m in MODELS}
    return reach, (reach["dpcn"] / reach["kpcn"] if reach["dpcn"] and reach["kpcn"] else None)


def compare(
    data: str,
    out: str,
    config: str = "small",
    steps: int = 2000,
    val_every: int = 100,
    loss: str = "lobes",
    lr: float = 1e-3,
    batch_size: int = 8,
    crop: int = 32,
    seed: int = 0,
    device: str = "auto",
    threads: int = 1,
    val_frames: int = 8,
    progress: bool = True,
    plot: bool = True,
) -> dict:
    """Train DPCN and KPCN alike and return ``{"runs": {model: {...}}, "target", "steps_to_target", "speedup"}``."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    runs = {}
    for model in MODELS:
        options = TrainOptions(
            model=model,
            data=data,
            config=config,
            steps=steps,
            out=str(folder / f"{model}.pt"),
            seed=seed,
            batch_size=batch_size,
            crop=crop,
            lr=lr,
            loss=loss,
            val_every=val_every,
            val_frames=val_frames,
            checkpoint_every=0,
            threads=threads,
            device=device,
            progress=progress,
        )
        meta = train(options)
        # the final validation closes the curve (val_every validates only strictly before the end)
        validation = list(meta.get("validation_history", [])) + [
            [meta["steps"], (meta.get("validation") or {}).get("relmse")]
        ]
        runs[model] = {
            "command": command_line(options, options.out),
            "seconds": meta["seconds"],
            "loss_history": meta["history"],
            "validation_history": validation,
            "validation_noisy": (meta.get("validation") or {}).get("relmse_noisy"),
        }
    finals = [v for _, v in runs["dpcn"]["validation_history"] if v is not None]
    target = min(finals) if finals else None
    reach, speedup = _speedup(runs, "validation_history", target)
    loss_target = runs["dpcn"]["loss_history"][-1][1] if runs["dpcn"]["loss_history"] else None
    loss_reach, loss_speedup = _speedup(runs, "loss_history", loss_target)
    result = {
        "data": str(data),
        "config": config,
        "steps": steps,
        "loss": loss,
        "lr": lr,
        "runs": runs,
        "target": target,
        "steps_to_target": reach,
        "speedup": speedup,
        "loss_target": loss_target,
        "steps_to_loss_target": loss_reach,
        "loss_speedup": loss_speedup,
    }
    (folder / "curves.json").write_text(json.dumps(result, indent=2))
    if plot:
        _plot(result, folder / "curves.png")
    return result


def _plot(result: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for model, run in result["runs"].items():
        if run["loss_history"]:
            left.plot(*zip(*run["loss_history"]), label=model)
        points = [(s, v) for s, v in run["validation_history"] if v is not None]
        if points:
            right.plot(*zip(*points), marker="o", label=model)
    noisy = result["runs"]["dpcn"]["validation_noisy"]
    if noisy:
        right.axhline(noisy, color="gray", linestyle="--", label="noisy input")
    left.set(title=f"training loss ({result['loss']}, running mean)", xlabel="step", yscale="log")
    right.set(title="validation relMSE (val split)", xlabel="step", yscale="log")
    for axis in (left, right):
        axis.legend()
    figure.suptitle(f"DPCN vs KPCN, {result['config']} configuration (same shape, seed, batches, lr {result['lr']})")
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True, help="dataset folder (generate-dataset output)")
    parser.add_argument("--out", default="bench_out/pcn_convergence", help="output folder")
    parser.add_argument("--config", default="small", choices=("small", "paper"))
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--val-every", type=int, default=100)
    parser.add_argument("--loss", default="lobes", choices=("log", "relative", "lobes", "exposure"))
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--batch-size", type=int, default=8)
    parser.add_argument("--crop", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--val-frames", type=int, default=8)
    parser.add_argument("--quiet", action="store_true")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.val_every < 1:
        print("error: --steps and --val-every must be >= 1", file=sys.stderr)
        return 2
    result = compare(
        args.data,
        args.out,
        args.config,
        args.steps,
        args.val_every,
        args.loss,
        args.lr,
        args.batch_size,
        args.crop,
        args.seed,
        args.device,
        args.threads,
        args.val_frames,
        progress=not args.quiet,
    )
    for model, run in result["runs"].items():
        print(f"{model}: {run['seconds']:.0f} s, validation relMSE by step {run['validation_history']}")
    print(
        f"steps to reach DPCN's final training loss {result['loss_target']}: {result['steps_to_loss_target']}; "
        f"KPCN speed-up {result['loss_speedup']}"
    )
    print(
        f"steps to reach DPCN's best val relMSE {result['target']}: {result['steps_to_target']}; "
        f"KPCN speed-up {result['speedup']}"
    )
    print(f"wrote {Path(args.out) / 'curves.json'} and curves.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
