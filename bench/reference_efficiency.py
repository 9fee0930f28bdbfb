"""Our reference against Mitsuba's ``path`` at its defaults: agreement and efficiency, in one run.

The scene is a plain user stage with no denoisebench metadata (tests/support/plain_stages.py: a
Cornell-style box with an area light, diffuse walls, a matte and a rough-metal sphere), or
``--usd FILE``. Both renderers see the same translated Mitsuba scene and camera, box pixel filter.

1. **Agreement** (the issue's "done when"): our reference render (the plan's full transport) and
   Mitsuba ``{"type": "path"}`` at ``--spp`` each; relative difference of the image means and of
   every ``--block``×``--block`` block mean (luminance). Target: mean < 2 %, every block < 8 %.
2. **Efficiency** 1 / (relMSE × seconds) of each at ``--eff-spp``, relMSE against a ground truth of
   Mitsuba ``path`` at ``--truth-spp`` (in replicas, so its own noise floor is known and subtracted
   from both relMSEs: what remains is each renderer's own error). Each renderer is warmed up at the
   same spp (JIT compilation and, for ours, the ``dr.freeze`` recording excluded), then timed
   ``--repeats`` times; the median seconds are used. Efficiency is time-invariant for an unbiased
   estimator (relMSE ∝ 1/time), so equal spp stands in for equal time; the seconds are printed.
   Target ratio ours / path >= 1.0.

    .venv/bin/python bench/reference_efficiency.py [--size 48] [--spp 4096] [--eff-spp 256]
        [--truth-spp 16384] [--block 12] [--repeats 3] [--usd FILE]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from denoisebench.generator.contract.render_plan import make_render_plan  # noqa: E402
from denoisebench.generator.render.frame import render_frame  # noqa: E402
from denoisebench.generator.render.reference import floor_of  # noqa: E402
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict  # noqa: E402
from denoisebench.generator.usd.translate import translate_usd  # noqa: E402
from denoisebench.mitsuba_runtime import load_mitsuba  # noqa: E402

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def relmse(pred: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean(np.square(pred - ref) / (np.square(ref) + 0.01)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--usd", default=None, help="a stage to use instead of the plain box")
    parser.add_argument("--size", type=int, default=48)
    parser.add_argument("--spp", type=int, default=4096, help="spp of the agreement check (default 4096)")
    parser.add_argument("--block", type=int, default=12)
    parser.add_argument("--eff-spp", type=int, default=256, help="spp of the efficiency comparison (default 256)")
    parser.add_argument("--truth-spp", type=int, default=16384, help="ground truth spp, Mitsuba path (default 16384)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args(argv)

    mi = load_mitsuba()
    if args.usd:
        usd = Path(args.usd)
    else:
        from plain_stages import author_plain_box

        usd = author_plain_box(Path(tempfile.mkdtemp(prefix="plain-box-")) / "box.usda")
    translated = translate_usd(usd)
    plan = make_render_plan(translated.effects, stage_max_depth=translated.max_depth)
    scene = build_mitsuba_scene(translated)
    size = args.size
    path = mi.load_dict({"type": "path"})
    print(f"scene {usd} ({size}x{size}); plan: {plan.transport_line()}; Mitsuba {mi.__version__} {mi.variant()}")

    def ours(spp: int, seed: int):
        out = render_frame(
            scene, translated.camera, 0, plan, width=size, height=size, spp=spp, seed=seed, reference=True
        )
        return out.buffers["color"].astype(np.float64), out.seconds

    def theirs(spp: int, seed: int):
        sensor = mi.load_dict(sensor_dict(translated.camera, 0, size, size, spp))
        start = time.perf_counter()
        image = np.array(mi.render(scene, sensor=sensor, integrator=path, seed=seed, spp=spp))[..., :3]
        return image.astype(np.float64), time.perf_counter() - start

    # ---------------------------------------------------------------- agreement
    a, _ = ours(args.spp, 1)
    b, _ = theirs(args.spp, 2)
    la, lb = a @ LUMINANCE, b @ LUMINANCE
    mean_diff = abs(la.mean() - lb.mean()) / lb.mean()
    k = args.block
    h, w = (size // k) * k, (size // k) * k
    ba = la[:h, :w].reshape(h // k, k, w // k, k).mean(axis=(1, 3))
    bb = lb[:h, :w].reshape(h // k, k, w // k, k).mean(axis=(1, 3))
    block_diff = np.abs(ba - bb) / np.maximum(bb, 1e-12)
    print(
        f"agreement at {args.spp} spp: image mean ours {la.mean():.5f} vs path {lb.mean():.5f}: "
        f"{100 * mean_diff:.2f}% (target < 2%); {k}x{k} blocks: max {100 * block_diff.max():.2f}%, "
        f"median {100 * np.median(block_diff):.2f}% (target every block < 8%)"
    )

    # --------------------------------------------------------------- efficiency
    replicas = 16
    per = max(1, args.truth_spp // replicas)
    truth_images = np.stack([theirs(per, 1000 + r)[0] for r in range(replicas)])
    truth = truth_images.mean(axis=0)
    truth_floor = floor_of(truth, truth_images.var(axis=0, ddof=1) / replicas)
    ours(args.eff_spp, 3)  # warm-up: compile and record
    theirs(args.eff_spp, 4)
    o_times, t_times, o_err, t_err = [], [], [], []
    for r in range(args.repeats):
        img, sec = ours(args.eff_spp, 10 + r)
        o_times.append(sec)
        o_err.append(relmse(img, truth) - truth_floor)
        img, sec = theirs(args.eff_spp, 20 + r)
        t_times.append(sec)
        t_err.append(relmse(img, truth) - truth_floor)
    o_sec, t_sec = statistics.median(o_times), statistics.median(t_times)
    o_rel, t_rel = float(np.mean(o_err)), float(np.mean(t_err))
    o_eff, t_eff = 1 / (o_rel * o_sec), 1 / (t_rel * t_sec)
    print(f"truth: path {replicas}x{per} spp, its floor {truth_floor:.2e} (subtracted)")
    print(
        f"ours  at {args.eff_spp} spp: relMSE {o_rel:.4e}, {o_sec:.3f} s (median of {args.repeats}), "
        f"efficiency 1/(relMSE*s) {o_eff:.4g}"
    )
    print(
        f"path  at {args.eff_spp} spp: relMSE {t_rel:.4e}, {t_sec:.3f} s (median of {args.repeats}), "
        f"efficiency 1/(relMSE*s) {t_eff:.4g}"
    )
    print(f"efficiency ratio ours / path: {o_eff / t_eff:.3f} (target >= 1.0)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
