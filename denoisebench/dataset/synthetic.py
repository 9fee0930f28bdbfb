"""A tiny synthetic dataset (no renderer): for tests of readers, loaders, denoisers and models.

Each scene is a smooth procedural pattern sliding by ``velocity`` pixels per frame, so its motion
vectors are exact: the pattern at frame t is ``f(x − t·vx, y − t·vy)`` and a pixel's point was
``(−vx, −vy)`` away in frame t−1 (frame 0 has zero motion, like the renderer). The reference is
the pattern; noisy color adds Gaussian noise of standard deviation ``noise / sqrt(spp)``, with the
matching ``color_var``. Features are plausible and finite: albedo = the pattern's tint, normal
(0, 0, 1), depth and position from a plane, roughness 0.5, diffuse/specular = 0.7/0.3 of color.
Same arguments, same bytes.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from denoisebench.dataset import layout
from denoisebench.dataset.manifest import assign_splits
from denoisebench.dataset.writer import DatasetWriter


def pattern(height: int, width: int, t: float, velocity: tuple[float, float], phase: float = 0.0) -> np.ndarray:
    """H×W×3 radiance of the sliding pattern at frame ``t`` (float32, positive)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    u = x - t * velocity[0]
    v = y - t * velocity[1]
    base = 0.5 + 0.25 * np.sin(0.7 * u + phase) * np.cos(0.45 * v - phase) + 0.15 * np.sin(0.23 * (u + 2 * v))
    tint = np.array([1.0, 0.8, 0.6])
    return (base[..., None] * tint).astype(np.float32)


def synthetic_frame(
    height: int,
    width: int,
    t: int,
    spp: int,
    velocity=(1.0, 0.0),
    noise: float = 0.3,
    seed: int = 0,
    phase: float = 0.0,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """(noisy buffers, reference color) of frame ``t``."""
    ref = pattern(height, width, t, velocity, phase)
    rng = np.random.default_rng([seed, t, spp])
    sigma = noise / np.sqrt(spp)
    color = np.maximum(ref + rng.normal(0.0, sigma, ref.shape).astype(np.float32), 0.0).astype(np.float32)
    var = np.full(ref.shape, sigma * sigma, np.float32)
    ones = np.ones((height, width, 1), np.float32)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    depth = (5.0 + 0.01 * y)[..., None]
    motion = np.zeros((height, width, 2), np.float32)
    if t > 0:
        motion[..., 0] = -velocity[0]
        motion[..., 1] = -velocity[1]
    buffers = {
        "color": color,
        "color_var": var,
        "diffuse": (0.7 * color).astype(np.float32),
        "diffuse_var": (0.49 * var).astype(np.float32),
        "specular": (0.3 * color).astype(np.float32),
        "specular_var": (0.09 * var).astype(np.float32),
        "albedo": np.clip(ref / 1.2, 0.0, 1.0).astype(np.float32),
        "normal": np.concatenate([0 * ones, 0 * ones, ones], axis=-1),
        "depth": depth.astype(np.float32),
        "position": np.stack([x, y, np.full_like(x, 5.0)], axis=-1).astype(np.float32),
        "roughness": 0.5 * ones,
        "motion": motion,
    }
    return buffers, ref


def make_synthetic_dataset(
    out_dir: str | os.PathLike,
    scenes: int = 3,
    frames: int = 3,
    height: int = 16,
    width: int = 16,
    spp=(1, 4),
    ref_spp: int = 1024,
    per_sample: bool = False,
    seed: int = 0,
    velocity=(1.0, 0.0),
) -> Path:
    """Write a complete synthetic dataset to ``out_dir`` (scenes ``synthetic_000``...); return the path."""
    config = {
        "generator": "synthetic",
        "scenes": scenes,
        "frames": frames,
        "size": [height, width],
        "spp": sorted(int(s) for s in spp),
        "ref_spp": ref_spp,
        "per_sample": per_sample,
        "seed": seed,
        "velocity": list(velocity),
    }
    writer = DatasetWriter(out_dir, config, {"synthetic": "1"})
    names = [f"synthetic_{i:03d}" for i in range(scenes)]
    for i, name in enumerate(names):
        writer.add_scene(
            name,
            {
                "family": "synthetic",
                "seed": seed + i,
                "frames": frames,
                "width": width,
                "height": height,
                "spp": list(spp),
                "ref_spp": ref_spp,
                "usd": layout.usd_path(name),
                "effects": {"declared": [], "inferred": []},
                "plan": {"camera_model": "pinhole", "per_sample": per_sample},
                "camera": {"velocity": list(velocity)},
            },
        )
        for t in range(frames):
            for s in sorted(spp):
                if writer.is_done(name, t, s):
                    continue
                buffers, _ = synthetic_frame(height, width, t, s, velocity, seed=seed + i, phase=i)
                samples = None
                if per_sample:
                    rng = np.random.default_rng([seed + i, t, s, 1])
                    samples = {
                        "color": np.repeat(buffers["color"][None], s, axis=0),
                        "albedo": np.repeat(buffers["albedo"][None], s, axis=0),
                        "pixel": rng.random((s, height, width, 2), dtype=np.float32),
                    }
                writer.write_frame(name, t, s, buffers, samples, seconds=0.001 * s)
            if not writer.is_done(name, t, "reference"):
                _, ref = synthetic_frame(height, width, t, 1, velocity, seed=seed + i, phase=i)
                writer.write_reference(name, t, ref, np.full(ref.shape, 1e-6, np.float32), seconds=0.5)
    writer.finalize(assign_splits(names, seed))
    return Path(out_dir)
