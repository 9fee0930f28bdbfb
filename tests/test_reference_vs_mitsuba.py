"""References you can trust: our reference against Mitsuba's ``path`` integrator at its defaults.

For every scene family, and for stages the tests author without any denoisebench metadata (a
Cornell-style box; a stage with every supported light kind, rough and smooth materials and a
texture), the reference the dataset would store (adaptive rounds, :mod:`reference_render`) and
Mitsuba's ``{"type": "path"}`` (max_depth -1, rr_depth 5) render the same translated scene; their
image means and 4×4-block means must agree within the combined standard error. Ours comes from the
reference's variance of the mean (box filter: pixels independent), Mitsuba's from 16 independent
replicas. A control proves the statistics can fail: transport cut at depth 2 is rejected.

A second test proves that pruning leaves the expectation unchanged: the pruned plan (pinhole, no
time samples, no lobe split without glossy/specular effects) and the unpruned one (thin lens of zero
aperture, a time sample per ray, lobe-split evaluation) agree within noise.

Images are 24 px and a few hundred samples; most of the time is kernel compilation.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from plain_stages import author_every_light, author_plain_box

from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render.frame import render_frame
from denoisebench.generator.render.reference import render_adaptive, round_seed
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family, list_families

pytestmark = pytest.mark.slow

SIZE = 24
BLOCK = 4
OURS_SPP = 256  # 64 rounds of 4 (the adaptive reference's schedule at this cap)
REPLICAS, REPLICA_SPP = 16, 16


def our_reference(scene, translated, plan, frame, spp=OURS_SPP, seed=11):
    """The reference as the dataset renders it: adaptive rounds (target unreachable: all rounds run)."""

    def render_round(index, round_spp):
        out = render_frame(
            scene,
            translated.camera,
            frame,
            plan,
            width=SIZE,
            height=SIZE,
            spp=round_spp,
            seed=round_seed(seed, frame, index),
            reference=True,
        )
        return out.buffers, out.seconds, 0.0

    outcome = render_adaptive(render_round, spp, ref_error=1e-12)
    assert outcome.spp == spp
    return outcome.buffers


def mitsuba_path(mi, translated, scene, frame, aperture_scale=1.0):
    """REPLICAS independent renders by Mitsuba ``path`` at its defaults (box filter), R×H×W×3."""
    sensor = mi.load_dict(sensor_dict(translated.camera, frame, SIZE, SIZE, REPLICA_SPP, aperture_scale=aperture_scale))
    integrator = mi.load_dict({"type": "path"})
    images = [
        np.array(mi.render(scene, sensor=sensor, integrator=integrator, seed=500 + k, spp=REPLICA_SPP))[..., :3]
        for k in range(REPLICAS)
    ]
    return np.stack(images).astype(np.float64)


def block_means(image):
    *lead, h, w, c = image.shape
    return image.reshape(*lead, h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean(axis=(-4, -2))


def z_scores(mean_a, var_a, mean_b, var_b):
    """z of a − b for the image mean (per channel) and every block mean (per channel); inputs are
    per-pixel means and variances of those means (independent pixels)."""
    n = BLOCK * BLOCK
    # Float rounding (1e-6 relative) stands in for the variance where both have none (a constant sky).
    a_blocks, b_blocks = block_means(mean_a), block_means(mean_b)
    blocks = (a_blocks - b_blocks) / np.sqrt(
        (block_means(var_a) + block_means(var_b)) / n + np.square(1e-6 * (np.abs(a_blocks) + np.abs(b_blocks))) + 1e-20
    )
    pixels = mean_a[..., 0].size
    a_image, b_image = mean_a.mean(axis=(0, 1)), mean_b.mean(axis=(0, 1))
    image = (a_image - b_image) / np.sqrt(
        (var_a.sum(axis=(0, 1)) + var_b.sum(axis=(0, 1))) / pixels**2
        + np.square(1e-6 * (np.abs(a_image) + np.abs(b_image)))
        + 1e-30
    )
    return image, blocks


def replicas_as_mean(replicas):
    return replicas.mean(axis=0), replicas.var(axis=0, ddof=1) / len(replicas)


def assert_agree(z_image, z_blocks):
    assert np.all(np.abs(z_image) < 4.0), z_image
    # Mitsuba's variances come from 16 replicas (t with 15 dof) and fireflies make tails heavy:
    # a few blocks beyond 4, none extreme.
    assert np.mean(np.abs(z_blocks) > 4.0) <= 0.05, np.sort(np.abs(z_blocks).ravel())[-8:]
    assert np.abs(z_blocks).max() < 8.0, np.sort(np.abs(z_blocks).ravel())[-8:]


def _compare(mi, translated, frame, plan):
    scene = build_mitsuba_scene(translated, shutter_motion=False)  # one mi.Scene for both (frame poses)
    ours = our_reference(scene, translated, plan, frame)
    theirs = mitsuba_path(mi, translated, scene, frame, aperture_scale=plan.aperture_scale)
    assert ours["color"].mean() > 1e-3, "a black image compares nothing"
    mean_b, var_b = replicas_as_mean(theirs)
    return (
        scene,
        ours,
        (mean_b, var_b),
        z_scores(ours["color"].astype(np.float64), ours["color_var"].astype(np.float64), mean_b, var_b),
    )


@pytest.mark.parametrize("family", [f.name for f in list_families()])
def test_every_family_reference_matches_mitsuba_path(mi, tmp_path, family):
    translated = translate_usd(get_family(family).author(tmp_path, seed=0, frames=2, width=SIZE, height=SIZE))
    plan = make_render_plan(translated.effects, stage_max_depth=translated.max_depth)
    assert plan.max_depth == -1 and plan.max_depth_source == "default"  # families render full transport
    if plan.time_sampling:
        # Mitsuba's sensor cannot move the camera within the shutter: compare the frame's own pose
        # (without time samples our camera sits at the frame's pose, as Mitsuba's does).
        plan = dataclasses.replace(
            plan, time_sampling=False, random_parameters=tuple(p for p in plan.random_parameters if p != "time")
        )
    _, _, _, (z_image, z_blocks) = _compare(mi, translated, 1, plan)
    assert_agree(z_image, z_blocks)


def test_cluttered_blurred_reference_matches_a_mitsuba_sub_frame_average(mi, tmp_path):
    """Object motion blur and a moving camera (cluttered seed 0) against 32 static sub-frames by ``path``.

    Sub-frame times are stratified and jittered over frame 1's shutter; each sub-frame freezes the
    moving shapes (``translated_at``) and the camera at its time. Their average's variance is the
    paired-strata estimate (conservative for stratified sampling).

    Pitfall: at 24 px this scene's blur is about a pixel, so the frame frozen at its time code passes
    too (measured: worst block z 2.9); the power against a wrong blur is in tests/test_object_motion.py,
    whose control rejects the frozen frame. This one checks the whole path on a real cluttered stage
    (moving camera, several moving shapes, glass and mirrors, environment) for bias."""
    from denoisebench.generator.render.motion import translated_at

    translated = translate_usd(get_family("cluttered").author(tmp_path, seed=0, frames=2, width=SIZE, height=SIZE))
    assert translated.shutter_moving
    plan = make_render_plan(translated.effects, stage_max_depth=translated.max_depth)
    assert plan.time_sampling
    ours = our_reference(build_mitsuba_scene(translated, frame=1), translated, plan, 1)
    camera = translated.camera
    rng = np.random.default_rng(1)
    count = 32
    centre, span = 1 + 0.5 * (camera.shutter_open + camera.shutter_close), camera.shutter_close - camera.shutter_open
    subs = []
    for i in range(count):
        tau = centre + span * ((i + rng.random()) / count - 0.5)
        scene = build_mitsuba_scene(translated_at(translated, tau), shutter_motion=False)
        sensor = sensor_dict(camera, tau, SIZE, SIZE, REPLICA_SPP)
        sensor["to_world"] = mi.ScalarTransform4f(np.asarray(camera.mitsuba_to_world(tau), dtype=np.float64).tolist())
        image = mi.render(scene, sensor=mi.load_dict(sensor), integrator=mi.load_dict({"type": "path"}), seed=900 + i)
        subs.append(np.array(image)[..., :3].astype(np.float64))
    subs = np.stack(subs)
    var_b = np.sum(np.square(subs[0::2] - subs[1::2]), axis=0) / count**2
    z_image, z_blocks = z_scores(
        ours["color"].astype(np.float64), ours["color_var"].astype(np.float64), subs.mean(0), var_b
    )
    assert_agree(z_image, z_blocks)


def test_plain_box_without_metadata_matches_mitsuba_path_and_a_cut_does_not(mi, tmp_path):
    translated = translate_usd(author_plain_box(tmp_path / "box.usda"))
    assert translated.effects_declared == () and translated.max_depth is None
    plan = make_render_plan(translated.effects)
    assert plan.max_depth == -1
    scene, _, (mean_b, var_b), (z_image, z_blocks) = _compare(mi, translated, 0, plan)
    assert_agree(z_image, z_blocks)
    # The control: direct light only (what the old plan gave a stage without an `indirect` declaration).
    cut = our_reference(scene, translated, make_render_plan(translated.effects, RenderOptions(max_depth=2)), 0)
    z_image, z_blocks = z_scores(cut["color"].astype(np.float64), cut["color_var"].astype(np.float64), mean_b, var_b)
    assert np.all(z_image < -4.0) and z_image.mean() < -8.0, z_image  # measured: -18, -12, -6 (R, G, B)
    assert np.mean(np.abs(z_blocks) > 4.0) > 0.5


def test_every_light_kind_stage_matches_mitsuba_path(mi, tmp_path):
    translated = translate_usd(author_every_light(tmp_path / "lights.usda"))
    assert translated.effects_declared == () and not translated.warnings, translated.warnings
    kinds = {e["type"] for e in translated.scene_dict["emitters"]} | {
        s["emitter"]["type"] for s in translated.scene_dict["shapes"] if s.get("emitter")
    }
    assert {"area", "point", "spot", "directional", "constant"} <= kinds, kinds
    assert {"textures", "glossy", "specular", "transmission"} <= set(translated.effects)
    plan = make_render_plan(translated.effects)
    _, _, _, (z_image, z_blocks) = _compare(mi, translated, 0, plan)
    assert_agree(z_image, z_blocks)


def test_pruned_and_unpruned_plans_agree_in_expectation(mi, tmp_path):
    """What the plan skips (thin lens of zero aperture, time samples of a static camera, the lobe split
    of a scene without glossy/specular effects) changes the work, not the expected image."""
    box = translate_usd(author_plain_box(tmp_path / "box.usda"))  # static camera, no depth of field
    cornell = translate_usd(
        get_family("cornell").author(tmp_path / "cornell", seed=0, frames=2, width=SIZE, height=SIZE)
    )
    for translated, frame, with_time in ((box, 0, True), (cornell, 1, False)):
        pruned = make_render_plan(translated.effects)
        assert pruned.camera_model == "pinhole" and not pruned.time_sampling
        unpruned = dataclasses.replace(
            pruned,
            camera_model="thin_lens",
            time_sampling=with_time,
            lobe_split=True,
            random_parameters=("pixel", "lens") + (("time",) if with_time else ()),
        )
        scene = build_mitsuba_scene(translated)
        a = our_reference(scene, translated, pruned, frame, seed=21)
        b = our_reference(scene, translated, unpruned, frame, seed=22)
        z_image, z_blocks = z_scores(
            *(x.astype(np.float64) for x in (a["color"], a["color_var"], b["color"], b["color_var"]))
        )
        assert np.all(np.abs(z_image) < 4.0), z_image
        assert np.mean(np.abs(z_blocks) > 4.0) <= 0.02 and np.abs(z_blocks).max() < 6.0
        np.testing.assert_allclose(b["diffuse"] + b["specular"], b["color"], rtol=1e-4, atol=1e-5)
