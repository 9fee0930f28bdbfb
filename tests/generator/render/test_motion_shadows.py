"""Shadows of shapes moving within the shutter from infinite emitters are never cut short.

Mitsuba ends a shadow ray towards an environment ``2 R`` beyond the shading point, ``R`` the radius of
the main scene's bounding sphere; moving shapes live outside the main scene (render/motion.py), so an
occluder further out than ``2 R`` cast no shadow in next-event estimation (light leaked). Here a wide slab hangs
over a small floor, far beyond ``2 R`` of the floor's bounds, and drifts within the shutter; the dome
is the only light. Our blurred frame must agree with the average of static sub-frame renders by
Mitsuba's ``path`` (where the slab is part of the scene, so its ``R`` covers it), block by block.
Measured: before the fix mean z² 2.1 (rejected; next-event estimation missed the slab, BSDF-sampled rays
still met it), after it 0.96; the image without the slab scores 24.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from pxr import Gf, UsdGeom

from denoisebench.generator.contract.render_plan import make_render_plan
from denoisebench.generator.render.frame import render_frame
from denoisebench.generator.render.motion import ShutterMotionScene
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
from denoisebench.generator.usd.translate import translate_stage
from denoisebench.mitsuba_runtime import load_mitsuba
from denoisebench.scenes import camera_paths, geometry
from denoisebench.scenes.authoring import SceneBuilder
from tests.support.motion_helpers import SIZE, block_z_scores, sub_frame_renders

FRAMES = 3
SLAB_HEIGHT = 4.0  # the floor's bounding radius is sqrt(2): 2 R = 2.83 < 4 - 0.1


def moving_box_stage(tmp_path):
    b = SceneBuilder(tmp_path, family="test", seed=0, frames=FRAMES, effects=("motion_blur", "environment"))
    b.mesh("Floor", geometry.grid(2.0, 2.0, 1, 1, axis="y"), b.material("Floor", diffuse=(0.8, 0.8, 0.8)))
    slab = b.mesh("Slab", geometry.box(size=(3.0, 0.2, 3.0)), b.material("Slab", diffuse=(0.5, 0.5, 0.5)))
    translate = UsdGeom.Xformable(slab).AddTranslateOp()
    for f in range(FRAMES):
        translate.Set(Gf.Vec3d(-1.0 + 1.0 * f, SLAB_HEIGHT, 0.0), float(f))
    b.dome_light("Sky", 1.0)
    eye = np.array([0.0, 2.2, 2.2])
    b.camera(camera_paths.dolly(eye, eye, (0.0, 0.0, 0.0), FRAMES, b.up, ease=False), 35.0, shutter=(-0.5, 0.5))
    return b.stage


def test_moving_occluder_beyond_twice_the_scene_radius_shadows_the_sky(tmp_path):
    mi = load_mitsuba()
    translated = translate_stage(moving_box_stage(tmp_path))
    assert translated.shutter_moving
    scene = build_mitsuba_scene(translated, frame=1)
    assert isinstance(scene, ShutterMotionScene)
    radius = scene.base.bbox().bounding_sphere().radius
    assert SLAB_HEIGHT - 0.1 > 2.0 * radius  # the slab lies beyond Mitsuba's shadow-ray length
    plan = make_render_plan(translated.effects)
    ours = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=256, seed=3, reference=True)
    subs = sub_frame_renders(mi, translated, 16, 64)
    z = block_z_scores(ours.buffers["color"], ours.buffers["color_var"], subs)
    assert np.abs(z).max() < 4.5 and np.mean(z**2) < 1.8, (np.abs(z).max(), np.mean(z**2))
    # Control: the image without the slab's shadow (what the 2 R shadow rays rendered) is rejected.
    bare = dataclasses.replace(translated, shapes=tuple(r for r in translated.shapes if r.shutter_motion is None))
    unshadowed = build_mitsuba_scene(bare, sensor_dict(translated.camera, 1, SIZE, SIZE, 256, seed=7), {"type": "path"})
    unshadowed = np.asarray(mi.render(unshadowed, spp=256, seed=7))[..., :3]
    z_bare = block_z_scores(unshadowed, ours.buffers["color_var"], subs)
    print("chi2", np.mean(z**2), np.abs(z).max(), "unshadowed", np.mean(z_bare**2), np.abs(z_bare).max())
    assert np.mean(z_bare**2) > 10.0, np.mean(z_bare**2)  # measured: 24 (accepted frames: < 1.8)
