"""texture_checker: high-frequency textures (checkerboards, a zone plate, stripes) on a Z-up stage."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder

UP = (0.0, 0.0, 1.0)


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    # Ground: a fine checkerboard with a noisy roughness map (dielectric, so still diffuse-ish).
    checks = int(rng.choice([96, 128, 160]))
    c0 = rng.uniform(0.75, 0.95, 3)
    c1 = rng.uniform(0.02, 0.12, 3)
    floor_tex = b.texture("floor_checker", textures.checker(1024, checks, c0, c1))
    rough_tex = b.texture(
        "floor_roughness", 0.35 + 0.6 * np.repeat(textures.value_noise(rng, 256, octaves=4)[..., None], 3, axis=2)
    )
    floor = b.material("CheckerFloor", roughness=0.7, diffuse_texture=floor_tex, roughness_texture=rough_tex)
    b.mesh("Floor", geometry.grid(20.0, 20.0, 1, 1, axis="z"), floor)

    # A wall-sized zone plate facing the camera (−Y).
    zp = b.texture("zone_plate", textures.zone_plate(1024, cycles=rng.uniform(90.0, 140.0)))
    board = b.material("ZonePlate", roughness=0.8, diffuse_texture=zp)
    b.mesh("Billboard", geometry.quad([(-2.5, 4.0, 0.3), (2.5, 4.0, 0.3), (2.5, 4.0, 3.3), (-2.5, 4.0, 3.3)]), board)

    # Striped cubes on shared corners (faceVarying normals and st) and a bricked sphere.
    for i in range(int(rng.integers(3, 6))):
        tex = b.texture(
            f"stripes_{i}",
            textures.stripes(
                256,
                int(rng.integers(24, 48)),
                rng.uniform(0.6, 0.95, 3),
                rng.uniform(0.0, 0.2, 3),
                angle_deg=rng.uniform(0.0, 180.0),
            ),
        )
        mat = b.material(f"Stripes{i}", roughness=0.8, diffuse_texture=tex)
        s = rng.uniform(0.4, 0.8)
        b.mesh(
            f"Cube{i}",
            geometry.box_shared((s, s, s)),
            mat,
            translate=(rng.uniform(-3.0, 3.0), rng.uniform(-1.5, 2.5), s / 2),
            rotate=(0.0, 0.0, rng.uniform(0.0, 90.0)),
        )
    brick_tex = b.texture("bricks", textures.bricks(512, rows=32, cols=16))
    brick = b.material("Bricks", roughness=0.85, diffuse_texture=brick_tex)
    r = rng.uniform(0.5, 0.8)
    b.mesh(
        "BrickBall",
        geometry.uv_sphere(r, 32, 16, up="z"),
        brick,
        translate=(rng.uniform(-1.0, 1.0), rng.uniform(0.5, 1.5), r),
    )

    # Overhead rect light and a sun.
    b.rect_light("Overhead", 3.0, 3.0, intensity=rng.uniform(3.0, 5.0), matrix=b.aim((0.0, 0.5, 5.0), (0.0, 0.5, 0.0)))
    b.distant_light(
        "Sun", 1.0, intensity=rng.uniform(1.5, 2.5), direction=(rng.uniform(-0.5, 0.5), rng.uniform(0.2, 0.6), -1.0)
    )

    # Dolly in at a grazing angle (texture minification changes every frame).
    x = rng.uniform(-1.0, 1.0)
    poses = camera_paths.dolly(
        (x, -8.0, rng.uniform(1.0, 1.4)), (x * 0.5, -4.5, rng.uniform(0.7, 0.9)), (0.0, 3.0, 0.6), b.frames, UP
    )
    b.camera(poses, focal_length_mm=30.0, clipping=(0.05, 100.0))
