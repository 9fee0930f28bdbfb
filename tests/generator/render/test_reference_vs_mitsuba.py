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

Object motion blur, which Mitsuba cannot render: a cluttered stage with depth of field and movers,
taken through ``generate-dataset``, must store a blurred reference that agrees with the average of
static sub-frame renders by ``path``, while the frame with its objects frozen is rejected.

Images are 24 px (the blurred check: 32 px) and a few hundred samples; most of the time is kernel compilation.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render.frame import render_frame
from denoisebench.generator.render.reference import render_adaptive, round_seed
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family, list_families
from tests.support.plain_stages import author_every_light, author_plain_box

pytestmark = pytest.mark.slow

SIZE = 24
BLOCK = 4
OURS_SPP = 256  # 64 rounds of 4 (the adaptive reference's schedule at this cap)
REPLICAS, REPLICA_SPP = 16, 16
#: Cluttered seed with depth of field and six objects moving within the shutter; their motion scaled ×SPEED_UP.
BLUR_SEED, SPEED_UP = 152, 6.0


def our_reference(scene, translated, plan, frame, spp=OURS_SPP, seed=11, size=SIZE):
    """The reference as the dataset renders it: adaptive rounds (target unreachable: all rounds run)."""

    def render_round(index, round_spp):
        out = render_frame(
            scene,
            translated.camera,
            frame,
            plan,
            width=size,
            height=size,
            spp=round_spp,
            seed=round_seed(seed, frame, index),
            reference=True,
        )
        return out.buffers, out.seconds, 0.0

    outcome = render_adaptive(render_round, spp, ref_error=1e-12)
    assert outcome.spp == spp
    return outcome.buffers


def mitsuba_path(mi, translated, scene, frame, aperture_scale=1.0):
    """REPLICAS independent renders by Mitsuba ``path`` at its defaults (box filter), R×H×W×3; ``volpath``
    (also at its defaults) for a scene with participating media, which ``path`` does not render."""
    sensor = mi.load_dict(sensor_dict(translated.camera, frame, SIZE, SIZE, REPLICA_SPP, aperture_scale=aperture_scale))
    integrator = mi.load_dict({"type": "volpath" if "media" in translated.effects else "path"})
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
    # Cluttered: the blurred check's seed (depth of field, movers), here at its frame's pose: the static frame.
    seed = BLUR_SEED if family == "cluttered" else 0
    translated = translate_usd(get_family(family).author(tmp_path, seed=seed, frames=2, width=SIZE, height=SIZE))
    if family == "cluttered":
        assert {"depth_of_field", "motion_blur"} <= set(translated.effects) and translated.shutter_moving
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


def _speed_up_movers(usd_path, factor: float, frame: float = 1.0) -> None:
    """Scale every time-sampled op of the cluttered objects about its value at ``frame`` (travel and turn ×factor)."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(usd_path))
    for prim in stage.Traverse():
        if not prim.GetName().startswith("Object"):
            continue
        for op in UsdGeom.Xformable(prim).GetOrderedXformOps():
            times = op.GetTimeSamples()
            if len(times) < 2:
                continue
            pivot = op.Get(frame)
            for t in times:
                value = op.Get(t)
                op.Set(type(value)(pivot + factor * (value - pivot)), t)
    stage.GetRootLayer().Save()


def test_cluttered_blurred_dataset_reference_matches_a_sub_frame_average_and_a_frozen_one_does_not(mi, tmp_path):
    """A cluttered stage with depth of field, object motion blur and a moving camera, rendered by
    ``generate-dataset``: its stored reference of frame 1 agrees with 32 static sub-frame renders by ``path``
    (tests/support/motion_helpers.py), and the same frame with the objects frozen at its time code (the camera
    still moving, the lens still open: the image before object motion blur existed) is rejected.

    Notes
    -----
    The family's movers travel 0.04-0.13 units and turn up to 75 degrees within the half-frame shutter,
    objects 0.3-0.9 units across seen whole, a few pixels each at 32 px: the blur is too small for a
    CI-sized render to resolve (seed 152 as authored, measured: blurred mean z² 0.97, frozen 1.11; with
    turns of at most 20 degrees, over seeds 0-193 no 4×4 block of a 32 px albedo image changed by more
    than 0.02). So the stage is seed
    152 (six movers, depth of field) with its movers' travel and turn scaled ×6 about frame 1: measured
    at 32 px, 256 spp, 32×16 sub-frame spp, blurred worst block z 3.1, mean z² 0.93; frozen worst block
    z 9.8, mean z² 4.0, 8 % of blocks beyond 4; over four more noise draws (sub-frame times and seeds,
    our seeds) blurred mean z² 0.75-1.20, frozen 3.35-4.33, while the frozen frame's worst block (7.4-11.9)
    and share beyond 4 (4-7 %) straddle :func:`assert_agree`'s limits: the blocks' mean z² is the
    criterion with power, and the control must fail it. Frame 1 is the last of two, so USD holds the
    poses after it: half the shutter moves, the sub-frames see the same clamp. Cost (2 cores): 20 s with
    Dr.Jit's kernel cache warm, 49 s cold on a loaded machine, mostly kernel compilation
    (generate-dataset's noisy and reference kernels, the frozen scene's, ``path``'s)."""
    from denoisebench.cli import main
    from denoisebench.dataset import open_dataset
    from tests.support.motion_helpers import paired_strata_variance, sub_frame_renders

    size, spp = 32, 256
    shot = get_family("cluttered").author(tmp_path / "shot", seed=BLUR_SEED, frames=2, width=size, height=size)
    _speed_up_movers(shot, SPEED_UP)
    translated = translate_usd(shot)
    assert {"depth_of_field", "motion_blur"} <= set(translated.effects) and translated.shutter_moving
    plan = make_render_plan(translated.effects, stage_max_depth=translated.max_depth)
    assert plan.time_sampling and plan.camera_model == "thin_lens"
    common = ["--width", str(size), "--height", str(size), "--spp", "1", "--ref-spp", str(spp)]
    assert (
        main(["generate", "--out", str(tmp_path / "ds"), "--usd", str(shot), *common, "--ref-error", "0", "--quiet"])
        == 0
    )
    dataset = open_dataset(tmp_path / "ds", verify=True)
    (scene_name,) = dataset.scenes
    assert {"depth_of_field", "motion_blur"} <= set(dataset.scene(scene_name).effects["inferred"])
    layers, record = dataset.reference(scene_name, 1)
    assert record["spp"] == spp
    subs = sub_frame_renders(mi, translated, 32, 16, size=size, frame=1)
    mean_b, var_b = np.mean(subs, axis=0, dtype=np.float64), paired_strata_variance(subs)
    ours = layers["color"].astype(np.float64), layers["color_var"].astype(np.float64)
    assert ours[0].mean() > 1e-2, "a black image compares nothing"
    z_image, z_blocks = z_scores(*ours, mean_b, var_b)
    frozen = render_frame(
        build_mitsuba_scene(translated, frame=1, shutter_motion=False),
        translated.camera,
        1,
        plan,
        width=size,
        height=size,
        spp=spp,
        seed=12,
        reference=True,
    ).buffers
    z_frozen = z_scores(frozen["color"].astype(np.float64), frozen["color_var"].astype(np.float64), mean_b, var_b)[1]
    print(
        "blurred", np.abs(z_blocks).max(), np.mean(z_blocks**2), "frozen", np.abs(z_frozen).max(), np.mean(z_frozen**2)
    )
    assert_agree(z_image, z_blocks)
    assert np.mean(z_blocks**2) < 1.8, np.mean(z_blocks**2)  # the blocks' chi², the powerful part here
    # The control fails the same criterion, by the chi² clause (measured 3.4-4.3 over five noise draws).
    assert np.mean(z_frozen**2) > 2.5, np.mean(z_frozen**2)


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
    kinds = {e.kind for e in translated.emitters} | {"area" for s in translated.shapes if s.emitter is not None}
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
