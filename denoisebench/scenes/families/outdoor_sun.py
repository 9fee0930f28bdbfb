"""outdoor_sun: glossy metal sculptures on a textured meadow under a sun and a sky dome."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder

_PAINTS = [(0.7, 0.05, 0.05), (0.05, 0.2, 0.6), (0.9, 0.75, 0.3), (0.8, 0.8, 0.82), (0.1, 0.45, 0.2)]


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    noise = textures.value_noise(rng, 512, octaves=6, base_cells=8)
    meadow = np.stack([0.18 + 0.2 * noise, 0.3 + 0.25 * noise, 0.08 + 0.08 * noise], axis=-1)
    tex = b.texture("meadow", meadow)
    ground = b.material("Meadow", roughness=0.95, diffuse_texture=tex)
    b.mesh("Ground", geometry.grid(40.0, 40.0, 1, 1, axis="y"), ground)

    # Glossy metal: spheres, blocks and a stretched uv-sphere "pebble" each.
    for i in range(int(rng.integers(4, 7))):
        paint = _PAINTS[int(rng.integers(len(_PAINTS)))]
        mat = b.material(f"Metal{i}", diffuse=paint, metallic=1.0, roughness=rng.uniform(0.08, 0.35))
        x, z = rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0)
        kind = int(rng.integers(3))
        if kind == 0:
            r = rng.uniform(0.3, 0.7)
            b.sphere(f"Sphere{i}", r, mat, translate=(x, r, z))
        elif kind == 1:
            s = rng.uniform(0.5, 1.0)
            b.cube(f"Block{i}", s, mat, translate=(x, s / 2, z), rotate=(0.0, rng.uniform(0.0, 90.0), 0.0))
        else:
            r = rng.uniform(0.3, 0.5)
            stretch = rng.uniform(1.5, 2.5)
            b.mesh(
                f"Pebble{i}",
                geometry.uv_sphere(r, 24, 12),
                mat,
                translate=(x, r * 0.7, z),
                rotate=(0.0, rng.uniform(0.0, 180.0), 0.0),
                scale=(stretch, 0.7, 1.0),
            )
    stone = b.material("Stone", diffuse=(0.45, 0.43, 0.4), roughness=0.9)
    for i in range(int(rng.integers(3, 6))):
        r = rng.uniform(0.1, 0.25)
        b.sphere(f"Rock{i}", r, stone, translate=(rng.uniform(-5.0, 5.0), r * 0.5, rng.uniform(-5.0, 5.0)))

    # Sun and sky dome.
    sun_az, sun_el = rng.uniform(0.0, 360.0), rng.uniform(20.0, 60.0)
    sky = b.texture("sky", textures.sky_latlong(512, 256, sun_az, sun_el, sun_radius_deg=3.0))
    b.dome_light("Sky", intensity=rng.uniform(0.8, 1.2), texture=sky)
    el, az = np.deg2rad(sun_el), np.deg2rad(sun_az)
    b.distant_light(
        "Sun",
        0.53,
        intensity=rng.uniform(3.0, 5.0),
        color=(1.0, 0.94, 0.82),
        direction=-np.array([np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az)]),
    )

    # Handheld orbit: a slow arc with a walking wobble.
    base = camera_paths.orbit(
        (0.0, 0.5, 0.0),
        rng.uniform(5.5, 7.0),
        rng.uniform(1.2, 2.0),
        rng.uniform(0.0, 360.0),
        rng.choice([-1.0, 1.0]) * rng.uniform(10.0, 20.0),
        b.frames,
        b.up,
    )
    poses = camera_paths.handheld_shake(base, rng, translate_amp=0.03, rotate_amp_deg=0.4)
    b.camera(poses, focal_length_mm=35.0, clipping=(0.05, 200.0))
