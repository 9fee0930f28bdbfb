"""motion_blur: a whip pan through a ring of columns and striped boards, shutter open half a frame."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder

#: Shutter interval in frames, relative to each frame's time.
SHUTTER = (-0.25, 0.25)
#: The camera turns at least this many degrees per frame.
MIN_YAW_DEG_PER_FRAME = 6.0


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    asphalt = b.texture(
        "asphalt",
        np.repeat((0.12 + 0.2 * textures.value_noise(rng, 512, octaves=6, base_cells=16))[..., None], 3, axis=2),
    )
    ground = b.material("Asphalt", roughness=0.95, diffuse_texture=asphalt)
    b.mesh("Ground", geometry.grid(40.0, 40.0, 1, 1, axis="y"), ground)

    # A ring of coloured columns, and striped boards between them (hard vertical edges to smear).
    n = int(rng.integers(10, 15))
    ring = rng.uniform(5.0, 7.0)
    for i in range(n):
        ang = 2.0 * np.pi * (i + rng.uniform(-0.2, 0.2)) / n
        x, z = ring * np.cos(ang), ring * np.sin(ang)
        mat = b.material(f"Column{i}", diffuse=rng.uniform(0.1, 0.9, 3), roughness=0.8)
        hgt = rng.uniform(2.0, 4.0)
        b.cylinder(f"Column{i}", rng.uniform(0.2, 0.4), hgt, "Y", mat, translate=(x, hgt / 2, z))
        if i % 2 == 0:
            tex = b.texture(
                f"board_{i}",
                textures.stripes(256, int(rng.integers(6, 14)), rng.uniform(0.7, 1.0, 3), rng.uniform(0.0, 0.2, 3)),
            )
            board = b.material(f"Board{i}", roughness=0.8, diffuse_texture=tex)
            mid = ang + np.pi / n
            bx, bz = (ring + 0.8) * np.cos(mid), (ring + 0.8) * np.sin(mid)
            # A board facing the ring's center: its normal points from (bx, bz) toward the origin.
            t = np.array([-np.sin(mid), 0.0, np.cos(mid)])  # tangent
            c = np.array([bx, 0.3, bz])
            half = 1.0
            corners = [c - t * half, c + t * half, c + t * half + (0, 2.0, 0), c - t * half + (0, 2.0, 0)]
            b.mesh(f"Board{i}", geometry.quad(corners), board)

    # Sun and sky.
    sun_az, sun_el = rng.uniform(0.0, 360.0), rng.uniform(25.0, 50.0)
    sky = b.texture("sky", textures.sky_latlong(512, 256, sun_az, sun_el))
    b.dome_light("Sky", intensity=rng.uniform(0.8, 1.2), texture=sky)
    d = -np.array(
        [
            np.cos(np.deg2rad(sun_el)) * np.cos(np.deg2rad(sun_az)),
            np.sin(np.deg2rad(sun_el)),
            np.cos(np.deg2rad(sun_el)) * np.sin(np.deg2rad(sun_az)),
        ]
    )
    b.distant_light("Sun", 0.53, intensity=rng.uniform(2.0, 3.0), color=(1.0, 0.95, 0.85), direction=d)

    # Whip pan from the center, sliding sideways as it turns.
    yaw = rng.choice([-1.0, 1.0]) * rng.uniform(MIN_YAW_DEG_PER_FRAME, 10.0)
    start = rng.uniform(0.0, 2.0 * np.pi)
    target = (np.cos(start), 1.4, np.sin(start))
    poses = camera_paths.fast_pan(
        (0.0, 1.5, 0.0), target, b.frames, yaw, slide_per_frame=(rng.uniform(0.1, 0.3), 0.0, 0.0), up=b.up
    )
    b.camera(poses, focal_length_mm=30.0, clipping=(0.05, 200.0), shutter=SHUTTER)
