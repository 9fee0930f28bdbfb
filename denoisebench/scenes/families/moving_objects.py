"""moving_objects: objects that move rigidly, pass behind pillars and reappear, under a near-still camera.

Every frame is the objects' pose at that frame's time code (time-sampled ``xformOp``s); the motion
vectors are dominated by object motion (the camera only creeps in by :data:`CAMERA_PUSH_PER_FRAME`,
a fraction of a pixel at the back wall), with occlusion and disocclusion where a box slides behind
the pillars and a ball rolls in front of them.

* ``Slider``: a textured box translating along x behind the pillars at
  :data:`SLIDE_PER_FRAME` (0.18-0.3 m per frame) while it turns about the vertical axis
  (6-12° per frame): rigid translation + rotation, hidden and revealed by the pillars.
* ``Ball``: a striped sphere crossing diagonally in front of the pillars, rolling (its rotation
  matches its travel), so it occludes them in turn. Spheres that move are tessellated by the
  translator.
* ``Spinner``: a box turning in place (rotation only, no translation).

Objects move between frames only: there is no motion blur inside a frame (out of scope).
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, UsdGeom

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder

#: Range of the slider's travel per frame (meters).
SLIDE_PER_FRAME = (0.18, 0.3)
#: The camera's slow push-in per frame (meters): every family's camera moves, this one barely.
CAMERA_PUSH_PER_FRAME = 0.015


def _animate(prim, translations, rotations_y) -> None:
    """Replace a prim's xform ops by time-sampled translate + rotateY (one sample per frame)."""
    xformable = UsdGeom.Xformable(prim)
    xformable.ClearXformOpOrder()
    translate = xformable.AddTranslateOp()
    rotate = xformable.AddRotateYOp()
    for frame, (offset, angle) in enumerate(zip(translations, rotations_y)):
        translate.Set(Gf.Vec3d(*[float(v) for v in offset]), float(frame))
        rotate.Set(float(angle), float(frame))


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    frames = np.arange(b.frames, dtype=np.float64)
    floor_tex = b.texture("floor", textures.checker(256, 16, c0=(0.75, 0.75, 0.72), c1=(0.2, 0.2, 0.22)))
    floor = b.material("Floor", roughness=0.85, diffuse_texture=floor_tex)
    b.mesh("Floor", geometry.grid(12.0, 12.0, 1, 1, axis="y", st_repeat=3.0), floor)
    wall_tex = b.texture("wall", textures.bricks(256, 8, 4))
    wall = b.material("Wall", roughness=0.9, diffuse_texture=wall_tex)
    b.mesh("BackWall", geometry.quad([(-6, 0, -3), (6, 0, -3), (6, 4, -3), (-6, 4, -3)]), wall)

    # Pillars between the camera and the slider: occluders.
    pillar = b.material("Pillar", diffuse=rng.uniform(0.5, 0.7, 3), roughness=0.7)
    for i, x in enumerate((-1.1, 0.0, 1.1)):
        b.cylinder(f"Pillar{i}", 0.16, 2.2, "Y", pillar, translate=(x + rng.uniform(-0.1, 0.1), 1.1, -0.4))

    # Slider: behind the pillars, crossing the frame, turning as it goes.
    slide = rng.choice([-1.0, 1.0]) * rng.uniform(*SLIDE_PER_FRAME)
    start = -slide * (b.frames - 1) / 2.0
    turn = rng.choice([-1.0, 1.0]) * rng.uniform(6.0, 12.0)
    box_tex = b.texture(
        "slider",
        textures.stripes(
            128, int(rng.integers(4, 8)), rng.uniform(0.6, 1.0, 3), rng.uniform(0.0, 0.2, 3), angle_deg=30.0
        ),
    )
    box = b.mesh(
        "Slider", geometry.box(size=(0.8, 0.8, 0.8)), b.material("Slider", roughness=0.6, diffuse_texture=box_tex)
    )
    _animate(box, [(start + slide * f, 0.4, -1.4) for f in frames], [turn * f for f in frames])

    # Ball: in front of the pillars, diagonal travel, rolling about the vertical axis.
    radius = rng.uniform(0.25, 0.35)
    ball_tex = b.texture("ball", textures.stripes(128, 8, (0.95, 0.35, 0.1), (0.1, 0.1, 0.4), angle_deg=90.0))
    ball = b.mesh(
        "Ball",
        geometry.uv_sphere(radius, segments=32, rings=16),
        b.material("Ball", roughness=0.4, diffuse_texture=ball_tex),
    )
    travel = np.array([-slide * 0.8, 0.0, 0.12])
    ball_start = np.array([slide * 0.8 * (b.frames - 1) / 2.0, radius, 0.5])
    roll = np.degrees(np.linalg.norm(travel) / radius)
    _animate(ball, [ball_start + travel * f for f in frames], [roll * f for f in frames])

    # Spinner: rotation only, on the right.
    spin = rng.choice([-1.0, 1.0]) * rng.uniform(8.0, 15.0)
    spinner = b.mesh(
        "Spinner",
        geometry.box(size=(0.5, 1.0, 0.5)),
        b.material("Spinner", diffuse=rng.uniform(0.2, 0.8, 3), roughness=0.5),
    )
    _animate(spinner, [(2.0, 0.5, 0.2)] * b.frames, [spin * f for f in frames])

    # Overhead soft light and a small fill.
    b.rect_light("Key", 2.0, 1.2, intensity=rng.uniform(8.0, 11.0), matrix=b.aim((0.5, 3.8, 1.0), (0.0, 0.0, -0.5)))
    b.rect_light("Fill", 1.0, 1.0, intensity=rng.uniform(1.5, 2.5), matrix=b.aim((-3.0, 2.0, 3.0), (0.0, 0.5, -0.5)))

    # A near-still camera: the motion vectors are the objects'.
    eye = np.array([rng.uniform(-0.3, 0.3), 1.3, 4.2])
    end = eye - np.array([0.0, 0.0, CAMERA_PUSH_PER_FRAME * max(b.frames - 1, 1)])
    poses = camera_paths.dolly(eye, end, (0.0, 0.6, -0.8), b.frames, b.up, ease=False)
    b.camera(poses, focal_length_mm=30.0, clipping=(0.05, 50.0))
