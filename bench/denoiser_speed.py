"""Seconds per megapixel of every baseline, against OIDN measured in the same run, and our
cross-bilateral filter against scikit-image's ``denoise_bilateral`` on the same image and window.

    .venv/bin/python bench/denoiser_speed.py [--size 256] [--rpf-size 128] [--rpf-spp 4,8] [--rpf-baseline REV]
                                             [--spp 4] [--radius 7] [--repeats 3] [--rpf-only] [--rpf-data DIR]

Frames are synthetic (``denoisebench.denoisers.synthetic``, textured family) with features and
per-sample data. Each denoiser runs through the harness runner (:func:`run_frame`), which times
``denoise()`` alone; the figure is the minimum over ``--repeats`` calls after one warm-up.
The machine's load average (1, 5, 15 min) is printed before and after: on a shared machine the
wall-clock figures move with it (2x between load 1 and load 6 here).
RPF is timed on a ``--rpf-size`` frame at each ``--rpf-spp`` (its per-sample work makes the full size
slow on two cores); seconds per megapixel put both sizes on one scale, and OIDN is timed on each of
those frames too so its ratio compares like with like. RPF's relMSE against the frame's reference is
printed beside its time, for the paper settings (``rpf``) and the ``rpf_fast`` preset.
``--rpf-baseline REV`` also times ``denoisebench/baselines/rpf.py`` as it was at git revision REV (e.g. the commit before a change) on the same frames, in the same run:
"x faster" and the quality of both are then measured under the same load. ``--rpf-data DIR`` times
RPF (and the baseline, and OIDN) on rendered frames instead: frame 0 of every scene of a dataset made
with ``generate-dataset --samples`` at each of its spp (the kind of frame the issue's figures came
from: rendered scenes' per-sample data, not the synthetic family's).

The bilateral comparison uses colour only (scikit-image's filter knows no feature buffers), the
same square window of 2·radius+1 pixels and the same σ_spatial: ours with the full 2-D window
(``separable=False``, no firefly pre-pass, exactly the work the formula asks for) and our
separable default preset, both against ``denoise_bilateral(win_size=2·radius+1)``. Target: ours ≥ 10×.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import timeit
import types
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.baselines.cross_bilateral import cross_bilateral_filter  # noqa: E402
from denoisebench.denoisers.registry import load_denoiser  # noqa: E402
from denoisebench.denoisers.runner import run_frame  # noqa: E402
from denoisebench.denoisers.synthetic import synthetic_frame  # noqa: E402
from denoisebench.metrics.ours.spatial import relmse  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

BASELINES = (
    "identity",
    "cross_bilateral_fast",
    "cross_bilateral",
    "cross_bilateral_high",
    "nlmeans",
    "oidn_fast",
    "oidn_balanced",
    "oidn",
)


def seconds_in_denoise(name, frame, repeats: int, with_output: bool = False):
    """Minimum seconds inside ``denoise()`` over ``repeats`` runner calls, after one warm-up
    (``name``: a registered name or a denoiser object); with ``with_output`` also the output."""
    denoiser = load_denoiser(name) if isinstance(name, str) else name
    warm = run_frame(denoiser, frame, keep_output=with_output)
    if not warm.ok:
        raise SystemExit(f"{name} failed: {warm.error}")
    seconds = min(run_frame(denoiser, frame, keep_output=False).seconds for _ in range(repeats))
    return (seconds, warm.output) if with_output else seconds


def rpf_at_revision(revision: str):
    """A RandomParameterFilter built from ``denoisebench/baselines/rpf.py`` as of git ``revision``."""
    try:
        source = subprocess.run(
            ["git", "show", f"{revision}:denoisebench/baselines/rpf.py"],
            cwd=ROOT,
            check=True,
            capture_output=True,
            text=True,
        ).stdout
    except (OSError, subprocess.CalledProcessError) as error:
        raise SystemExit(f"--rpf-baseline {revision}: cannot read rpf.py there ({error})") from None
    module = types.ModuleType(f"rpf_at_{revision}")
    module.__package__ = "denoisebench.baselines"  # its relative imports resolve against today's package
    sys.modules[module.__name__] = module  # dataclasses look their module up there
    exec(compile(source, f"rpf.py@{revision}", "exec"), module.__dict__)  # noqa: S102 - our own history
    return module.RandomParameterFilter()


def dataset_frames(path: str):
    """(scene, spp, frame 0) for every scene and spp of a dataset with per-sample data."""
    from denoisebench.dataset.reader import open_dataset  # noqa: PLC0415

    dataset = open_dataset(path)
    for scene in dataset.scenes:
        for spp in dataset.scene(scene).spp:
            frame = dataset.frame(scene, spp, 0)
            if frame.samples is None:
                raise SystemExit(f"--rpf-data {path}: {scene} has no per-sample data (generate it with --samples)")
            yield scene, spp, frame


def load_average() -> str:
    """The 1, 5 and 15 minute load averages, or "unknown" where the OS does not say."""
    try:
        return " ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "unknown"


def best_of(fn, repeats: int) -> float:
    """Minimum seconds of ``repeats`` calls after one warm-up call."""
    fn()
    return min(timeit.repeat(fn, number=1, repeat=repeats))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--rpf-size", type=int, default=128)
    parser.add_argument("--rpf-spp", default="4,8", help="comma-separated spp of the RPF frames")
    parser.add_argument("--rpf-baseline", metavar="REV", help="also time rpf.py as of this git revision")
    parser.add_argument("--rpf-only", action="store_true", help="time OIDN and RPF only (no other baselines)")
    parser.add_argument(
        "--rpf-data",
        metavar="DIR",
        help="time RPF on frame 0 of every scene of this dataset (made with --samples) instead of synthetic frames",
    )
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--radius", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)

    frame = synthetic_frame("textured", args.size, args.size, args.spp, seed=0, samples=False)
    try:
        rpf_spps = [int(v) for v in args.rpf_spp.split(",") if v.strip()]
    except ValueError:
        parser.error(f"--rpf-spp: comma-separated integers expected, got {args.rpf_spp!r}")
    megapixels = args.size * args.size / 1e6

    names = ("oidn",) if args.rpf_only else BASELINES
    per_mp = {name: seconds_in_denoise(name, frame, args.repeats) / megapixels for name in names}
    oidn = per_mp["oidn"]

    print("load average before: " + load_average())
    print(
        f"denoiser speed: {args.size}x{args.size} px, {args.spp} spp (rpf: {args.rpf_size}x{args.rpf_size} at "
        f"{args.rpf_spp} spp); min of {args.repeats} after a warm-up"
    )
    print(f"{'denoiser':<22}{'s/MP':>10}{'x OIDN (high)':>16}")
    for name, value in per_mp.items():
        print(f"{name:<22}{value:>10.3f}{value / oidn:>16.3f}")

    baseline = rpf_at_revision(args.rpf_baseline) if args.rpf_baseline else None
    if args.rpf_data:
        cases = list(dataset_frames(args.rpf_data))
        print(f"\nrpf on frame 0 of every scene of {args.rpf_data} (OIDN timed on the same frame):")
    else:
        cases = [
            (
                f"textured {args.rpf_size}x{args.rpf_size}",
                spp,
                synthetic_frame("textured", args.rpf_size, args.rpf_size, spp, seed=0, samples=True),
            )
            for spp in rpf_spps
        ]
        print(f"\nrpf, textured {args.rpf_size}x{args.rpf_size} px (OIDN timed on the same frame):")
    presets = ("rpf", "rpf_fast")  # the paper settings and the 48-draw preset
    totals = dict.fromkeys(presets + ("old",), 0.0)
    for label, spp, small in cases:
        small_megapixels = small.color.shape[0] * small.color.shape[1] / 1e6
        oidn_small = seconds_in_denoise("oidn", small, args.repeats) / small_megapixels
        noisy = relmse(small.color, small.reference)
        print(f"  {label}, {spp} spp (input relMSE {noisy:.4f}, OIDN {oidn_small:.3f} s/MP):")
        per_mp = {}
        for name in presets:
            seconds, image = seconds_in_denoise(name, small, args.repeats, with_output=True)
            per_mp[name] = seconds / small_megapixels
            totals[name] += seconds
            print(
                f"    {name:<12}{per_mp[name]:9.2f} s/MP  {per_mp[name] / oidn_small:8.1f}x OIDN  "
                f"relMSE {relmse(image, small.reference):.4f}"
            )
        if baseline is not None:
            old_seconds, old_image = seconds_in_denoise(baseline, small, args.repeats, with_output=True)
            old = old_seconds / small_megapixels
            totals["old"] += old_seconds
            faster = ", ".join(f"{name} {old / per_mp[name]:.1f}x" for name in presets)
            print(
                f"    {'rpf@' + args.rpf_baseline:<12}{old:9.2f} s/MP  {old / oidn_small:8.1f}x OIDN  "
                f"relMSE {relmse(old_image, small.reference):.4f}  -> faster today: {faster}"
            )
    if baseline is not None and len(cases) > 1:
        faster = ", ".join(f"{name} {totals['old'] / totals[name]:.1f}x" for name in presets)
        print(f"  all frames: rpf@{args.rpf_baseline} {totals['old']:.2f} s; faster today: {faster}")
    if args.rpf_only:
        print("load average after: " + load_average())
        return 0

    from skimage.restoration import denoise_bilateral

    color = np.maximum(np.asarray(frame.color, np.float32), 0.0)
    sigma_spatial = args.radius / 2.0
    window = 2 * args.radius + 1
    skimage_seconds = best_of(
        lambda: denoise_bilateral(color, win_size=window, sigma_spatial=sigma_spatial, channel_axis=-1), args.repeats
    )
    full_seconds = best_of(
        lambda: cross_bilateral_filter(
            color,
            {},
            color_variance=frame.buffers["color_var"],
            radius=args.radius,
            sigma_spatial=sigma_spatial,
            feature_sigmas={},
            separable=False,
            firefly_support=None,
        ),
        args.repeats,
    )
    separable_seconds = best_of(
        lambda: cross_bilateral_filter(
            color,
            {},
            color_variance=frame.buffers["color_var"],
            radius=args.radius,
            sigma_spatial=sigma_spatial,
            feature_sigmas={},
            separable=True,
        ),
        args.repeats,
    )
    print(
        f"\nbilateral, colour only, {window}x{window} window, sigma_spatial {sigma_spatial:g}, {args.size}x{args.size} px:"
    )
    print(f"  skimage denoise_bilateral   {skimage_seconds:8.3f} s")
    print(
        f"  ours, full 2-D window       {full_seconds:8.3f} s   skimage/ours = {skimage_seconds / full_seconds:6.1f}x"
    )
    print(
        f"  ours, separable (default)   {separable_seconds:8.3f} s   skimage/ours = {skimage_seconds / separable_seconds:6.1f}x"
        "   (target >= 10x)"
    )
    print("load average after: " + load_average())
    return 0


if __name__ == "__main__":
    sys.exit(main())
