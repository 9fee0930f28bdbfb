"""Procedural surface textures for cluttered scenes: noise, stripes, checks, marble-like, wood-like.

Float RGB arrays in [0, 1] (H×W×3), pure functions of their arguments and a seeded generator, so a
family writes the same PNG bytes for the same seed. :data:`KINDS` lists them; the cluttered family
keeps some kinds for its held-out (test) scenes only.
"""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import textures

#: Texture kinds, in a fixed order.
KINDS = ("noise", "stripes", "checks", "marble", "wood")


def _palette(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    c0 = rng.uniform(0.05, 0.95, 3)
    c1 = np.clip(c0 * rng.uniform(0.2, 0.7) + rng.uniform(0.0, 0.3, 3), 0.0, 1.0)
    return c0, c1


def noise(rng: np.random.Generator, size: int) -> np.ndarray:
    c0, c1 = _palette(rng)
    t = textures.value_noise(rng, size, octaves=5, base_cells=int(rng.integers(2, 6)))
    return c1 + (c0 - c1) * t[..., None]


def stripes(rng: np.random.Generator, size: int) -> np.ndarray:
    c0, c1 = _palette(rng)
    return textures.stripes(size, int(rng.integers(3, 12)), c0, c1, angle_deg=float(rng.uniform(0, 180)))


def checks(rng: np.random.Generator, size: int) -> np.ndarray:
    c0, c1 = _palette(rng)
    return textures.checker(size, int(rng.choice([2, 4, 8])), c0=c0, c1=c1)


def marble(rng: np.random.Generator, size: int) -> np.ndarray:
    """Veined stone: a sine of a direction plus fractal turbulence (tileable: integer frequencies)."""
    u, v = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
    turbulence = textures.value_noise(rng, size, octaves=6, base_cells=4)
    fu, fv = int(rng.integers(1, 4)), int(rng.integers(0, 3))
    t = 0.5 + 0.5 * np.sin(2 * np.pi * (fu * u + fv * v) + rng.uniform(4.0, 9.0) * turbulence)
    t = t ** rng.uniform(0.3, 0.8)
    base = rng.uniform(0.75, 0.95) * np.ones(3) * rng.uniform(0.9, 1.0, 3)
    vein = rng.uniform(0.05, 0.4, 3)
    return vein + (base - vein) * t[..., None]


def wood(rng: np.random.Generator, size: int) -> np.ndarray:
    """Growth rings around an off-image axis, perturbed by noise, with fine grain."""
    u, v = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size)
    cx, cy = rng.uniform(-1.0, 2.0), rng.uniform(-1.0, 2.0)
    r = np.hypot(u - cx, (v - cy) * 0.25)
    wobble = textures.value_noise(rng, size, octaves=4, base_cells=4)
    rings = 0.5 + 0.5 * np.sin(2 * np.pi * (rng.uniform(8.0, 20.0) * r + 2.0 * wobble))
    grain = textures.value_noise(rng, size, octaves=3, base_cells=32)
    t = np.clip(0.7 * rings + 0.3 * grain, 0.0, 1.0)
    light = np.array([0.65, 0.45, 0.25]) * rng.uniform(0.8, 1.2)
    dark = np.array([0.3, 0.17, 0.08]) * rng.uniform(0.7, 1.1)
    return np.clip(dark + (light - dark) * t[..., None], 0.0, 1.0)


def make(kind: str, rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """A texture of ``kind`` (one of :data:`KINDS`), ``size``² pixels."""
    builders = {"noise": noise, "stripes": stripes, "checks": checks, "marble": marble, "wood": wood}
    if kind not in builders:
        raise ValueError(f"unknown texture kind {kind!r} (known: {', '.join(KINDS)})")
    return np.clip(builders[kind](rng, size), 0.0, 1.0)
