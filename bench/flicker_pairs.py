"""Which frame pairs and pixels carry a scene's flicker score, and what the reference's own frame difference is there.

For one scene of a dataset at each ``--spp``, prints per consecutive frame pair: the noisy input's
``temporal_relmse_robust`` with the metric as it is (denominator: the larger local magnitude of the
two frames compared) and with frame t's local magnitude alone (the former denominator), and how many
pixels of the reference's own warped frame difference, scored the same way against frame t's
magnitude alone, exceed 50; then the ``--top`` pixels of that reference difference with their values
in both frames and their motion. No rendering: it reads the dataset.

Used for issue 54 (glossy_fireflies' flicker ~1.5e5 for every denoiser, demo of main 3a0b9b0, seed 915)::

    .venv/bin/python bench/flicker_pairs.py --data /work/data/demo_before/dataset --scene glossy_fireflies_915

Measured there (64×64, 8 frames): with frame t's magnitude alone the input's robust flicker per pair
was 2.6e3–7.3e5 at 1 spp, 1.3e3–1.4e5 at 4 and 9.5e2–5.2e4 at 16 (it did not fall with spp), and
10–19 pixels per pair of the reference's own difference scored above 50 (up to 1.4e10): background
pixels (depth 0, black 3×3 neighbourhood in frame t, motion −2.9 px) that the warp reads from small
emitters of frame t−1 (radiance ~1e4, motion −0.6 px). With both frames' magnitude: 0.34–0.80 at 1
spp, 0.11–0.18 at 4, 0.036–0.051 at 16.
"""

from __future__ import annotations

import argparse

import numpy as np

from denoisebench.dataset import open_dataset
from denoisebench.metrics.ours import temporal as tm
from denoisebench.metrics.ours.robust import kept_mask


def _pair(noisy, ref, motion):
    """(robust flicker as defined, robust flicker with frame t's magnitude alone, reference Δ scores, taps)."""
    checked = tm.check_sequences(noisy, ref, min_frames=2)
    diff, denom, valid, _ = tm._relative_pairs(checked, None, motion, None, tm.DEPTH_TOLERANCE)
    alone = np.square(tm._local_magnitude(ref[1])) + tm.EPS_TEMPORAL_RELMSE
    scores = []
    for d in (denom[0], alone):
        values = (np.square(diff[0]) / d).mean(axis=-1)
        scores.append(float(values[kept_mask(values, 0.001, valid[0])].mean()))
    taps = tm._taps(motion[1])
    own = ref[1] - tm._bilinear(ref[0], taps)
    return scores[0], scores[1], (np.square(own) / alone).mean(axis=-1), taps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="dataset folder")
    parser.add_argument("--scene", required=True, help="scene name, e.g. glossy_fireflies_915")
    parser.add_argument("--spp", default="1,4,16", help="input spp to read (default 1,4,16)")
    parser.add_argument("--top", type=int, default=2, help="pixels of the reference's difference to print per pair")
    args = parser.parse_args()
    dataset = open_dataset(args.data)
    for spp in (int(s) for s in args.spp.split(",")):
        frames = dataset.sequence(args.scene, spp, samples=False).frames
        ref = np.stack([f.reference for f in frames]).astype(np.float64)
        noisy = np.stack([np.nan_to_num(f.color) for f in frames]).astype(np.float64)
        motion = np.stack([f.buffers["motion"] for f in frames]).astype(np.float64)
        for t in range(1, len(frames)):
            both, alone, own, taps = _pair(noisy[t - 1 : t + 1], ref[t - 1 : t + 1], motion[t - 1 : t + 1])
            print(
                f"{spp:3d} spp pair {t}: input flicker {both:.3g} (frame t's magnitude alone {alone:.3g}); "
                f"reference's own difference > 50 at {int((own > 50).sum())} pixels, max {own.max():.3g}"
            )
            warped = tm._bilinear(ref[t - 1], taps)
            for index in np.argsort(own.ravel())[::-1][: args.top]:
                y, x = divmod(int(index), own.shape[1])
                print(
                    f"    pixel ({y},{x}): {own[y, x]:.3g}; r_t {ref[t, y, x].mean():.3g}, warped r_t-1 "
                    f"{warped[y, x].mean():.3g}, motion {motion[t, y, x].round(2).tolist()}"
                )


if __name__ == "__main__":
    main()
