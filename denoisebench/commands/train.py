"""Train a learned denoiser (dpcn, kpcn, rae or lbf) on a dataset made by generate-dataset.

Trains on the dataset's train split (random crops, flips and rotations; K-frame windows for the
recurrent autoencoder), validates on whole frames of its val split, and writes a checkpoint with
its metadata: model and configuration, dataset config hash, steps, seed, training seconds and the
validation relMSE next to the noisy input's. The same command with --resume CKPT continues a run
exactly where it stopped (same seed, same batches), on the dataset it was trained on; --init-from
CKPT fine-tunes a checkpoint's weights (shipped weights too) on another dataset with a fresh
optimiser, and its card then lists both datasets, every command and every stage.

Options left out take the configuration's recipe (lbf: --loss relmse, the paper's relative MSE),
then the defaults below. --device auto trains on a CUDA GPU when torch sees one (loader workers
and pinned memory there), else on the CPU with --threads threads (up to the core count).

--evaluate additionally scores the trained model on the test split against the identity and
cross_bilateral denoisers (relMSE, mean over frames), as the shipped model cards report.
--ship with --third-party DIR also scores the shipped weights on datasets of scenes nobody here
wrote (pooled; beside the noisy input, cross_bilateral and OIDN, at every spp they have) and puts
that section in the card (denoisebench.study.card_scores).

Exit codes: 0 done, 2 bad input (unknown model, no such dataset, empty train split, a checkpoint
of another model), 1 internal failure.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from denoisebench.analysis.aggregate import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED, bootstrap_over_scenes
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.reader import open_dataset
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.runner import run_sequence
from denoisebench.errors import UserInputError
from denoisebench.metrics.ours.spatial import relmse
from denoisebench.models.card import render_card
from denoisebench.models.names import MODEL_NAMES

# Lazy imports: the models and the trainer (torch: 1 s) only when a model is trained or shipped, so
# that --help stays quick.

EPILOG = """examples:
  denoisebench train --model kpcn --data data/small --config small --steps 2000 --out kpcn.pt
  denoisebench train --model lbf --data data/small --steps 600 --lr-schedule cosine --val-every 200 --out lbf.pt
  denoisebench train --model kpcn --data data/big --config paper --device cuda --batch-size 32 --crop 64
  denoisebench train --model kpcn --data data/small --steps 1000 --resume kpcn.pt --out kpcn.pt
  denoisebench train --model rae --data data/small --set residual=false --out rae_direct.pt   # an ablation
  denoisebench train --model dpcn --data data/mine --steps 3000 --lr 1e-4 --loss relmse --init-from denoisebench/models/weights/dpcn_small.pt --out d.pt
  denoisebench train --model dpcn --data data/mine --steps 0 --resume denoisebench/models/weights/dpcn_small.pt --out d.pt --evaluate
  denoisebench train --model rae --data data/small --steps 0 --resume rae.pt --out rae.pt --evaluate
  denoisebench train --model kpcn --data data/small --steps 0 --resume kpcn.pt --out kpcn.pt --ship weights/ \
      --third-party data/tp_docs --third-party data/tp_usd   # the card also scores scenes nobody here wrote
  denoisebench benchmark --data data/small --denoisers kpcn --option kpcn:checkpoint=kpcn.pt   # use the result

documentation:
  docs/training.md  training the learned denoisers; the shipped weights' model cards
                    (denoisebench/models/weights/*.md)
"""


def _spp(text: str | None):
    if text is None:
        return None
    try:
        values = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise UserInputError(f"--spp expects comma-separated integers like 4,8 (got {text!r})") from None
    if not values or min(values) < 1:
        raise UserInputError(f"--spp expects positive integers (got {text!r})")
    return values


def add_arguments(parser) -> None:
    parser.add_argument("--model", required=True, choices=MODEL_NAMES, help="which network to train")
    parser.add_argument("--data", required=True, help="dataset folder (dataset.json inside)")
    parser.add_argument(
        "--config",
        default="small",
        choices=("small", "paper"),
        help="network size: small (trains on a CPU) or paper (default small)",
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        dest="overrides",
        help="replace one key of the configuration for this run, e.g. residual=false "
        "(repeatable; VALUE is JSON; the checkpoint records the result)",
    )
    parser.add_argument("--steps", type=int, default=500, help="optimisation steps to add (default 500)")
    parser.add_argument("--out", default=None, help="checkpoint to write (default checkpoints/MODEL_CONFIG.pt)")
    parser.add_argument(
        "--resume",
        default=None,
        metavar="CKPT",
        help="continue from this checkpoint; with --steps 0 also shipped weights, to score them "
        "(--evaluate/--ship) on another dataset",
    )
    parser.add_argument(
        "--init-from",
        default=None,
        metavar="CKPT",
        help="fine-tune: start from this checkpoint's weights (shipped weights too) and step count "
        "with a fresh optimiser, on --data (which may differ from the checkpoint's)",
    )
    parser.add_argument("--seed", type=int, default=0, help="initialisation and batch-order seed (default 0)")
    parser.add_argument("--batch-size", type=int, default=8, help="crops per step (default 8)")
    parser.add_argument(
        "--crop",
        type=int,
        default=None,
        help="crop side in pixels, capped by the smallest train scene (default: the recipe's, rae paper 128; else 32)",
    )
    parser.add_argument(
        "--play-backward",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="rae: play each training window backwards half the time (default: on in both configurations' recipes)",
    )
    parser.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (default 1e-3)")
    parser.add_argument("--spp", default=None, help="train on these noisy spp only, e.g. 4 (default all)")
    parser.add_argument(
        "--sequence-length", type=int, default=7, help="frames per training window, rae only (default 7)"
    )
    parser.add_argument(
        "--loss",
        default=None,
        choices=("log", "relative", "relmse", "lobes", "exposure"),
        help="spatial loss: log = L1 of log(1+x); relative adds |p-r|/(r+0.01); relmse = "
        "(p-r)^2/(r^2+0.01); lobes = separate diffuse/specular L1 (dpcn/kpcn); exposure = log "
        "after dividing by the input's exposure, so dark scenes count (dpcn/kpcn) "
        "(default: the configuration's recipe, else log)",
    )
    parser.add_argument(
        "--lr-schedule",
        default="constant",
        choices=("constant", "cosine", "step"),
        help="learning rate over this command's steps: constant, cosine (to lr/100) or "
        "step (x0.1 at 1/2 and 3/4) (default constant)",
    )
    parser.add_argument(
        "--val-every",
        type=int,
        default=0,
        help="also validate every N steps (recorded in the checkpoint; default 0: only at the end)",
    )
    parser.add_argument(
        "--device",
        default="auto",
        choices=("auto", "cpu", "cuda"),
        help="auto: CUDA when torch sees a GPU, else CPU (default auto)",
    )
    parser.add_argument(
        "--workers", type=int, default=None, help="data loader processes (default 0 on the CPU, up to 4 on CUDA)"
    )
    parser.add_argument("--checkpoint-every", type=int, default=100, help="save every N steps (default 100)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads, 1 to the core count (default 1)")
    parser.add_argument("--evaluate", action="store_true", help="also score on the test split against the --peers")
    parser.add_argument(
        "--peers",
        default="identity,cross_bilateral",
        help="denoisers --evaluate/--ship compare against, comma-separated (default identity,cross_bilateral; "
        "e.g. add oidn)",
    )
    parser.add_argument(
        "--ship",
        default=None,
        metavar="DIR",
        help="implies --evaluate; write DIR/MODEL_CONFIG.pt (no optimiser state) and its model card DIR/MODEL_CONFIG.md",
    )
    parser.add_argument(
        "--third-party",
        action="append",
        default=[],
        metavar="DIR",
        help="with --ship: also score the weights on this dataset of third-party scenes (e.g. made by "
        "generate --scene-list) beside the noisy input, cross_bilateral and OIDN at every spp, and put the "
        "scores in the card; repeat it to pool several datasets",
    )
    parser.add_argument(
        "--third-party-out",
        default=None,
        metavar="DIR",
        help="folder of --third-party's results store and scores (resumable; default: third_party_runs beside "
        "the checkpoint, never the --ship folder)",
    )
    parser.add_argument(
        "--train-scenes",
        default=None,
        metavar="A,B,...",
        help="train on these scenes of --data instead of its train split (not its val scenes), e.g. "
        "cornell_000,cornell_001 (default: the train split)",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args) -> int:
    if args.steps < 0:
        raise UserInputError(f"--steps must be >= 0 (got {args.steps})")
    if args.batch_size < 1 or (args.crop is not None and args.crop < 4):
        raise UserInputError("--batch-size must be >= 1 and --crop >= 4")
    from denoisebench.models.training import train
    from denoisebench.models.training_options import TrainOptions, max_threads, parse_override

    if not 1 <= args.threads <= max_threads():
        raise UserInputError(f"--threads must be between 1 and the core count {max_threads()} (got {args.threads})")
    if args.val_every < 0 or (args.workers is not None and args.workers < 0):
        raise UserInputError("--val-every and --workers must be >= 0")
    peers = tuple(name.strip() for name in args.peers.split(",") if name.strip())
    if not peers or args.model in peers:
        raise UserInputError(f"--peers must name at least one other denoiser (got {args.peers!r})")
    if not (Path(args.data) / "dataset.json").is_file():
        raise UserInputError(f"{args.data}: not a dataset folder (no dataset.json)")
    if args.third_party:
        if not args.ship:
            raise UserInputError("--third-party puts scores in the model card: give --ship DIR too")
        from denoisebench.study.data_value import open_third_party

        open_third_party(args.third_party)  # before training: a wrong folder costs nothing

    options = TrainOptions(
        model=args.model,
        data=args.data,
        config=args.config,
        steps=args.steps,
        out=args.out,
        resume=args.resume,
        init_from=args.init_from,
        seed=args.seed,
        batch_size=args.batch_size,
        crop=args.crop,
        lr=args.lr,
        spp=_spp(args.spp),
        sequence_length=args.sequence_length,
        play_backward=args.play_backward,
        loss=args.loss,
        checkpoint_every=args.checkpoint_every,
        threads=args.threads,
        device=args.device,
        workers=args.workers,
        lr_schedule=args.lr_schedule,
        val_every=args.val_every,
        progress=not args.quiet,
        overrides=dict(parse_override(text) for text in args.overrides),
        train_scenes=None
        if args.train_scenes is None
        else tuple(name.strip() for name in args.train_scenes.split(",") if name.strip()),
    )
    try:
        meta = train(options)
    except DatasetError as error:
        raise UserInputError(str(error)) from None
    validation = meta.get("validation") or {}
    summary = f"{meta['checkpoint']}: {args.model} ({args.config}), {meta['steps']} steps, {meta['seconds']:.0f} s"
    if validation:
        summary += (
            f"; val relMSE {validation['relmse']:.5f} (noisy {validation['relmse_noisy']:.5f},"
            f" ratio {validation['relmse_ratio']:.3f})"
        )
    else:
        summary += "; no val split to validate on"
    print(summary)
    if args.evaluate or args.ship:
        table = evaluate_on_split(
            meta["checkpoint"],
            args.model,
            args.data,
            split="test",
            threads=args.threads,
            peers=peers,
            progress=not args.quiet,
        )
        print(json.dumps(table, indent=2))
        if args.ship:
            print(ship(meta["checkpoint"], args, table))
    return 0


def ship(checkpoint: str, args, evaluation: dict) -> str:
    """Write the stripped weights and the model card into ``args.ship``; return a one-line summary."""
    from denoisebench.models.catalog import model_config, parameter_count
    from denoisebench.models.checkpoint import load_checkpoint, model_from_checkpoint
    from denoisebench.models.training import strip_for_shipping

    folder = Path(args.ship)
    stem = f"{args.model}_{args.config}"
    weights = strip_for_shipping(checkpoint, folder / f"{stem}.pt")
    payload = load_checkpoint(weights)
    sections = None
    if args.third_party:
        from denoisebench.study.card_scores import card_section, score_checkpoint

        out = Path(args.third_party_out) if args.third_party_out else Path(checkpoint).parent / "third_party_runs"
        record = score_checkpoint(args.model, weights, args.third_party, out, progress=not args.quiet)
        (out / f"{stem}.third_party.json").write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
        sections = card_section(args.model, record)
    card = render_card(
        args.model,
        args.config,
        payload["config"],
        parameter_count(model_from_checkpoint(payload)),
        weights.name,
        weights.stat().st_size,
        payload["meta"],
        evaluation,
        list(payload["meta"].get("commands", [])),
        args.data,
        named_config=model_config(args.model, args.config),
        sections=sections,
    )
    (folder / f"{stem}.md").write_text(card)
    return f"shipped {weights} ({weights.stat().st_size / 1024:.0f} KiB) and {folder / f'{stem}.md'}"


def evaluate_on_split(
    checkpoint: str,
    model: str,
    data: str,
    split: str = "test",
    threads: int = 1,
    peers=("identity", "cross_bilateral"),
    progress: bool = True,
) -> dict:
    """relMSE (mean over frames, every noisy spp) of the checkpoint and of ``peers`` on a split.

    Sequences go through :func:`~denoisebench.denoisers.runner.run_sequence` (reset, frames in
    order), so the recurrent model is scored as the benchmark scores it. Returns
    ``{"split", "scenes", "frames", "relmse": {name: value}, "ratio": {peer: ours / peer},
    "relmse_ci95": {name: [lo, hi]}, "ratio_ci95": {peer: [lo, hi]}, "bootstrap": {...}}``: the
    intervals are 95% percentile bootstraps over scenes
    (:func:`denoisebench.analysis.aggregate.bootstrap_over_scenes`, the analyses' resamples and seed).
    """
    ds = open_dataset(data)
    scenes = ds.split(split)
    if not scenes:
        raise UserInputError(f"{data}: split {split!r} is empty")
    denoisers = {model: load_denoiser(model, checkpoint=checkpoint, threads=threads)}
    denoisers.update({name: load_denoiser(name) for name in peers})
    scores: dict[str, list[float]] = {name: [] for name in denoisers}
    frame_scene: list[str] = []
    per_spp: dict[str, dict[int, list[float]]] = {name: {} for name in denoisers}
    jobs = [(scene, spp) for scene in scenes for spp in ds.scene(scene).spp]
    for scene, spp in tqdm(jobs, desc=f"evaluate {split}", disable=not progress):
        sequence = ds.sequence(scene, spp)
        frame_scene += [scene] * len(sequence)
        for name, denoiser in denoisers.items():
            for frame, result in zip(sequence, run_sequence(denoiser, sequence, name=name)):
                if not result.ok:
                    raise RuntimeError(f"{name} failed on {scene} frame {frame.index}: {result.error}")
                value = relmse(result.output, frame.reference)
                scores[name].append(value)
                per_spp[name].setdefault(spp, []).append(value)
    means = {name: float(np.mean(values)) for name, values in scores.items()}
    intervals, ratio_intervals = bootstrap_over_scenes(scores, frame_scene, model, list(peers))
    return {
        "split": split,
        "scenes": scenes,
        "frames": len(scores[model]),
        "relmse": means,
        "relmse_by_spp": {
            name: {str(s): float(np.mean(v)) for s, v in sorted(d.items())} for name, d in per_spp.items()
        },
        "ratio": {peer: means[model] / means[peer] for peer in peers},
        "relmse_ci95": intervals,
        "ratio_ci95": ratio_intervals,
        "bootstrap": {"resamples": BOOTSTRAP_RESAMPLES, "unit": "scene", "seed": BOOTSTRAP_SEED},
    }


if __name__ == "__main__":  # pragma: no cover
    sys.exit(run(None))
