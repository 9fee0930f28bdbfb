"""The peer of a blurred frame: static sub-frame renders by Mitsuba's ``path``, shared by the object motion tests.

Mitsuba 3.9 has no animated shape transforms, so the expectation of a frame blurred by object motion is
built from static renders: at ``count`` stratified, jittered times over the frame's shutter, every
moving shape frozen at that time (:func:`~denoisebench.generator.render.motion.translated_at`) and the
camera at its pose at that time. Each sub-frame is an unbiased estimate of the time integral at its
stratum; their mean estimates the blurred frame, and :func:`paired_strata_variance` its variance.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, UsdGeom

from denoisebench.generator.render.motion import translated_at
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
from denoisebench.scenes import camera_paths, geometry
from denoisebench.scenes.authoring import SceneBuilder


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


SIZE = 16
FRAMES = 3


def moving_box_stage(tmp_path, kind: str = "rigid", shutter=(-0.5, 0.5), emissive: bool = False):
    """A box moving (``rigid``) or moving and stretching (``stretch``) over FRAMES frames under one rect light."""
    b = SceneBuilder(tmp_path, family="test", seed=0, frames=FRAMES, effects=("motion_blur", "area_lights"))
    b.mesh("Floor", geometry.grid(6.0, 6.0, 1, 1, axis="y"), b.material("Floor", diffuse=(0.6, 0.6, 0.6)))
    material = b.material("Box", diffuse=(0.9, 0.2, 0.1), roughness=0.5, emissive=(4.0, 4.0, 4.0) if emissive else None)
    box = b.mesh("Box", geometry.box(size=(0.6, 0.6, 0.6)), material)
    xform = UsdGeom.Xformable(box)
    translate = xform.AddTranslateOp()
    rotate = xform.AddRotateYOp()
    scale = xform.AddScaleOp() if kind == "stretch" else None
    for f in range(FRAMES):
        translate.Set(Gf.Vec3d(-1.0 + 1.0 * f, 0.3, 0.0), float(f))
        rotate.Set(45.0 * f, float(f))
        if scale is not None:
            scale.Set(Gf.Vec3f(1.0 + 0.5 * f, 1.0, 1.0 - 0.25 * f), float(f))
    b.rect_light("Key", 2.0, 2.0, intensity=8.0, matrix=b.aim((0.5, 3.0, 1.0), (0.0, 0.0, 0.0)))
    eye = np.array([0.0, 1.5, 3.0])
    b.camera(camera_paths.dolly(eye, eye, (0.0, 0.3, 0.0), FRAMES, b.up, ease=False), 30.0, shutter=shutter)
    return b.stage


def block_means(image, size=4):
    """Means of ``size``×``size`` blocks of a SIZE×SIZE image."""
    return image.reshape(SIZE // size, size, SIZE // size, size, -1).mean((1, 3))


def block_z_scores(ours, ours_var, subs):
    """Block z-scores of our image against the sub-frame average (paired-strata variance)."""
    a, va = block_means(ours), block_means(ours_var) / 16.0  # independent pixels: variance of a 4x4 block mean
    blocks = np.array([block_means(s) for s in subs])
    n = len(subs)
    vb = np.sum(np.square(blocks[0::2] - blocks[1::2]), axis=0) / n**2
    return (a - blocks.mean(0)) / np.sqrt(va + vb + 1e-12)
