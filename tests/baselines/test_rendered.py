"""Baselines on frames rendered with Mitsuba: they lower relMSE against the noisy input, and RPF's
feature weights respond to the lens random parameters.

Frames: three families authored at 32×32, one frame, rendered with the feature renderer at 4 spp
(with per-sample data) and a 256-spp reference from an independent stream. The depth-of-field
scene is rendered with ``aperture_scale=6``: at 32 px its own lens blurs by under a pixel
(circle of confusion ≈ 0.6 px), too little for the lens to matter to any pixel.
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.baselines.rpf import RPFSettings, rpf_filter
from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.runner import run_frame
from denoisebench.metrics.ours.spatial import relmse

pytestmark = pytest.mark.slow

SIZE = 32
SPP = 4
REFERENCE_SPP = 256
FAMILIES = {"texture_checker": 1.0, "dim_room": 1.0, "depth_of_field": 6.0}  # family -> aperture scale


def _render(family: str, aperture_scale: float, tmp_dir) -> Frame:
    from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
    from denoisebench.generator.render.frame import render_frame
    from denoisebench.generator.render.scene import build_mitsuba_scene
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import get_family

    path = get_family(family).author(tmp_dir / family, seed=0, frames=1, width=SIZE, height=SIZE)
    translated = translate_usd(path)
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True, aperture_scale=aperture_scale))
    scene = build_mitsuba_scene(translated)
    noisy = render_frame(scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=SPP, seed=1)
    reference = render_frame(
        scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=REFERENCE_SPP, seed=2, reference=True
    )
    return Frame(
        buffers=noisy.buffers, spp=SPP, scene=family, reference=reference.buffers["color"], samples=noisy.samples
    )


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    tmp_dir = tmp_path_factory.mktemp("rendered_baselines")
    return {family: _render(family, scale, tmp_dir) for family, scale in FAMILIES.items()}


@pytest.mark.parametrize("family", list(FAMILIES))
@pytest.mark.parametrize("name", ["cross_bilateral", "rpf", "oidn"])
def test_denoiser_lowers_relmse_against_identity(rendered, family, name):
    frame = rendered[family]
    noisy = run_frame(load_denoiser("identity"), frame)
    denoised = run_frame(load_denoiser(name), frame)
    assert noisy.ok and denoised.ok, denoised.error
    before = relmse(noisy.output, frame.reference)
    after = relmse(denoised.output, frame.reference)
    # a real improvement, not a tie: at least a quarter of the error gone
    assert after < 0.75 * before, f"{name} on {family}: relMSE {before:.4f} -> {after:.4f}"


def test_rendered_depth_of_field_frame_carries_lens_samples(rendered):
    samples = rendered["depth_of_field"].samples
    assert samples["lens"].shape == (SPP, SIZE, SIZE, 2)
    assert "lens" not in rendered["texture_checker"].samples  # only scenes with depth of field


def _defocused(samples) -> np.ndarray:
    """Pixels whose samples disagree most about the surface (the top quarter of albedo spread)."""
    spread = samples["albedo"].std(axis=0).mean(axis=-1)
    return spread > np.percentile(spread, 75)


def test_rpf_feature_weights_drop_where_features_depend_on_the_lens(rendered):
    samples = dict(rendered["depth_of_field"].samples)
    # the same samples, except that the lens parameter is replaced by independent uniform numbers:
    # the features no longer depend on it, so RPF must not down-weight them for it
    decoupled = dict(samples)
    decoupled["lens"] = np.random.default_rng(0).random(samples["lens"].shape).astype(np.float32)
    mask = _defocused(samples)
    # the mean over the filter's seeds 0-2 (one draw moves the ratio by about 0.01): coupled/decoupled
    # β measured 0.89 (position) and 0.85 (albedo), 0.88 / 0.84 without the straddling refinement
    ratios = {"position": [], "albedo": []}
    for seed in range(3):
        _, coupled_weights = rpf_filter(samples, RPFSettings(seed=seed))
        _, decoupled_weights = rpf_filter(decoupled, RPFSettings(seed=seed))
        for feature in ratios:
            coupled_beta = np.mean([beta[feature][mask].mean() for beta in coupled_weights.beta])
            decoupled_beta = np.mean([beta[feature][mask].mean() for beta in decoupled_weights.beta])
            coupled_w = np.mean([w[feature][mask].mean() for w in coupled_weights.w_random])
            decoupled_w = np.mean([w[feature][mask].mean() for w in decoupled_weights.w_random])
            assert coupled_w > decoupled_w, feature  # more of the feature's dependency is on the lens
            ratios[feature].append(coupled_beta / decoupled_beta)
    for feature, values in ratios.items():
        assert np.mean(values) < 0.92, f"{feature}: coupled/decoupled β {values}"
