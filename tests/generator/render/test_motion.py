"""Object motion blur within the shutter (render/motion.py): unbiased against Mitsuba sub-frame averages.

The statistical test: a box moving (translating and turning, or stretching) during a one-frame shutter
under a static camera. Our blurred reference (1024 spp) must agree, block by block, with the average of
32 static sub-frame renders by Mitsuba's ``path`` at jittered stratified times (each an unbiased
estimate of the time integral). The sub-frame average's variance is the paired-strata estimate
``Σ (x_2i - x_2i+1)² / N²`` (conservative for stratified sampling). The same test must reject the
frame frozen at its time code (the image before object motion blur existed).
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.generator.contract.render_plan import make_render_plan
from denoisebench.generator.render.frame import render_frame
from denoisebench.generator.render.motion import ShutterMotionScene, pose_matrices, translated_at
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
from denoisebench.generator.usd import geometry as usd_geometry
from denoisebench.generator.usd.stage import stage_to_mitsuba_matrix
from denoisebench.generator.usd.translate import translate_stage
from denoisebench.mitsuba_runtime import load_mitsuba
from tests.support.motion_helpers import SIZE, block_z_scores, moving_box_stage, sub_frame_renders


@pytest.mark.parametrize("kind", ["rigid", "stretch"])
def test_blur_converges_to_sub_frame_average(tmp_path, kind):
    mi = load_mitsuba()
    translated = translate_stage(moving_box_stage(tmp_path, kind))
    assert translated.shutter_moving and "motion_blur" in translated.effects
    plan = make_render_plan(translated.effects)
    scene = build_mitsuba_scene(translated, frame=1)
    assert isinstance(scene, ShutterMotionScene)
    blur = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=1024, seed=3, reference=True)
    subs = sub_frame_renders(mi, translated, 32, 64)
    z = block_z_scores(blur.buffers["color"], blur.buffers["color_var"], subs)
    assert np.abs(z).max() < 4.5 and np.mean(z**2) < 1.8, (np.abs(z).max(), np.mean(z**2))

    # Sensitivity: the frame frozen at its time code (what Mitsuba renders) is rejected by the same test.
    frozen_scene = build_mitsuba_scene(
        translated, sensor_dict(translated.camera, 1, SIZE, SIZE, 1024, seed=9), {"type": "path"}, frame=1
    )
    frozen = np.asarray(mi.render(frozen_scene, spp=1024, seed=5))[..., :3]
    z_frozen = block_z_scores(frozen, blur.buffers["color_var"], subs)
    print("chi2", np.mean(z**2), np.abs(z).max(), "frozen", np.mean(z_frozen**2), np.abs(z_frozen).max())
    assert np.mean(z_frozen**2) > 2.5, np.mean(z_frozen**2)


def test_host_pose_matches_usd_between_frames(tmp_path):
    """Translate + rotateY (+ scale) ops: the interpolated pose is USD's own at fractional time codes."""
    for kind in ("rigid", "stretch"):
        stage = moving_box_stage(tmp_path / kind, kind)
        translated = translate_stage(stage)
        motion = next(s.shutter_motion for s in translated.shapes if s.shutter_motion is not None)
        prim = stage.GetPrimAtPath("/World/Geometry/Box")
        to_mitsuba = stage_to_mitsuba_matrix(stage)
        for tau in (0.1, 0.55, 1.3, 1.99):
            usd = to_mitsuba @ usd_geometry.local_to_world(prim, tau)
            np.testing.assert_allclose(pose_matrices(motion, tau), usd, atol=2e-3 if kind == "stretch" else 1e-6)


def test_motion_vectors_follow_the_object(tmp_path):
    """Static camera: motion on the moving box points back along its travel (+x), at the shutter's centre."""
    translated = translate_stage(moving_box_stage(tmp_path))
    plan = make_render_plan(translated.effects)
    out = render_frame(
        build_mitsuba_scene(translated, frame=1), translated.camera, 1, plan, width=SIZE, height=SIZE, spp=8, seed=1
    )
    motion = out.buffers["motion"]
    moving = np.linalg.norm(motion, axis=-1) > 0.5
    assert moving.sum() >= 4
    assert np.all(motion[moving][:, 0] < 0.0)  # previous position is to the left (the box moves right)
    # Background and floor: static camera, static geometry: no motion.
    assert np.abs(motion[~moving]).max() < 0.5


def test_closed_shutter_keeps_between_frame_motion_only(tmp_path):
    translated = translate_stage(moving_box_stage(tmp_path, shutter=(0.0, 0.0)))
    assert not translated.shutter_moving and translated.moving
    assert "motion_blur" not in translated.effects
    assert not isinstance(build_mitsuba_scene(translated, frame=1), ShutterMotionScene)


def test_moving_emitter_is_refused_with_a_warning(tmp_path):
    translated = translate_stage(moving_box_stage(tmp_path, emissive=True))
    assert not translated.shutter_moving
    assert any("emissive geometry moving within the shutter is not supported" in w for w in translated.warnings)


def test_sub_frame_copy_leaves_the_original_alone(tmp_path):
    translated = translate_stage(moving_box_stage(tmp_path))
    before = [s.positions.copy() for s in translated.shapes]
    frozen = translated_at(translated, 1.25)
    assert not frozen.shutter_moving
    for shape, positions in zip(translated.shapes, before):
        np.testing.assert_array_equal(shape.positions, positions)
    moved = [s for s, o in zip(frozen.shapes, before) if not np.array_equal(s.positions, o)]
    assert len(moved) == 1
