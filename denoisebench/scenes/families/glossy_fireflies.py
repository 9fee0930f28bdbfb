"""glossy_fireflies: tiny, very bright sphere lights seen through glossy metal (firefly bait)."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry
from denoisebench.scenes.authoring import SceneBuilder

_METAL_TINTS = [(0.95, 0.93, 0.88), (1.0, 0.78, 0.34), (0.95, 0.64, 0.54), (0.91, 0.92, 0.92), (0.55, 0.56, 0.58)]

#: Every light of this family smaller than this radius (meters) counts as "small".
SMALL_LIGHT_RADIUS = 0.03


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    # Brushed-metal floor and a dark diffuse backdrop.
    floor = b.material("BrushedFloor", diffuse=(0.8, 0.8, 0.82), metallic=1.0, roughness=rng.uniform(0.08, 0.2))
    b.mesh("Floor", geometry.grid(10.0, 10.0, 1, 1, axis="y"), floor)
    backdrop = b.material("Backdrop", diffuse=(0.08, 0.08, 0.09), roughness=0.9)
    b.mesh("Backdrop", geometry.quad([(-5, 0, -3.5), (5, 0, -3.5), (5, 4, -3.5), (-5, 4, -3.5)]), backdrop)

    # Glossy metal spheres and blocks on an arc.
    count = int(rng.integers(5, 8))
    angles = np.linspace(-60.0, 60.0, count) + rng.uniform(-6.0, 6.0, count)
    for i, ang in enumerate(angles):
        tint = _METAL_TINTS[int(rng.integers(len(_METAL_TINTS)))]
        mat = b.material(f"Metal{i}", diffuse=tint, metallic=1.0, roughness=rng.uniform(0.05, 0.35))
        dist = rng.uniform(1.0, 1.8)
        x, z = dist * np.sin(np.deg2rad(ang)), -dist * np.cos(np.deg2rad(ang)) + 0.5
        if rng.random() < 0.7:
            r = rng.uniform(0.2, 0.4)
            b.sphere(f"Sphere{i}", r, mat, translate=(x, r, z))
        else:
            s = rng.uniform(0.3, 0.5)
            b.cube(f"Block{i}", s, mat, translate=(x, s / 2, z), rotate=(0.0, rng.uniform(0.0, 90.0), 0.0))

    # The fireflies' source: one or two tiny, intense sphere lights behind the objects.
    for k in range(int(rng.integers(1, 3))):
        radius = rng.uniform(0.01, 0.025)
        b.sphere_light(
            f"TinyLight{k}",
            radius,
            intensity=rng.uniform(2.0e4, 6.0e4),
            color=(1.0, rng.uniform(0.85, 0.95), rng.uniform(0.7, 0.85)),
            translate=(rng.uniform(-1.5, 1.5), rng.uniform(0.8, 1.8), rng.uniform(-2.8, -1.8)),
        )
    # A weak fill so the diffuse parts are not black.
    b.rect_light("Fill", 2.0, 1.0, intensity=rng.uniform(0.4, 0.8), matrix=b.aim((0.0, 3.0, 3.0), (0.0, 0.3, 0.0)))

    # Partial orbit around the arc.
    start = 90.0 + rng.uniform(-15.0, 15.0)
    poses = camera_paths.orbit(
        (0.0, 0.3, 0.0),
        rng.uniform(3.6, 4.2),
        rng.uniform(0.5, 0.9),
        start,
        rng.choice([-1.0, 1.0]) * rng.uniform(12.0, 20.0),
        b.frames,
        b.up,
    )
    b.camera(poses, focal_length_mm=32.0, clipping=(0.05, 50.0))
