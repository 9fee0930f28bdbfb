"""Seconds per megapixel of every registered metric, and our wrapper against the library it wraps.

    .venv/bin/python bench/metrics_speed.py [--size 1024] [--frames 3] [--repeats 3]

For SSIM, HDR-FLIP and ΔE2000 the script also times the library called directly on the same
data, prepared the way the library needs it (tone-mapped for SSIM, non-negative float32 for FLIP,
Reinhard-mapped linear sRGB for ΔE2000), once with the preparation done beforehand ("direct") and
once inside the timed call ("direct+prep"), and prints ours / direct (target ≈ 1: the wrapper
adds only validation and that preparation). Timings are the minimum over repeats, ours and direct
interleaved; FLIP runs OpenMP threads, so on a shared machine expect noise of several percent.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench import metrics as M  # noqa: E402
from denoisebench.metrics.tonemap import reinhard, tonemap  # noqa: E402


def make_data(size: int, frames: int, seed: int = 0):
    """A panned HDR plane (smooth structure, fireflies) and a noisy prediction, float32."""
    rng = np.random.default_rng(seed)
    h = w = size
    shift = 2
    yy, xx = np.mgrid[0:h, 0 : w + shift * frames].astype(np.float32)
    plane = np.stack([0.6 + 0.5 * np.sin(0.05 * xx + c) * np.cos(0.04 * yy) for c in range(3)], -1)
    fireflies = rng.random(plane.shape[:2]) < 1e-3
    plane[fireflies] *= 50.0
    ref = np.stack([plane[:, shift * k : shift * k + w] for k in range(frames)]).astype(np.float32)
    pred = np.clip(ref + rng.normal(0, 0.1, ref.shape).astype(np.float32), 0, None)
    motion = np.zeros((frames, h, w, 2), dtype=np.float32)
    motion[..., 0] = shift
    return pred, ref, motion


def best_of(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def paired(ours, direct, repeats: int) -> tuple[float, float]:
    """Interleaved minimum times of two callables (one warm-up call each)."""
    ours()
    direct()
    a = b = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        ours()
        a = min(a, time.perf_counter() - t0)
        t0 = time.perf_counter()
        direct()
        b = min(b, time.perf_counter() - t0)
    return a, b


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=1024, help="image side in pixels (default 1024)")
    parser.add_argument("--frames", type=int, default=3, help="frames for temporal metrics (default 3)")
    parser.add_argument("--repeats", type=int, default=3, help="timed repeats, minimum kept (default 3)")
    args = parser.parse_args(argv)
    if args.size < 16 or args.frames < 2 or args.repeats < 1:
        parser.error("need --size ≥ 16, --frames ≥ 2, --repeats ≥ 1")

    pred_seq, ref_seq, motion = make_data(args.size, args.frames)
    pred, ref = pred_seq[0], ref_seq[0]
    mp = M.megapixels(ref.shape)
    print(
        f"image {args.size}×{args.size} ({mp:.3f} MP), float32, {args.frames} frames for temporal; "
        f"min of {args.repeats} repeats"
    )
    print(f"{'metric':<20}{'value':>12}{'s/call':>10}{'s/MP':>10}")
    for name in M.metric_names():
        m = M.get_metric(name)
        if m.temporal:
            kw = {"motion": motion} if "motion" in m.requires else {}
            call = lambda m=m, kw=kw: m.fn(pred_seq, ref_seq, **kw)  # noqa: E731
            pixels = mp * (args.frames - 1)  # per frame pair
        else:
            call = lambda m=m: m.fn(pred, ref)  # noqa: E731
            pixels = mp
        value = call()
        seconds = best_of(call, args.repeats)
        print(f"{name:<20}{value:>12.5g}{seconds:>10.4f}{seconds / pixels:>10.4f}")
    cost = M.measure_call(M.relmse, pred, ref)
    print(f"peak traced memory of relmse: {cost.peak_bytes / 2**20:.1f} MiB (inputs {2 * ref.nbytes / 2**20:.1f} MiB)")

    print("\nwrapper vs the library called directly (ratio = ours / direct; target ≈ 1)")
    print("  direct: library on data prepared beforehand; direct+prep: preparation inside the timed call")
    print(f"{'metric':<12}{'ours s':>10}{'direct s':>10}{'ratio':>8}{'direct+prep s':>15}{'ratio':>8}")
    import flip_evaluator
    from skimage.metrics import structural_similarity

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour

    def ssim_lib(p, r):
        return structural_similarity(
            p, r, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0, channel_axis=-1
        )

    def flip_lib(p, r):
        return flip_evaluator.evaluate(r, p, "HDR", applyMagma=False)[1]

    white = colour.RGB_COLOURSPACES["sRGB"].whitepoint

    def deltae_lib(p, r):
        lab_p = colour.XYZ_to_Lab(colour.RGB_to_XYZ(p, "sRGB", apply_cctf_decoding=False), white)
        lab_r = colour.XYZ_to_Lab(colour.RGB_to_XYZ(r, "sRGB", apply_cctf_decoding=False), white)
        return colour.delta_E(lab_p, lab_r, method="CIE 2000").mean()

    def f32(a):
        return np.ascontiguousarray(np.clip(a, 0, None), dtype=np.float32)

    for name, ours_fn, lib, prep in (
        ("ssim", M.ssim, ssim_lib, tonemap),
        ("flip", M.flip, flip_lib, f32),
        ("deltae2000", M.deltae2000, deltae_lib, reinhard),
    ):
        pp, rr = prep(pred), prep(ref)
        ours, direct = paired(lambda: ours_fn(pred, ref), lambda: lib(pp, rr), args.repeats)
        _, with_prep = paired(lambda: None, lambda: lib(prep(pred), prep(ref)), args.repeats)
        assert abs(ours_fn(pred, ref) - lib(pp, rr)) < 1e-5, name  # same number
        print(f"{name:<12}{ours:>10.4f}{direct:>10.4f}{ours / direct:>8.3f}{with_prep:>15.4f}{ours / with_prep:>8.3f}")

    prep = best_of(lambda: (tonemap(pred), tonemap(ref)), args.repeats)
    check = best_of(lambda: M.validation.check_pair(pred, ref), args.repeats)
    print(f"\ninside the wrappers: tone map of both images {prep:.4f} s, validation {check:.4f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
