"""thin_geometry: sub-pixel wires, a mesh fence and grass blades under sun and sky."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry
from denoisebench.scenes.authoring import SceneBuilder

#: Wires and mesh strips are thinner than this (meters).
THIN = 0.01


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    ground = b.material(
        "Ground", diffuse=(rng.uniform(0.25, 0.35), rng.uniform(0.22, 0.3), rng.uniform(0.14, 0.2)), roughness=1.0
    )
    b.plane("Ground", 14.0, 14.0, "Y", ground)

    # Post-and-wire fence at z = 0: posts every meter, thin horizontal wires.
    post_mat = b.material("Posts", diffuse=(0.35, 0.24, 0.14), roughness=0.9)
    wire_mat = b.material("Wire", diffuse=(0.6, 0.6, 0.6), roughness=0.6)
    half = 3
    for i in range(-half, half + 1):
        b.cylinder(
            f"Post{i + half}", 0.03, 1.3, "Y", post_mat, translate=(float(i) + rng.uniform(-0.05, 0.05), 0.65, 0.0)
        )
    wires = int(rng.integers(6, 10))
    for k, y in enumerate(np.linspace(0.15, 1.2, wires)):
        b.cylinder(
            f"Wire{k}", rng.uniform(0.002, 0.004), 2.0 * half + 0.4, "X", wire_mat, translate=(0.0, float(y), 0.04)
        )

    # Welded-mesh fence behind: one mesh of thin strips on a 5-7 cm grid.
    spacing = rng.uniform(0.05, 0.07)
    width = rng.uniform(0.005, 0.009)
    z = -1.6
    x0, x1, y0, y1 = -3.5, 3.5, 0.0, 2.0
    strips = [geometry.strip((x, y0, z), (x, y1, z), width, (1, 0, 0)) for x in np.arange(x0, x1 + 1e-9, spacing)]
    strips += [
        geometry.strip((x0, y, z + 0.005), (x1, y, z + 0.005), width, (0, 1, 0))
        for y in np.arange(y0 + spacing, y1 + 1e-9, spacing)
    ]
    mesh_mat = b.material("MeshFence", diffuse=(0.12, 0.13, 0.12), roughness=0.7)
    b.mesh("MeshFence", geometry.merge(strips), mesh_mat, double_sided=True)

    # Grass in front of the fence.
    grass = b.material(
        "Grass", diffuse=(rng.uniform(0.12, 0.2), rng.uniform(0.35, 0.5), rng.uniform(0.06, 0.12)), roughness=0.8
    )
    blades = geometry.grass_blades(rng, int(rng.integers(300, 420)), area=4.0, height=0.35)
    b.mesh("Grass", blades, grass, double_sided=True, translate=(0.0, 0.0, 1.2))

    # Low sun and a constant sky.
    b.distant_light(
        "Sun",
        0.53,
        intensity=rng.uniform(2.5, 3.5),
        color=(1.0, 0.93, 0.8),
        direction=(rng.uniform(-0.6, 0.6), -rng.uniform(0.4, 0.8), -rng.uniform(0.3, 0.8)),
    )
    b.dome_light("Sky", intensity=rng.uniform(0.5, 0.8), color=(0.55, 0.68, 0.9))

    # Slow pan along the fence.
    eye = (rng.uniform(-0.5, 0.5), rng.uniform(0.8, 1.1), rng.uniform(3.5, 4.2))
    poses = camera_paths.pan(eye, (-1.2, 0.6, -0.5), (1.2, 0.6, -0.5), b.frames, b.up)
    b.camera(poses, focal_length_mm=35.0, clipping=(0.05, 100.0))
