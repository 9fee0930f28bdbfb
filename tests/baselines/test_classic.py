"""Classical baselines against peers and invariants: cross-bilateral, non-local means, OIDN (RPF: test_baselines_rpf.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from denoisebench.baselines import cross_bilateral as cb
from denoisebench.baselines.identity import Identity
from denoisebench.baselines.nlmeans import NLMeans
from denoisebench.baselines.oidn import OIDN, clamp_isolated
from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.synthetic import synthetic_frame
from denoisebench.metrics.ours.spatial import relmse


@pytest.fixture(scope="module")
def frame():
    return synthetic_frame("textured", 40, 36, 4, seed=7)


def test_identity_is_a_float32_copy(frame):
    out = Identity().denoise(frame)
    assert out.dtype == np.float32 and out is not frame.color
    np.testing.assert_array_equal(out, frame.color)


# ----------------------------------------------------------------------------------- cross-bilateral


@pytest.mark.parametrize("separable", [False, True])
def test_cross_bilateral_without_range_terms_is_scipy_normalised_gaussian(separable):
    rng = np.random.default_rng(1)
    color = rng.random((13, 17, 3)).astype(np.float32)
    radius, sigma = 3, 1.5
    out = cb.cross_bilateral_filter(
        color,
        {},
        radius=radius,
        sigma_spatial=sigma,
        sigma_color=1e12,
        feature_sigmas={},
        separable=separable,
        firefly_support=None,
    )
    taps = np.arange(-radius, radius + 1)
    if separable:
        # one horizontal then one vertical normalised pass
        kernel = np.exp(-(taps**2) / (2 * sigma**2))
        ones = np.ones(color.shape[:2])
        step = (
            ndimage.correlate1d(color, kernel, axis=1, mode="constant")
            / ndimage.correlate1d(ones, kernel, axis=1, mode="constant")[..., None]
        )
        peer = (
            ndimage.correlate1d(step, kernel, axis=0, mode="constant")
            / ndimage.correlate1d(ones, kernel, axis=0, mode="constant")[..., None]
        )
    else:
        yy, xx = np.meshgrid(taps, taps, indexing="ij")
        kernel = np.exp(-(yy**2 + xx**2) / (2 * sigma**2))
        ones = np.ones(color.shape[:2])
        norm = ndimage.correlate(ones, kernel, mode="constant")
        peer = (
            np.stack([ndimage.correlate(color[..., c], kernel, mode="constant") for c in range(3)], -1)
            / norm[..., None]
        )
    np.testing.assert_allclose(out, peer, rtol=2e-5, atol=1e-6)


def test_cross_bilateral_matches_brute_force_weights():
    """Full window: every output pixel is Σ w c / Σ w with w from the guide, computed pixel by pixel."""
    rng = np.random.default_rng(2)
    color = rng.gamma(0.8, 1.0, (9, 11, 3)).astype(np.float32)
    albedo = np.where(np.arange(11)[None, :, None] < 5, 0.2, 0.8) * np.ones((9, 11, 3), np.float32)
    sigmas = {"albedo": 0.1}
    radius, sigma_s = 2, 1.7
    guide = cb.build_guide(color, {"albedo": albedo}, sigma_color=5.0, feature_sigmas=sigmas)
    out = cb.cross_bilateral_filter(
        color,
        {"albedo": albedo},
        radius=radius,
        sigma_spatial=sigma_s,
        sigma_color=5.0,
        feature_sigmas=sigmas,
        separable=False,
        firefly_support=None,
    )
    expected = np.zeros_like(color, dtype=np.float64)
    for y in range(9):
        for x in range(11):
            num, den = np.zeros(3), 0.0
            for qy in range(max(0, y - radius), min(9, y + radius + 1)):
                for qx in range(max(0, x - radius), min(11, x + radius + 1)):
                    dist = ((qy - y) ** 2 + (qx - x) ** 2) / (2 * sigma_s**2)
                    w = np.exp(-dist + guide.log_weight((y, x), (qy, qx)))
                    num += w * color[qy, qx]
                    den += w
            expected[y, x] = num / den
    np.testing.assert_allclose(out, expected, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("separable", [True, False])
def test_cross_bilateral_threads_agree_with_one_thread_and_repeat_bytes(monkeypatch, separable):
    """The (strip, offset) pairs split over threads: same sums as one thread, same bytes run to run."""
    rng = np.random.default_rng(5)
    color = rng.gamma(0.8, 1.0, (150, 161, 3)).astype(np.float32)
    normal = rng.normal(size=(150, 161, 3)).astype(np.float32)
    monkeypatch.setattr(cb, "_STRIP_PIXELS", 2000)  # many strips, so every thread gets pairs from several
    monkeypatch.setattr(cb, "_MIN_PIXELS_PER_WORKER", 1)

    def run(workers):
        monkeypatch.setattr(cb, "_workers", lambda: workers)
        return cb.cross_bilateral_filter(color, {"normal": normal}, radius=4, separable=separable)

    one, three = run(1), run(3)
    np.testing.assert_allclose(three, one, rtol=2e-5, atol=1e-7)
    assert np.array_equal(run(3), three)


def test_cross_bilateral_does_not_mix_across_a_feature_edge():
    rng = np.random.default_rng(3)
    shape = (24, 24, 3)
    left = np.arange(24)[None, :, None] < 12
    clean = np.where(left, 0.2, 2.0) * np.ones(shape)
    color = (clean * rng.gamma(2.0, 0.5, shape)).astype(np.float32)
    albedo = np.where(left, 0.1, 0.9) * np.ones(shape, np.float32)
    frame = Frame(buffers={"color": color, "albedo": albedo})
    out = load_denoiser("cross_bilateral").denoise(frame)
    # next to the edge, each side keeps its own level (a plain blur would pull 0.2 towards 1.1)
    assert abs(out[:, 10:12].mean() - 0.2) < 0.05 and abs(out[:, 12:14].mean() - 2.0) < 0.5
    assert relmse(out, clean.astype(np.float32)) < 0.5 * relmse(color, clean.astype(np.float32))


def test_cross_bilateral_keeps_a_dark_pixel_dark_beside_a_noisy_highlight():
    """A dark floor pixel whose samples agree (tight variance) next to a bright, very noisy highlight:
    the pair is measured against the dark pixel's noise, so nothing of the highlight bleeds in
    (a mean-smoothed or summed variance lets it: the glossy_fireflies failure)."""
    rng = np.random.default_rng(11)
    shape = (24, 24, 3)
    highlight = np.zeros(shape[:2], bool)
    highlight[8:16, 12:] = True
    clean = np.where(highlight[..., None], 100.0, 1e-3) * np.ones(shape)
    # 4-spp-like highlight: the mean of 4 exponential samples (relative noise 0.5); the floor exact
    color = np.where(highlight[..., None], clean * rng.gamma(4.0, 0.25, shape[:2])[..., None], clean).astype(np.float32)
    variance = np.where(highlight[..., None], (0.5 * clean) ** 2, 1e-12).astype(np.float32)
    frame = Frame(buffers={"color": color, "color_var": variance})
    out = load_denoiser("cross_bilateral").denoise(frame)
    floor = ~highlight
    assert out[floor].max() < 2e-3  # at most 1e-3 of the highlight would be 0.1: 100× this
    assert relmse(out, clean.astype(np.float32)) < relmse(color, clean.astype(np.float32))


def test_cross_bilateral_removes_an_isolated_firefly_only_when_asked():
    color = np.full((15, 15, 3), 0.5, np.float32)
    color[7, 7] = 1e5
    frame = Frame(buffers={"color": color})
    kept = load_denoiser("cross_bilateral", firefly_support=None).denoise(frame)
    removed = load_denoiser("cross_bilateral").denoise(frame)
    assert kept[7, 7, 0] > 1e4  # a symmetric weight cannot pull the firefly in
    np.testing.assert_allclose(removed, 0.5, rtol=1e-5)


@pytest.mark.parametrize("preset", ["fast", "balanced", "high"])
def test_cross_bilateral_presets_lower_relmse(frame, preset):
    out = cb.CrossBilateral(preset).denoise(frame)
    assert relmse(out, frame.reference) < 0.5 * relmse(frame.color, frame.reference)


def test_cross_bilateral_rejects_bad_options():
    with pytest.raises(ValueError, match="unknown feature"):
        cb.CrossBilateral(features=["curvature"])
    with pytest.raises(ValueError):
        cb.CrossBilateral(radius=-1)


# ----------------------------------------------------------------------------------- NL-means, OIDN


def test_nlmeans_lowers_relmse_and_keeps_a_flat_image(frame):
    out = NLMeans().denoise(frame)
    assert relmse(out, frame.reference) < 0.6 * relmse(frame.color, frame.reference)
    flat = Frame(buffers={"color": np.full((9, 9, 3), 0.25, np.float32)})
    np.testing.assert_allclose(NLMeans().denoise(flat), 0.25, rtol=1e-6)


def test_oidn_without_clamp_is_pyoidn_itself(frame):
    import pyoidn

    ours = OIDN("fast", firefly_factor=None).denoise(frame)
    peer = pyoidn.denoise(
        np.ascontiguousarray(np.maximum(frame.color, 0)),
        np.ascontiguousarray(np.clip(frame.buffers["albedo"], 0, 1)),
        np.ascontiguousarray(np.clip(frame.buffers["normal"], -1, 1)),
        hdr=True,
        quality="fast",
    )
    np.testing.assert_allclose(ours, np.maximum(peer, 0), rtol=1e-6, atol=1e-7)
    assert relmse(ours, frame.reference) < 0.5 * relmse(frame.color, frame.reference)


def test_clamp_isolated_caps_spikes_and_leaves_ramps():
    image = np.full((5, 6, 3), 1.0, np.float32)
    image[2, 3] = 1e6
    clamped = clamp_isolated(image, 16.0)
    assert clamped[2, 3, 0] == pytest.approx(16.0) and np.all(np.delete(clamped.reshape(-1, 3), 2 * 6 + 3, 0) == 1.0)
    ramp = np.logspace(-6, 6, 32, dtype=np.float32)[None, :, None] * np.ones((4, 32, 3), np.float32)
    np.testing.assert_array_equal(clamp_isolated(ramp, 16.0), ramp)
    with pytest.raises(ValueError):
        OIDN(firefly_factor=0.5)


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (4, 1), (7, 9), (7, 9, 3), (64, 48)])
def test_median3x3_equals_scipy_median_filter(shape):
    """The column-sorting median of 9 against scipy.ndimage.median_filter (size 3, edges replicated), ties included."""
    rng = np.random.default_rng(len(shape) * 100 + shape[0])
    values = rng.random(shape).astype(np.float32)
    values[rng.random(shape) < 0.3] = 0.5
    size = (3, 3) + (1,) * (len(shape) - 2)
    assert np.array_equal(cb.median3x3(values), ndimage.median_filter(values, size=size, mode="nearest"))
