"""CPU inference seconds per megapixel of the learned denoisers (dpcn, kpcn, rae), against OIDN
(the ``oidn`` built-in, quality high) measured in the same run on the same frame.

    .venv/bin/python bench/model_speed.py [--size 256] [--repeats 3] [--threads 1,2] [--paper]

The frame is synthetic (``denoisebench.denoisers.synthetic``, textured family, 4 spp, no
per-sample data). Every denoiser runs through the harness runner (:func:`run_frame`), which
times ``denoise()`` alone; the figure is the minimum over ``--repeats`` calls after one warm-up.
The small configurations run with their shipped weights; ``--paper`` also times the paper-size
networks (9 × 100 × 5×5 PCNs, the 5-level autoencoder) with randomly initialised weights, whose
cost is the same as trained ones. OIDN uses its own thread pool (every core), our models
``--threads`` torch threads; the ratio column is model / OIDN (above 1: slower than OIDN).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import torch  # noqa: E402

from denoisebench.denoisers.registry import load_denoiser  # noqa: E402
from denoisebench.denoisers.runner import run_frame  # noqa: E402
from denoisebench.denoisers.synthetic import synthetic_frame  # noqa: E402
from denoisebench.models.catalog import build_model, model_config  # noqa: E402
from denoisebench.models.checkpoint import save_checkpoint  # noqa: E402

MODELS = ("dpcn", "kpcn", "rae")


def seconds(denoiser, frame, repeats: int) -> float:
    """Minimum time inside denoise() over ``repeats`` calls after a warm-up (reset between calls)."""
    best = float("inf")
    for _ in range(repeats + 1):
        if hasattr(denoiser, "reset"):
            denoiser.reset()
        result = run_frame(denoiser, frame, keep_output=False)
        if not result.ok:
            raise SystemExit(f"{getattr(denoiser, 'name', denoiser)} failed: {result.error}")
        best = min(best, result.seconds)
    return best


def paper_checkpoint(model: str, folder: Path) -> str:
    torch.manual_seed(0)
    config = model_config(model, "paper")
    path = folder / f"{model}_paper_random.pt"
    save_checkpoint(path, model, config, build_model(model, config), {"note": "random weights, for timing"})
    return str(path)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=256, help="frame side in pixels (default 256)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", default="1,2", help="torch thread counts to time (default 1,2)")
    parser.add_argument("--paper", action="store_true", help="also time the paper-size configurations")
    args = parser.parse_args()
    threads = [int(t) for t in args.threads.split(",")]
    frame = synthetic_frame("textured", width=args.size, height=args.size, spp=4, seed=1, samples=False)
    megapixels = args.size * args.size / 1e6

    oidn = seconds(load_denoiser("oidn"), frame, args.repeats)
    print(f"frame {args.size}×{args.size} ({megapixels:.4f} MP), torch {torch.__version__}, min of {args.repeats}")
    print(f"{'denoiser':<24}{'threads':>8}{'s/frame':>12}{'s/MP':>12}{'× OIDN':>10}")
    print(f"{'oidn (high)':<24}{'all':>8}{oidn:>12.4f}{oidn / megapixels:>12.3f}{1.0:>10.2f}")
    with tempfile.TemporaryDirectory() as tmp:
        variants = [(f"{m} small (shipped)", m, None) for m in MODELS]
        if args.paper:
            variants += [(f"{m} paper (random)", m, paper_checkpoint(m, Path(tmp))) for m in MODELS]
        for label, model, checkpoint in variants:
            for count in threads:
                denoiser = load_denoiser(model, checkpoint=checkpoint, threads=count)
                t = seconds(denoiser, frame, args.repeats)
                print(f"{label:<24}{count:>8}{t:>12.4f}{t / megapixels:>12.3f}{t / oidn:>10.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
