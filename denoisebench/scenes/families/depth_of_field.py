"""depth_of_field: rows of objects receding from a wide-open lens, bright bokeh balls behind."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder

#: The family's lens is at least this wide open (f-number at most this).
MAX_FSTOP = 2.0


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    # Textured ground: blur of fine detail is what depth of field is about.
    tex = b.texture("ground_tiles", textures.checker(1024, 64, rng.uniform(0.6, 0.8, 3), rng.uniform(0.15, 0.3, 3)))
    ground = b.material("Ground", roughness=0.9, diffuse_texture=tex)
    b.mesh("Ground", geometry.grid(8.0, 24.0, 1, 1, axis="y"), ground, translate=(0.0, 0.0, -8.0))

    # Rows of objects from about 1 m to 10 m in front of the camera (camera at z = 3), sized and
    # spread with their distance so that every row fills the view.
    distances = (1.0, 1.6, 2.4, 3.6, 5.5, 8.0, 10.5)
    for k, dist in enumerate(distances):
        z = 3.0 - dist
        scale = 0.25 + 0.12 * dist
        for j in range(int(rng.integers(3, 6))):
            color = rng.uniform(0.1, 0.9, 3)
            mat = b.material(f"Row{k}_{j}", diffuse=color, roughness=0.8)
            x = rng.uniform(-0.3, 0.3) * dist + rng.uniform(-0.1, 0.1)
            zz = z + rng.uniform(-0.1, 0.1) * scale
            kind = int(rng.integers(3))
            if kind == 0:
                r = rng.uniform(0.06, 0.12) * scale
                b.sphere(f"Sphere{k}_{j}", r, mat, translate=(x, r, zz))
            elif kind == 1:
                c = rng.uniform(0.1, 0.2) * scale
                b.cube(f"Cube{k}_{j}", c, mat, translate=(x, c / 2, zz), rotate=(0.0, rng.uniform(0.0, 90.0), 0.0))
            else:
                hgt = rng.uniform(0.3, 0.6) * scale
                b.cylinder(
                    f"Cylinder{k}_{j}", rng.uniform(0.03, 0.06) * scale, hgt, "Y", mat, translate=(x, hgt / 2, zz)
                )

    # Small emissive balls far behind: bokeh discs when out of focus.
    for i in range(int(rng.integers(10, 17))):
        glow = b.material(
            f"Glow{i}",
            diffuse=(0.0, 0.0, 0.0),
            roughness=1.0,
            emissive=rng.uniform(4.0, 12.0) * np.array([1.0, rng.uniform(0.5, 0.9), rng.uniform(0.2, 0.6)]),
        )
        b.sphere(
            f"Bokeh{i}",
            rng.uniform(0.03, 0.06),
            glow,
            translate=(rng.uniform(-3.0, 3.0), rng.uniform(0.4, 2.5), rng.uniform(-16.0, -12.0)),
        )

    # Key light overhead and a fill from behind the camera.
    b.disk_light("Key", 1.0, intensity=rng.uniform(6.0, 10.0), matrix=b.aim((0.0, 5.0, -3.0), (0.0, 0.0, -3.0)))
    b.rect_light("Fill", 3.0, 1.5, intensity=rng.uniform(0.8, 1.5), matrix=b.aim((0.0, 2.5, 6.0), (0.0, 0.5, -3.0)))

    # Slow sideways truck; a wide-open 65 mm lens focused on the second or third row, close to the
    # camera, so that both the foreground and the background are far out of focus.
    eye_y = rng.uniform(0.3, 0.45)
    focus_row = int(rng.integers(1, 3))
    tilt = 0.1  # the view direction drops 0.1 per unit forward
    poses = camera_paths.truck((-0.1, eye_y, 3.0), (0.1, eye_y, 3.0), (0.0, -tilt, -1.0), b.frames, b.up)
    # Focus distance is measured along the view axis: the row's z distance / cos(tilt angle).
    focus = distances[focus_row] / np.cos(np.arctan(tilt))
    b.camera(
        poses, focal_length_mm=65.0, fstop=rng.uniform(1.2, MAX_FSTOP), focus_distance=focus, clipping=(0.05, 100.0)
    )
