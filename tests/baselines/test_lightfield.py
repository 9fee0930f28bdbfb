"""The ``lightfield`` denoiser (Lehtinen et al. 2011): trajectories, SameSurface, and its error.

Peers: the synthetic thin-lens frames of :mod:`denoisebench.denoisers.synthetic` (their circle of
confusion is known: the fitted trajectories must match it), hand-made hit sets for the visibility
rule, and the noisy input itself on synthetic and rendered defocused frames (it must do better).
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.baselines.lightfield import LightField
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.synthetic import make_scene, render


def _rel_mse(pred, truth):
    return float(np.mean((pred - truth) ** 2 / (truth**2 + 0.01)))


def test_fitted_trajectories_follow_the_thin_lens():
    """The synthetic lens moves a layer at depth z by aperture·|z − z_f| / z pixels per unit of lens disk."""
    scene = make_scene("depth_of_field", 32, 32, 0)
    frame = render(scene, 4, 1, samples=True, reference_samples=4)
    denoiser = LightField()
    _, _, slopes, z = denoiser.trajectories(frame.samples)
    assert denoiser.last_fit["used"] == 2 and denoiser.last_fit["residual"] < 0.1
    hit = z < 1e5
    expected = scene.aperture * np.abs(z[hit] - scene.focus_depth) / z[hit]
    along = np.abs(slopes[hit, 0, 0])  # x per lens x
    # the median within 0.1 px (measured 0.056, correlation 0.98): the synthetic layers' circle of confusion uses each layer's nominal depth
    # while tilted planes and discs report their varying depth (up to 0.4 px apart at the far edge)
    assert np.median(np.abs(along - expected)) < 0.1, np.median(np.abs(along - expected))
    assert np.corrcoef(along, expected)[0, 1] > 0.95
    assert np.median(np.abs(slopes[hit, 0, 1])) < 0.05  # x does not move with lens y


def test_time_trajectories_are_fitted_with_motion_blur():
    frame = render(make_scene("motion_blur", 32, 32, 0), 4, 1, samples=True, reference_samples=4)
    denoiser = LightField()
    denoiser.trajectories(frame.samples)
    assert denoiser.last_fit["params"] == 1 and denoiser.last_fit["used"] in (0, 1)


def _hits(xs, depths, slopes):
    """Candidate arrays for one reconstruction point at (0, 0) and lens 0 (1-D lens: Q = 1)."""
    n = len(xs)
    base = np.stack([np.asarray(xs, float), np.zeros(n)], 1)[None]
    slope = np.zeros((1, n, 2, 1))
    slope[0, :, 0, 0] = slopes
    colors = np.repeat(np.asarray(depths, float)[:, None], 3, 1)[None]  # colour = depth: tells who was used
    return base, slope, np.asarray(depths, float)[None], colors, np.ones((1, n), bool)


def test_same_surface_keeps_a_covering_front_surface_and_sees_past_an_occluders_fringe():
    corners = LightField._corners(1, False)
    point, params = np.zeros((1, 2)), np.zeros(1)
    # front surface (depth 2, steep trajectories) hits on both sides of the point: it covers it
    base, slope, z, colors, ok = _hits([-0.3, 0.3, -0.2, 0.25], [2, 2, 9, 9], [3, 3, 0, 0])
    value, found = LightField._point(base, slope, z, colors, ok, point, params, 0.5, corners)
    assert found[0] == 1 and value[0, 0] == pytest.approx(2.0)
    # front hits on one side only (the blurred fringe of an occluder): the surface behind is seen
    base, slope, z, colors, ok = _hits([0.35, 0.4, -0.2, 0.25], [2, 2, 9, 9], [3, 3, 0, 0])
    value, found = LightField._point(base, slope, z, colors, ok, point, params, 0.5, corners)
    assert value[0, 0] == pytest.approx(9.0)
    # parallel trajectories at two depths never cross: one apparent surface, all hits used
    base, slope, z, colors, ok = _hits([-0.3, 0.3, -0.2, 0.25], [2, 2, 3, 3], [1, 1, 1, 1])
    value, _ = LightField._point(base, slope, z, colors, ok, point, params, 0.5, corners)
    assert value[0, 0] == pytest.approx(2.5)


@pytest.mark.parametrize("family", ["depth_of_field", "motion_blur"])
def test_lightfield_beats_its_input_on_synthetic_defocus_and_motion(family):
    """4 spp, 3 noise draws. Measured relMSE: depth of field 0.10 vs 0.56 (cross_bilateral 0.16)."""
    ours, noisy = [], []
    for seed in range(3):
        frame = render(make_scene(family, 32, 32, seed), 4, seed + 1, samples=True, reference_samples=64)
        ours.append(_rel_mse(load_denoiser("lightfield").denoise(frame), frame.reference))
        noisy.append(_rel_mse(frame.color, frame.reference))
    assert np.mean(ours) < 0.5 * np.mean(noisy), (np.mean(ours), np.mean(noisy))


def test_lightfield_beats_its_input_on_a_rendered_defocused_scene(mi, tmp_path):
    """A depth_of_field stage rendered at 16 px, 4 spp, over 3 noise draws, against a 512-spp reference."""
    from denoisebench.dataset.frame import Frame
    from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
    from denoisebench.generator.render.frame import render_frame
    from denoisebench.generator.render.scene import build_mitsuba_scene
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import get_family

    translated = translate_usd(get_family("depth_of_field").author(tmp_path, seed=0, frames=2, width=16, height=16))
    scene = build_mitsuba_scene(translated)
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    kw = dict(width=16, height=16)
    ref = render_frame(scene, translated.camera, 1, plan, spp=512, seed=99, reference=True, **kw).buffers["color"]
    ours, noisy = [], []
    denoiser = LightField()
    for seed in range(3):
        rendered = render_frame(scene, translated.camera, 1, plan, spp=4, seed=seed, **kw)
        frame = Frame(buffers=rendered.buffers, spp=4, scene="dof", index=1, samples=rendered.samples)
        ours.append(_rel_mse(denoiser.denoise(frame), ref))
        noisy.append(_rel_mse(rendered.buffers["color"], ref))
    assert denoiser.last_fit["used"] == 2, denoiser.last_fit
    print(f"relMSE lightfield {np.mean(ours):.4f} input {np.mean(noisy):.4f}")
    assert np.mean(ours) < np.mean(noisy)
