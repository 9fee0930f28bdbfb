"""The feature renderer against Mitsuba's own integrators, and its invariants.

Peers: Mitsuba's ``path`` integrator (the color estimator must be unbiased for the very image it
renders at the same max depth) and its ``aov`` integrator (features at pixel centers). Invariants:
diffuse + specular = color, per-sample data averaging to the stored means and variances,
determinism, independent streams, channels present only when the plan calls for them, finiteness
on black frames, backgrounds and odd sizes. Images are 16-32 px; Mitsuba kernels compile once per
scene and integrator, which is most of this file's time.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage, stats

from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render.frame import load_scene, render_frame
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family

SIZE = 24
BLOCK = 4  # block means over 4×4 pixels: 36 blocks × 3 channels per image


@pytest.fixture(scope="module")
def family_scene(mi, tmp_path_factory):
    """``family_scene(name, frames=2)`` → (translated scene, Mitsuba scene), authored once per module."""
    cache = {}

    def get(name: str, frames: int = 2):
        key = (name, frames)
        if key not in cache:
            out = tmp_path_factory.mktemp(f"{name}_{frames}")
            translated = translate_usd(get_family(name).author(out, seed=0, frames=frames, width=SIZE, height=SIZE))
            cache[key] = (translated, build_mitsuba_scene(translated))
        return cache[key]

    return get


def mitsuba_path_replicas(mi, translated, scene, plan, *, frame: int, spp: int, replicas: int, max_depth: int):
    """``replicas`` independent renders by Mitsuba's ``path`` integrator (box filter), R×H×W×3."""
    sensor = mi.load_dict(sensor_dict(translated.camera, frame, SIZE, SIZE, spp, aperture_scale=plan.aperture_scale))
    integrator = mi.load_dict(
        {"type": "path", "max_depth": max_depth, "rr_depth": plan.rr_depth, "hide_emitters": False}
    )
    images = [
        np.array(mi.render(scene, sensor=sensor, integrator=integrator, seed=1000 + k, spp=spp))[..., :3]
        for k in range(replicas)
    ]
    return np.stack(images).astype(np.float64)


def block_means(image: np.ndarray) -> np.ndarray:
    """Means over BLOCK×BLOCK pixel blocks, per channel (leading axes kept)."""
    *lead, h, w, c = image.shape
    return image.reshape(*lead, h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean(axis=(-4, -2))


def agreement(ours_mean: np.ndarray, ours_var: np.ndarray, replicas: np.ndarray):
    """z-scores of ours − Mitsuba for the image mean and every block mean (per channel).

    Our variance of a block mean is the sum of its pixels' variances of the mean / n² (box filter:
    pixels are independent); Mitsuba's comes from its independent replicas.
    """
    n = BLOCK * BLOCK
    ours_blocks = block_means(ours_mean.astype(np.float64))
    ours_block_var = block_means(ours_var.astype(np.float64)) / n
    rep_blocks = block_means(replicas)
    count = len(replicas)
    theirs_blocks = rep_blocks.mean(axis=0)
    theirs_block_var = rep_blocks.var(axis=0, ddof=1) / count
    z_blocks = (ours_blocks - theirs_blocks) / np.sqrt(ours_block_var + theirs_block_var + 1e-20)

    ours_image = ours_mean.mean(axis=(0, 1), dtype=np.float64)
    ours_image_var = ours_var.astype(np.float64).sum(axis=(0, 1)) / ours_var[..., 0].size ** 2
    rep_image = replicas.mean(axis=(1, 2))
    z_image = (ours_image - rep_image.mean(axis=0)) / np.sqrt(ours_image_var + rep_image.var(axis=0, ddof=1) / count)
    return z_image, z_blocks


@pytest.mark.parametrize("family, spp", [("cornell", 128), ("glossy_fireflies", 128), ("depth_of_field", 128)])
def test_color_is_unbiased_against_mitsuba_path(mi, family_scene, family, spp):
    translated, scene = family_scene(family)
    plan = make_render_plan(translated.effects)
    ours = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=spp, seed=7, reference=True)
    replicas = mitsuba_path_replicas(
        mi, translated, scene, plan, frame=1, spp=spp // 16, replicas=16, max_depth=plan.max_depth
    )
    assert ours.buffers["color"].mean() > 1e-3  # a lit image, so the comparison means something
    z_image, z_blocks = agreement(ours.buffers["color"], ours.buffers["color_var"], replicas)
    assert np.all(np.abs(z_image) < 4.0), z_image
    # Mitsuba's block variances come from 16 replicas (t with 15 dof) and fireflies make tails heavy:
    # allow a few outliers, none extreme.
    assert np.mean(np.abs(z_blocks) > 4.0) <= 0.05, np.sort(np.abs(z_blocks).ravel())[-8:]
    assert np.abs(z_blocks).max() < 8.0

    if family == "cornell":
        # The same statistics catch a biased renderer: paths cut at depth 2 (direct light only)
        # against Mitsuba at the plan's depth (unbounded) lose the indirect light.
        short = make_render_plan(translated.effects, RenderOptions(max_depth=2))
        biased = render_frame(
            scene, translated.camera, 1, short, width=SIZE, height=SIZE, spp=spp, seed=7, reference=True
        )
        z_image, z_blocks = agreement(biased.buffers["color"], biased.buffers["color_var"], replicas)
        assert np.all(z_image < -6.0), z_image  # measured: -21, -17, -10 (R, G, B)
        assert np.mean(np.abs(z_blocks) > 4.0) > 0.5


def test_diffuse_plus_specular_is_color(mi, family_scene):
    translated, scene = family_scene("glossy_fireflies")
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    assert plan.lobe_split
    out = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=4, seed=3)
    samples = out.samples
    # Both lobes carry light in this scene, so the split is not trivially all-diffuse.
    assert samples["specular"].max() > 1e-3 and samples["diffuse"].max() > 0.1
    assert np.allclose(samples["diffuse"] + samples["specular"], samples["color"], rtol=1e-5, atol=1e-6)
    buffers = out.buffers
    assert np.allclose(buffers["diffuse"] + buffers["specular"], buffers["color"], rtol=1e-5, atol=1e-6)


def aov_render(mi, translated, scene, frame: int):
    """Mitsuba's ``aov`` integrator with one unjittered sample per pixel (stratified, jitter off)."""
    sensor_data = sensor_dict(translated.camera, frame, SIZE, SIZE, 1)
    sensor_data["sampler"] = {"type": "stratified", "sample_count": 1, "jitter": False}
    sensor = mi.load_dict(sensor_data)
    integrator = mi.load_dict({"type": "aov", "aovs": "al:albedo,nn:sh_normal,pp:position"})
    mi.render(scene, sensor=sensor, integrator=integrator, spp=1)
    bitmap = sensor.film().bitmap()
    names = [bitmap.struct_()[k].name for k in range(bitmap.channel_count())]
    data = np.array(bitmap, dtype=np.float64)
    pick = {name: data[..., names.index(name)] for name in names}
    return {
        "albedo": np.stack([pick["al.R"], pick["al.G"], pick["al.B"]], -1),
        "normal": np.stack([pick["nn.X"], pick["nn.Y"], pick["nn.Z"]], -1),
        "position": np.stack([pick["pp.X"], pick["pp.Y"], pick["pp.Z"]], -1),
    }


@pytest.mark.parametrize("family", ["cornell", "glossy_fireflies"])
def test_features_match_mitsuba_aov(mi, family_scene, family):
    translated, scene = family_scene(family)
    plan = make_render_plan(translated.effects)
    ours = render_frame(
        scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=2, seed=0, _jitter=False
    ).buffers
    theirs = aov_render(mi, translated, scene, 1)
    hit = (ours["depth"][..., 0] > 0) & (np.abs(theirs["position"]).sum(-1) > 0)
    assert hit.mean() > 0.5
    for name in ("albedo", "normal", "position"):
        close = np.all(np.abs(ours[name] - theirs[name]) <= 1e-3 * (1 + np.abs(theirs[name])), axis=-1)
        # Rays are built by different code (float rounding): allow a silhouette pixel to differ.
        assert close[hit].mean() >= 0.99, (name, close[hit].mean())
    # Depth is the camera-space z of the first hit: compare with Mitsuba's hit positions.
    pose = translated.camera.mitsuba_to_world(1.0)
    forward = pose[:3, 2] / np.linalg.norm(pose[:3, 2])
    depth_theirs = (theirs["position"] - pose[:3, 3]) @ forward
    close = np.abs(ours["depth"][..., 0] - depth_theirs) <= 1e-3 * (1 + depth_theirs)
    assert close[hit].mean() >= 0.99
    assert np.allclose(np.linalg.norm(ours["normal"][hit], axis=-1), 1.0, atol=1e-4)


def warp_error(previous: np.ndarray, current: np.ndarray, motion: np.ndarray) -> tuple[float, float]:
    """Mean |warped previous − current| and |previous − current| over pixels whose source is inside."""
    rows, cols = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    src_rows, src_cols = rows + motion[..., 1], cols + motion[..., 0]
    inside = (src_rows >= 0) & (src_rows <= SIZE - 1) & (src_cols >= 0) & (src_cols <= SIZE - 1)
    assert inside.mean() > 0.3
    warped = np.stack(
        [ndimage.map_coordinates(previous[..., c], [src_rows, src_cols], order=1, mode="nearest") for c in range(3)], -1
    )
    return np.abs(warped - current)[inside].mean(), np.abs(previous - current)[inside].mean()


def test_motion_vectors_warp_previous_frame(mi, family_scene):
    # The Cornell family's camera dollies in and slides sideways between frames.
    translated, scene = family_scene("cornell")
    assert translated.camera.is_animated
    plan = make_render_plan(translated.effects)
    previous = render_frame(scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=32, seed=1, reference=True)
    current = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=32, seed=1)
    motion = current.buffers["motion"].astype(np.float64)
    assert np.abs(motion).mean() > 0.3  # not trivially zero
    prev_color = previous.buffers["color"].astype(np.float64)
    target = current.buffers["color"].astype(np.float64)
    warped_error, unwarped_error = warp_error(prev_color, target, motion)
    # Measured at 32 px, 64 spp: 0.067 warped against 0.248 unwarped; reversed vectors give 0.249.
    assert warped_error < 0.5 * unwarped_error, (warped_error, unwarped_error)
    reversed_error, _ = warp_error(prev_color, target, -motion)
    assert warped_error < 0.5 * reversed_error

    # Frame 0 has no previous frame: zero motion.
    first = render_frame(scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=1, seed=1)
    assert not first.buffers["motion"].any()


def test_per_sample_data_averages_to_means(mi, family_scene):
    translated, scene = family_scene("depth_of_field")
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    spp = 6
    out = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=spp, seed=5)
    for name, values in out.samples.items():
        assert values.shape[:3] == (spp, SIZE, SIZE), name
        if name in out.buffers:
            values = values.astype(np.float64)
            assert np.allclose(values.mean(0), out.buffers[name], rtol=1e-5, atol=1e-5), name
            assert np.allclose(values.var(0, ddof=1) / spp, out.buffers[f"{name}_var"], rtol=1e-3, atol=1e-6), name
    for name in ("pixel", "lens"):
        assert 0.0 <= out.samples[name].min() and out.samples[name].max() < 1.0
        assert 0.4 < out.samples[name].mean() < 0.6  # uniform numbers, not a constant
    # Samples split over several lanes per pixel, or one lane looping over all: same statistics.
    one_lane = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=spp, seed=5, target_lanes=1)
    assert np.allclose(one_lane.samples["color"].mean(0), one_lane.buffers["color"], rtol=1e-5, atol=1e-5)


def test_random_parameter_channels_follow_the_plan(mi, family_scene):
    translated, scene = family_scene("cornell")
    plain = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    scaled = make_render_plan(translated.effects, RenderOptions(per_sample=True, aperture_scale=3.0, shutter_scale=0.2))
    a = render_frame(scene, translated.camera, 1, plain, width=SIZE, height=SIZE, spp=2, seed=2)
    b = render_frame(scene, translated.camera, 1, scaled, width=SIZE, height=SIZE, spp=2, seed=2)
    assert set(a.samples) >= {"pixel", "color"} and not {"lens", "time"} & set(a.samples)
    assert a.buffers.keys() == b.buffers.keys()
    for name in a.buffers:
        assert np.array_equal(a.buffers[name], b.buffers[name]), name

    dof, dof_scene = family_scene("depth_of_field")
    dof_plan = make_render_plan(dof.effects, RenderOptions(per_sample=True))
    out = render_frame(dof_scene, dof.camera, 1, dof_plan, width=SIZE, height=SIZE, spp=2, seed=2)
    assert "lens" in out.samples and "time" not in out.samples
    # There the aperture option does act (so the check above could fail).
    pinhole = make_render_plan(dof.effects, RenderOptions(per_sample=True, aperture_scale=0.0))
    sharp = render_frame(dof_scene, dof.camera, 1, pinhole, width=SIZE, height=SIZE, spp=2, seed=2)
    assert not np.array_equal(sharp.buffers["color"], out.buffers["color"])

    blur, blur_scene = family_scene("motion_blur")
    blur_plan = make_render_plan(blur.effects, RenderOptions(per_sample=True))
    out = render_frame(blur_scene, blur.camera, 1, blur_plan, width=SIZE, height=SIZE, spp=2, seed=2)
    assert "time" in out.samples and "lens" not in out.samples
    assert 0.0 <= out.samples["time"].min() and out.samples["time"].max() < 1.0


def test_determinism_and_independent_streams(mi, family_scene):
    translated, scene = family_scene("cornell")
    plan = make_render_plan(translated.effects)
    kwargs = dict(width=SIZE, height=SIZE, spp=4, seed=11)
    first = render_frame(scene, translated.camera, 1, plan, **kwargs)
    again = render_frame(scene, translated.camera, 1, plan, **kwargs)
    for name in first.buffers:
        assert np.array_equal(first.buffers[name], again.buffers[name]), name
    reference = render_frame(scene, translated.camera, 1, plan, reference=True, **kwargs)
    reference_again = render_frame(scene, translated.camera, 1, plan, reference=True, **kwargs)
    assert np.array_equal(reference.buffers["color"], reference_again.buffers["color"])
    assert set(reference.buffers) == {"color", "diffuse", "specular", "color_var", "diffuse_var", "specular_var"}
    # Same seed, other stream: the two renders' errors against a 64-spp estimate are uncorrelated
    # (rank correlation, so that fireflies do not dominate it; the same stream would give 1).
    lit = first.buffers["color"] > 0
    assert not np.array_equal(first.buffers["color"], reference.buffers["color"])
    truth = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=64, seed=99, reference=True)
    error_noisy = (first.buffers["color"] - truth.buffers["color"])[lit]
    error_reference = (reference.buffers["color"] - truth.buffers["color"])[lit]
    assert abs(stats.spearmanr(error_noisy, error_reference).statistic) < 0.2
    # Another seed gives other noise too.
    other_seed = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=4, seed=12)
    assert (
        abs(stats.spearmanr(error_noisy, (other_seed.buffers["color"] - truth.buffers["color"])[lit]).statistic) < 0.2
    )


def test_buffers_finite_on_hard_cases(mi, family_scene):
    # Environment light, glass and misses: background pixels exist and must be finite.
    translated, scene = family_scene("glass_env")
    plan = make_render_plan(translated.effects)
    out = render_frame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=4, seed=0)
    check_finite(out.buffers)
    miss = out.buffers["depth"][..., 0] == 0
    for name in ("albedo", "normal", "position", "roughness"):
        assert not out.buffers[name][miss].any(), name

    # A black frame (no light at all) at an odd size: zero color, zero variance, nothing NaN.
    black = load_scene({"type": "scene", "ball": {"type": "sphere", "radius": 0.5}})
    pose = np.eye(4)
    pose[2, 3] = 3.0
    camera = CameraTrack(poses=np.stack([pose, pose]), fov_x_deg=40.0)
    plan = make_render_plan(["indirect"])
    out = render_frame(black, camera, 1, plan, width=17, height=9, spp=3, seed=0)
    check_finite(out.buffers)
    assert out.buffers["color"].shape == (9, 17, 3)
    assert not out.buffers["color"].any() and not out.buffers["color_var"].any()
    assert (out.buffers["depth"] > 0).any() and (out.buffers["depth"] == 0).any()


def check_finite(buffers: dict) -> None:
    for name, value in buffers.items():
        assert value.dtype == np.float32, name
        assert np.all(np.isfinite(value)), name
        if name.endswith("_var"):
            assert value.min() >= 0.0, name


def test_second_hit_channels_only_with_per_sample_data_and_same_image(mi, family_scene):
    """RPF's per-sample extras: light/bounce random numbers are uniform, second hits are unit-normal
    points, and asking for them leaves the image's bytes unchanged."""
    translated, scene = family_scene("cornell")
    with_samples = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    without = make_render_plan(translated.effects, RenderOptions(per_sample=False))
    a = render_frame(scene, translated.camera, 1, with_samples, width=SIZE, height=SIZE, spp=4, seed=3)
    b = render_frame(scene, translated.camera, 1, without, width=SIZE, height=SIZE, spp=4, seed=3)
    assert b.samples is None
    for name in a.buffers:
        assert np.array_equal(a.buffers[name], b.buffers[name]), name
    for name in ("light", "bounce"):
        values = a.samples[name]
        assert values.shape == (4, SIZE, SIZE, 2)
        assert 0.0 <= values.min() and values.max() < 1.0
        # uniform numbers: mean 1/2, variance 1/12 (a constant or the pixel offset would fail)
        assert abs(values.mean() - 0.5) < 0.02 and abs(values.var() - 1 / 12) < 0.01, name
        assert not np.array_equal(values, a.samples["pixel"]), name
    hit = np.linalg.norm(a.samples["normal2"], axis=-1) > 0.5
    assert 0.5 < hit.mean() <= 1.0  # the Cornell box is closed on most sides
    assert np.allclose(np.linalg.norm(a.samples["normal2"][hit], axis=-1), 1.0, atol=1e-3)
    assert not a.samples["position2"][~hit].any()
    # the second hit is elsewhere than the first
    moved = np.linalg.norm(a.samples["position2"] - a.samples["position"], axis=-1)[hit]
    assert np.median(moved) > 1e-2

    direct = make_render_plan(translated.effects, RenderOptions(per_sample=True, max_depth=1))
    c = render_frame(scene, translated.camera, 1, direct, width=SIZE, height=SIZE, spp=2, seed=3)
    assert not {"light", "bounce", "position2", "normal2"} & set(c.samples)  # no bounce, no channels
    # the plan lists exactly the per-sample channels written (random parameters and second-hit features)
    for plan, frame in ((with_samples, a), (direct, c)):
        listed = set(plan.random_parameters) | set(plan.sample_features)
        written = {
            name
            for name in frame.samples
            if name in {"pixel", "lens", "time", "light", "bounce", "position2", "normal2"}
        }
        assert listed == written, (plan.max_depth, listed, written)
