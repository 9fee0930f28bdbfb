"""cornell: a closed Cornell box; red and green walls are GeomSubsets of one room mesh."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry
from denoisebench.scenes.authoring import SceneBuilder


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    # Room: x in [-1, 1], y in [0, 2], z in [-1, 2.2]; closed, faces looking inward.
    depth = 3.2
    room = geometry.box(size=(2.0, 2.0, depth), center=(0.0, 1.0, depth / 2 - 1.0), inward=True)
    white = b.material("White", diffuse=rng.uniform(0.68, 0.76, 3), roughness=0.9)
    red = b.material(
        "Red", diffuse=(rng.uniform(0.55, 0.7), rng.uniform(0.04, 0.08), rng.uniform(0.04, 0.08)), roughness=0.9
    )
    green = b.material(
        "Green", diffuse=(rng.uniform(0.1, 0.16), rng.uniform(0.4, 0.52), rng.uniform(0.08, 0.14)), roughness=0.9
    )
    mesh = b.mesh("Room", room, white)
    # Faces in geometry.BOX_FACES order: +x (right), -x (left), +y, -y, +z, -z.
    # The subsets partition the faces; the mesh's own binding (white) is the fallback.
    b.subset(mesh, "LeftWall", [1], red, family_type="partition")
    b.subset(mesh, "RightWall", [0], green, family_type="partition")
    b.subset(mesh, "WhiteWalls", [2, 3, 4, 5], white, family_type="partition")

    # Two blocks and, half of the time, a ball.
    tall_h = rng.uniform(1.1, 1.3)
    b.cube(
        "TallBlock",
        1.0,
        white,
        translate=(-0.35 + rng.uniform(-0.08, 0.08), tall_h / 2, -0.35 + rng.uniform(-0.08, 0.08)),
        rotate=(0.0, rng.uniform(10.0, 25.0), 0.0),
        scale=(0.55, tall_h, 0.55),
    )
    short_h = rng.uniform(0.5, 0.65)
    b.cube(
        "ShortBlock",
        1.0,
        white,
        translate=(0.38 + rng.uniform(-0.06, 0.06), short_h / 2, 0.3 + rng.uniform(-0.08, 0.08)),
        rotate=(0.0, -rng.uniform(10.0, 25.0), 0.0),
        scale=(0.55, short_h, 0.55),
    )
    if rng.random() < 0.5:
        r = rng.uniform(0.15, 0.22)
        b.sphere("Ball", r, white, translate=(rng.uniform(-0.6, -0.2), r, rng.uniform(0.5, 0.8)))

    # Ceiling light, just below the ceiling, facing down.
    size = rng.uniform(0.45, 0.65)
    b.rect_light(
        "CeilingLight",
        size,
        size * rng.uniform(0.8, 1.0),
        intensity=rng.uniform(18.0, 26.0),
        color=(1.0, rng.uniform(0.82, 0.9), rng.uniform(0.6, 0.7)),
        matrix=b.aim((0.0, 1.985, 0.0), (0.0, 0.0, 0.0)),
    )

    # Slow dolly in from near the front wall.
    z0 = rng.uniform(2.05, 2.12)
    poses = camera_paths.dolly(
        (0.0, 1.0, z0), (rng.uniform(-0.1, 0.1), 1.0, z0 - rng.uniform(0.25, 0.4)), (0.0, 0.95, -1.0), b.frames, b.up
    )
    b.camera(poses, focal_length_mm=28.0, clipping=(0.01, 20.0))
