"""The peer of a blurred frame: static sub-frame renders by Mitsuba's ``path``, shared by the object motion tests.

Mitsuba 3.9 has no animated shape transforms, so the expectation of a frame blurred by object motion is
built from static renders: at ``count`` stratified, jittered times over the frame's shutter, every
moving shape frozen at that time (:func:`~denoisebench.generator.render.motion.translated_at`) and the
camera at its pose at that time. Each sub-frame is an unbiased estimate of the time integral at its
stratum; their mean estimates the blurred frame, and :func:`paired_strata_variance` its variance.
"""

from __future__ import annotations

import numpy as np

from denoisebench.generator.render.motion import translated_at
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict


def sub_frame_renders(
    mi, translated, count: int, spp: int, size: int = 16, frame: int = 1, seed: int = 0
) -> list[np.ndarray]:
    """``count`` Mitsuba ``path`` renders (``size``², H×W×3) of ``frame`` at stratified, jittered shutter times.

    Times are ``frame + open + (close - open) (i + u_i) / count`` with ``u_i`` from
    ``np.random.default_rng(seed)``; sub-frame ``i`` renders with sampler seed ``i``. The camera sits at its
    pose at each time (a moving camera blurs too); with a static camera that is the frame's own pose."""
    camera = translated.camera
    rng = np.random.default_rng(seed)
    span = camera.shutter_close - camera.shutter_open
    subs = []
    for i in range(count):
        tau = frame + camera.shutter_open + span * (i + rng.random()) / count
        sensor = sensor_dict(camera, tau, size, size, spp, seed=i)
        sub = build_mitsuba_scene(translated_at(translated, tau), sensor, {"type": "path"})
        subs.append(np.asarray(mi.render(sub, spp=spp, seed=i))[..., :3])
    return subs


def paired_strata_variance(subs) -> np.ndarray:
    """Variance of the mean of ``subs`` (an even count of stratified estimates): ``Σ (x_2i - x_2i+1)² / N²``.

    Notes
    -----
    Pairs of neighbouring strata differ by their noise and by the image's change across two strata,
    so the estimate is conservative for stratified sampling (it never undercounts the noise)."""
    subs = np.asarray(subs, dtype=np.float64)
    if len(subs) % 2:
        raise ValueError(f"paired strata need an even number of sub-frames, not {len(subs)}")
    return np.sum(np.square(subs[0::2] - subs[1::2]), axis=0) / len(subs) ** 2
