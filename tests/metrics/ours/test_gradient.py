"""Gradient metrics against straightforward numpy formulas, invariants and hard inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view

from denoisebench import metrics as M
from denoisebench.metrics.ours import gradient


@pytest.fixture
def pair():
    rng = np.random.default_rng(2)
    ref = rng.uniform(0.0, 2.0, (21, 30, 3))
    pred = ref + rng.normal(0, 0.1, ref.shape)
    return pred, ref


def numpy_grad_l1(p, r):
    e = p - r
    h, w = e.shape[:2]
    return (np.abs(np.diff(e, axis=1)).sum() + np.abs(np.diff(e, axis=0)).sum()) / (h * w * 3)


def numpy_log(img, sigma=1.5, size=15):
    """MATLAB's fspecial('log', 15, 1.5) written out as one 2-D kernel, mirror-padded, correlated.

    h = G(x, y)·(x² + y² − 2σ²)/σ⁴ with G = exp(−(x² + y²)/2σ²) normalised to sum 1, then
    h −= mean(h) (fspecial's zero-sum step).
    """
    r = size // 2
    y, x = np.mgrid[-r : r + 1, -r : r + 1].astype(np.float64)
    g = np.exp(-(x**2 + y**2) / (2 * sigma**2))
    g /= g.sum()
    kernel = g * (x**2 + y**2 - 2 * sigma**2) / sigma**4
    kernel -= kernel.mean()
    out = np.empty(img.shape)
    for c in range(img.shape[2]):
        padded = np.pad(img[..., c], r, mode="symmetric")  # scipy's "reflect" (d c b a | a b c d)
        windows = sliding_window_view(padded, kernel.shape)
        out[..., c] = np.einsum("ijkl,kl->ij", windows, kernel)
    return out


def test_grad_l1_matches_numpy(pair):
    p, r = pair
    assert M.grad_l1(p, r) == pytest.approx(numpy_grad_l1(p, r), rel=1e-12)
    m = M.grad_l1_map(p, r)
    assert m.shape == (21, 30)
    assert m.mean() == pytest.approx(M.grad_l1(p, r), rel=1e-12)


def test_grad_l1_pinned_by_hand():
    r = np.zeros((3, 4, 3))
    p = r.copy()
    p[1, 1] = 1.0  # one bright pixel: 4 neighbours differ by 1 → Σ|Δ| = 4 per channel
    assert M.grad_l1(p, r) == pytest.approx(4 / 12)
    ramp = np.broadcast_to(np.arange(5.0)[None, :, None], (4, 5, 3))
    assert M.grad_l1(ramp + 3.0, ramp) == 0.0  # a constant offset has no gradient


def test_laplacian_of_gaussian_matches_numpy_kernel(pair):
    _, r = pair
    assert np.abs(gradient.laplacian_of_gaussian(np.full((9, 9, 3), 5.0))).max() < 1e-12  # zero DC
    np.testing.assert_allclose(gradient.laplacian_of_gaussian(r), numpy_log(r), rtol=1e-9, atol=1e-12)


def test_hfen_matches_numpy(pair):
    p, r = pair
    lp, lr = numpy_log(p), numpy_log(r)
    expected = np.sqrt(np.mean((lp - lr) ** 2)) / (np.sqrt(np.mean(lr**2)) + 0.01)
    assert M.hfen(p, r) == pytest.approx(expected, rel=1e-9)
    m = M.hfen_map(p, r)
    assert m.shape == (21, 30)
    assert math.sqrt(np.mean(m**2)) == pytest.approx(M.hfen(p, r), rel=1e-12)


def test_hfen_ignores_smooth_offsets_and_sees_detail():
    i, j = np.mgrid[0:32, 0:32]
    r = np.repeat((0.5 + 0.3 * np.sin(0.9 * i) * np.sin(0.8 * j))[..., None], 3, -1)
    assert M.hfen(r + 0.25, r) == pytest.approx(0.0, abs=1e-12)  # constant: no high frequency
    rng = np.random.default_rng(0)
    assert M.hfen(r + 0.05 * rng.normal(size=r.shape), r) > 0.05


@pytest.mark.parametrize("name", ["grad_l1", "hfen"])
def test_identical_images_score_zero(name, pair):
    _, r = pair
    assert getattr(M, name)(r, r.copy()) == 0.0


@pytest.mark.parametrize("name", ["grad_l1", "hfen"])
def test_error_grows_monotonically_with_noise(name):
    rng = np.random.default_rng(4)
    r = rng.uniform(0.2, 1.5, (24, 24, 3))
    noise = rng.normal(size=r.shape)
    values = [getattr(M, name)(r + s * noise, r) for s in (0.01, 0.03, 0.1, 0.3, 1.0)]
    assert np.all(np.diff(values) > 0), values


@pytest.mark.parametrize("name", ["grad_l1", "hfen"])
def test_hard_inputs(name):
    fn = getattr(M, name)
    z = np.zeros((16, 16, 3))
    assert fn(z, z) == 0.0
    spot = z.copy()
    spot[8, 8] = 1.0
    assert math.isfinite(fn(spot, z)) and fn(spot, z) > 0  # black reference: ε keeps HFEN finite
    rng = np.random.default_rng(6)
    r = 10.0 ** rng.uniform(-6, 6, (16, 16, 3))
    assert math.isfinite(fn(r * 1.01, r)) and fn(r * 1.01, r) > 0
    for shape in [(1, 1, 3), (5, 7, 3), (1, 6, 3)]:
        a = rng.random(shape)
        assert math.isfinite(fn(a * 1.5, a))
        assert getattr(M, name + "_map")(a * 1.5, a).shape == shape[:2]
    assert fn(np.ones((1, 1, 3)) * 2, np.ones((1, 1, 3))) == pytest.approx(0.0, abs=1e-12)  # no detail in 1×1
    with pytest.raises(ValueError, match=r"\(16, 16, 3\).*\(16, 15, 3\)"):
        fn(z, np.zeros((16, 15, 3)))
    bad_ref = z.copy()
    bad_ref[0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="reference"):
        fn(z, bad_ref)


@pytest.mark.parametrize("name", ["grad_l1", "hfen"])
def test_nonfinite_prediction_is_worst(name, pair):
    p, r = pair
    p = p.copy()
    p[5, 5, 2] = np.nan
    assert getattr(M, name)(p, r) == math.inf
    assert np.all(getattr(M, name + "_map")(p, r) == math.inf)
