"""Seconds per megapixel-frame of the field's metrics: cvvdp, msssim and the Noisebase set.

    .venv/bin/python bench/field_metrics_speed.py [--sizes 64,128,256] [--frames 8] [--repeats 2]

ColorVideoVDP is the costly one (a Laplacian pyramid of every frame in four channels, temporal
filters over 250 ms, a masking model): it is timed over whole sequences (T frames of size²) and
reported per megapixel-frame (seconds / (T · size² / 10⁶)), after one warm-up call that loads the
model (its load time is printed apart). msssim and the Noisebase spatial metrics are per frame;
nb_tpsnr/nb_trmae per sequence. Also prints what cvvdp would add to a run of U units (a unit = one
denoiser on one scene at one spp) of the demo's size: ``--units`` (default 112 = 4 scenes x 2 spp x
14 rows, the demo with every built-in denoiser). Minimum over repeats; the machine's other load shows.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.metrics import get_metric  # noqa: E402
from denoisebench.metrics.field.colorvideovdp import cvvdp  # noqa: E402


def make_sequence(size: int, frames: int, seed: int = 0):
    """A panning textured plane (2 px per frame) and a noisy prediction, float32 linear radiance."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0 : size + 2 * frames].astype(np.float32)
    plane = np.stack([0.6 + 0.5 * np.sin(0.15 * xx + c) * np.cos(0.11 * yy) for c in range(3)], -1)
    ref = np.stack([plane[:, 2 * k : 2 * k + size] for k in range(frames)]).astype(np.float32)
    pred = np.clip(ref + rng.normal(0, 0.08, ref.shape).astype(np.float32), 0, None)
    return pred, ref


def best_of(fn, repeats: int) -> tuple[float, float]:
    best, value = float("inf"), None
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn()
        best = min(best, time.perf_counter() - t0)
    return best, value


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="64,128,256", help="image sides, comma-separated (default 64,128,256)")
    parser.add_argument("--frames", type=int, default=8, help="frames per sequence (default 8)")
    parser.add_argument("--repeats", type=int, default=2, help="timed repeats, minimum kept (default 2)")
    parser.add_argument("--units", type=int, default=112, help="units of a run to cost cvvdp for (default 112)")
    args = parser.parse_args(argv)
    try:
        sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        parser.error(f"--sizes must be integers, got {args.sizes!r}")
    if not sizes or min(sizes) < 16 or args.frames < 2 or args.repeats < 1 or args.units < 1:
        parser.error("need sizes ≥ 16, --frames ≥ 2, --repeats ≥ 1, --units ≥ 1")

    import torch

    print(
        f"torch {torch.__version__}, {torch.get_num_threads()} threads; {args.frames} frames; "
        f"min of {args.repeats} repeats"
    )
    p, r = make_sequence(16, 2)
    t0 = time.perf_counter()
    cvvdp(p, r)
    print(f"cvvdp first call (import + model load): {time.perf_counter() - t0:.2f} s")
    print(f"{'metric':<11}{'size':>6}{'value':>10}{'s/call':>10}{'s/MP-frame':>12}")
    for size in sizes:
        pred, ref = make_sequence(size, args.frames)
        mp_frames = args.frames * size * size / 1e6
        cvvdp(pred, ref)  # warm-up at this size (pyramid set-up)
        seconds, value = best_of(lambda: cvvdp(pred, ref), args.repeats)
        print(f"{'cvvdp':<11}{size:>6}{value:>10.4f}{seconds:>10.3f}{seconds / mp_frames:>12.2f}")
        if size == 128:
            print(f"  cvvdp on {args.units} units of {args.frames}×128²: ≈ {seconds * args.units:.0f} s")
        for name in ("msssim", "nb_psnr", "nb_ssim", "nb_msssim", "nb_flip"):
            fn = get_metric(name).fn
            seconds, value = best_of(lambda fn=fn: fn(pred[0], ref[0]), args.repeats)
            print(f"{name:<11}{size:>6}{value:>10.4f}{seconds:>10.4f}{seconds / (size * size / 1e6):>12.3f}")
        for name in ("nb_tpsnr", "nb_trmae"):
            fn = get_metric(name).fn
            seconds, value = best_of(lambda fn=fn: fn(pred, ref), args.repeats)
            print(f"{name:<11}{size:>6}{value:>10.4f}{seconds:>10.4f}{seconds / mp_frames:>12.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
