"""fog_smoke: participating media: a fog bank lit through a skylight, a smoke plume, a subsurface sphere.

Meters, Y up. A roof with a square opening shades a box of thin homogeneous fog (Henyey-Greenstein,
forward scattering), so the sun draws a shaft of light through it; beside it, in the sun, a plume of
smoke is a heterogeneous medium on a seeded procedural density grid; in front, a glass sphere filled
with a dense, nearly white medium scatters light under its surface (subsurface scattering). A dim sky
dome fills the shadows. The media sit apart (none inside another), and the camera stays outside
every medium.

Held-out variation (as the cluttered family's): :func:`variant_pool` puts about
:data:`HELD_OUT_FRACTION` of seeds in the ``held_out`` pool, whose stages draw media that train stages
never show: a back-scattering fog (Henyey-Greenstein g < 0), a billowing smoke cloud instead of a
plume, a green-blue (jade-like) subsurface medium instead of a warm one. The pool and the variants
drawn are recorded on ``/World`` as ``customData["denoisebench:variants"]`` (dataset splits pin
held-out scenes to test).
"""

from __future__ import annotations

import hashlib

import numpy as np

from denoisebench.scenes import camera_paths, geometry
from denoisebench.scenes.authoring import SceneBuilder
from denoisebench.scenes.media import author_medium


def plume_density(rng: np.random.Generator, nx: int = 16, ny: int = 24, nz: int = 16) -> np.ndarray:
    """A z×y×x density in [0, 1]: a rising column that widens and wanders, broken up by seeded waves."""
    z, y, x = np.meshgrid(np.linspace(-1, 1, nz), np.linspace(0, 1, ny), np.linspace(-1, 1, nx), indexing="ij")
    phase = rng.uniform(0, 2 * np.pi, 4)
    cx = 0.25 * np.sin(3.0 * y + phase[0]) * y
    cz = 0.25 * np.cos(2.5 * y + phase[1]) * y
    radius = 0.25 + 0.45 * y
    column = np.exp(-((x - cx) ** 2 + (z - cz) ** 2) / (2 * (0.5 * radius) ** 2))
    waves = np.ones_like(x)
    for _ in range(4):
        k = rng.uniform(3.0, 8.0, 3)
        waves += 0.25 * np.sin(k[0] * x + k[1] * y * 2 + k[2] * z + rng.uniform(0, 2 * np.pi))
    fade = np.clip(y / 0.08, 0, 1) * np.clip((1.0 - y) / 0.3, 0, 1)
    return np.clip(column * waves * fade, 0.0, 1.0).astype(np.float32)


#: Share of seeds in the held-out pool.
HELD_OUT_FRACTION = 0.2
#: Key of the variants record in ``/World``'s customData (the cluttered family's key).
VARIANTS_KEY = "denoisebench:variants"
TRAIN = {"fog": "forward", "smoke": "plume", "subsurface": "warm"}
HELD_OUT = {"fog": "backward", "smoke": "cloud", "subsurface": "jade"}


def variant_pool(seed: int) -> str:
    """``"held_out"`` or ``"train"``: a hash of the seed (BLAKE2b), the same on every machine."""
    digest = hashlib.blake2b(f"fog_smoke:{int(seed)}".encode(), digest_size=8).digest()
    return "held_out" if int.from_bytes(digest, "little") / 2.0**64 < HELD_OUT_FRACTION else "train"


def cloud_density(rng: np.random.Generator, nx: int = 16, ny: int = 24, nz: int = 16) -> np.ndarray:
    """A z×y×x density in [0, 1]: a few overlapping soft blobs (a billowing cloud, held-out variant)."""
    z, y, x = np.meshgrid(np.linspace(-1, 1, nz), np.linspace(0, 1, ny), np.linspace(-1, 1, nx), indexing="ij")
    density = np.zeros_like(x)
    for _ in range(int(rng.integers(4, 8))):
        c = rng.uniform([-0.5, 0.25, -0.5], [0.5, 0.75, 0.5])
        r = rng.uniform(0.2, 0.4)
        density += np.exp(-((x - c[0]) ** 2 + ((y - c[1]) * 2.0) ** 2 + (z - c[2]) ** 2) / (2 * r * r))
    return np.clip(density, 0.0, 1.0).astype(np.float32)


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    pool = variant_pool(b.seed)
    variants = HELD_OUT if pool == "held_out" else TRAIN
    ground = b.material("Ground", diffuse=rng.uniform(0.35, 0.5, 3), roughness=0.9)
    b.mesh("Ground", geometry.grid(30.0, 30.0, 1, 1, axis="y"), ground)
    stone = b.material("Stone", diffuse=rng.uniform(0.45, 0.6, 3), roughness=0.85)
    haze = b.material("Haze", diffuse=(0.8, 0.8, 0.8), roughness=1.0)  # not rendered: null boundaries

    # Roof over the fog, with a square opening (the skylight) that the sun shines through.
    hx, hz, half = rng.uniform(-2.6, -1.4), rng.uniform(-2.6, -1.4), rng.uniform(0.4, 0.6)
    x0, x1, z0, z1, y = -6.0, 1.4, -6.0, 1.0, 4.4
    slabs = [
        (x0, x1, z0, hz - half),  # behind the opening
        (x0, x1, hz + half, z1),  # in front
        (x0, hx - half, hz - half, hz + half),  # left
        (hx + half, x1, hz - half, hz + half),  # right
    ]
    for i, (a0, a1, c0, c1) in enumerate(slabs):
        b.cube("Roof%d" % i, 1.0, stone, translate=((a0 + a1) / 2, y, (c0 + c1) / 2), scale=(a1 - a0, 0.2, c1 - c0))
    for i, (px, pz) in enumerate(((-5.5, -5.5), (1.0, -5.5), (-5.5, 0.6), (1.0, 0.6))):
        b.cube("Pillar%d" % i, 1.0, stone, translate=(px, 2.15, pz), scale=(0.3, 4.3, 0.3))

    fog = b.cube("Fog", 1.0, haze, translate=(-1.6, 2.0, -1.6), scale=(5.2, 4.0, 4.8))
    s = rng.uniform(0.12, 0.3)
    g = rng.uniform(0.2, 0.6) * (1.0 if variants["fog"] == "forward" else -1.0)
    author_medium(fog, "homogeneous", sigma_t=(s, s, s), albedo=(0.9,) * 3, g=g)
    b.cube("Block", 1.0, stone, translate=(hx + rng.uniform(-0.4, 0.4), 0.5, hz + rng.uniform(-0.4, 0.4)))

    smoke = b.cube("Smoke", 1.0, haze, translate=(2.6, 1.6, -0.9), scale=(1.6, 3.2, 1.6))
    author_medium(
        smoke,
        "heterogeneous",
        sigma_t=(rng.uniform(3.0, 6.0),) * 3,
        albedo=tuple(rng.uniform(0.7, 0.9, 3)),
        g=rng.uniform(0.0, 0.4),
        density=plume_density(rng) if variants["smoke"] == "plume" else cloud_density(rng),
    )

    glass = b.material("Skin", diffuse=(1.0, 1.0, 1.0), roughness=0.0, opacity=0.0, ior=rng.uniform(1.33, 1.5))
    r = rng.uniform(0.35, 0.5)
    ball = b.sphere("Subsurface", r, glass, translate=(rng.uniform(-0.9, -0.3), r, rng.uniform(1.6, 2.2)))
    author_medium(
        ball,
        "homogeneous",
        sigma_t=(rng.uniform(6.0, 12.0),) * 3,
        albedo=(
            (rng.uniform(0.9, 0.99), rng.uniform(0.75, 0.9), rng.uniform(0.6, 0.8))
            if variants["subsurface"] == "warm"
            else (rng.uniform(0.5, 0.7), rng.uniform(0.85, 0.97), rng.uniform(0.75, 0.9))
        ),
        g=rng.uniform(0.0, 0.3),
        boundary="surface",
    )

    b.distant_light("Sun", 0.53, intensity=rng.uniform(2.5, 3.5), color=(1.0, 0.93, 0.82), direction=(0.25, -1.0, 0.2))
    b.dome_light("Sky", intensity=rng.uniform(0.08, 0.15), color=(0.6, 0.75, 1.0))

    poses = camera_paths.orbit(
        (-0.5, 0.0, -0.8),
        rng.uniform(7.5, 8.5),
        rng.uniform(1.2, 2.0),
        90.0 + rng.uniform(-15.0, 15.0),
        rng.choice([-1.0, 1.0]) * rng.uniform(6.0, 12.0),
        b.frames,
        b.up,
        target=(-0.5, 1.3, -0.8),
    )
    b.camera(poses, focal_length_mm=30.0, clipping=(0.05, 100.0))
    b.stage.GetPrimAtPath("/World").SetCustomDataByKey(VARIANTS_KEY, {"pool": pool, **variants})
