"""dim_room: a closed room lit by one light hidden behind a shelf, facing the wall (mostly indirect)."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    w, h, d = 4.0, 2.6, 4.0  # x in [-2, 2], y in [0, 2.6], z in [-2, 2]
    wall = b.material("Paint", diffuse=rng.uniform(0.55, 0.75, 3), roughness=0.9)
    shell = geometry.box(size=(w, h, d), center=(0.0, h / 2, 0.0), inward=True, faces=("+x", "-x", "+y", "+z", "-z"))
    b.mesh("WallsAndCeiling", shell, wall)

    planks = b.texture("floor_planks", textures.planks(rng, 512, boards=12))
    floor = b.material("Floor", diffuse=(1, 1, 1), roughness=0.7, diffuse_texture=planks)
    b.mesh("Floor", geometry.grid(w, d, 1, 1, axis="y"), floor)

    # Shelf standing off the back wall; the light hides between them, facing the wall.
    wood = b.material("DarkWood", diffuse=(0.18, 0.1, 0.06), roughness=0.8)
    shelf_w = rng.uniform(1.6, 2.2)
    shelf_x = rng.uniform(-0.8, 0.2)
    b.cube("Shelf", 1.0, wood, translate=(shelf_x, 1.0, -1.55), scale=(shelf_w, 2.0, 0.35))
    b.rect_light(
        "HiddenLight",
        shelf_w * 0.7,
        0.35,
        intensity=rng.uniform(30.0, 50.0),
        color=(1.0, rng.uniform(0.75, 0.85), rng.uniform(0.55, 0.65)),
        matrix=b.aim((shelf_x, 1.6, -1.74), (shelf_x, 1.6, -3.0)),
    )

    # Furniture: a table, a low sofa, a ball.
    cloth = b.material(
        "Cloth", diffuse=(rng.uniform(0.1, 0.5), rng.uniform(0.1, 0.4), rng.uniform(0.2, 0.5)), roughness=1.0
    )
    tx, tz = rng.uniform(-0.4, 0.4), rng.uniform(-0.2, 0.4)
    b.cube("TableTop", 1.0, wood, translate=(tx, 0.72, tz), scale=(1.2, 0.05, 0.7))
    for i, (sx, sz) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
        b.cube(f"TableLeg{i}", 1.0, wood, translate=(tx + sx * 0.55, 0.35, tz + sz * 0.3), scale=(0.05, 0.7, 0.05))
    b.cube("SofaSeat", 1.0, cloth, translate=(-1.55, 0.22, 0.6), scale=(0.8, 0.44, 1.8))
    b.cube("SofaBack", 1.0, cloth, translate=(-1.9, 0.6, 0.6), scale=(0.2, 0.8, 1.8))
    ball = b.material("Ball", diffuse=(0.8, 0.25, 0.1), roughness=0.6)
    b.sphere("Ball", 0.15, ball, translate=(rng.uniform(0.4, 1.2), 0.15, rng.uniform(0.6, 1.2)))

    # Handheld camera in the front corner.
    base = camera_paths.static((1.6, 1.45, 1.75), (rng.uniform(-0.8, -0.2), 0.8, -1.2), b.frames, b.up)
    poses = camera_paths.handheld_shake(base, rng, translate_amp=0.015, rotate_amp_deg=0.5)
    b.camera(poses, focal_length_mm=22.0, clipping=(0.02, 20.0))
