"""Spatial metrics against their peers (numpy formulas, scikit-image, flip-evaluator, colour-science),
their invariants, and hard inputs. Images are 16–48 px."""

from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

from denoisebench import metrics as M
from denoisebench.metrics import tonemap as tm
from denoisebench.metrics.ours import spatial

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    import colour
import flip_evaluator
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

SPATIAL = ["mse", "relmse", "smape", "l1", "psnr", "ssim", "flip", "deltae2000"]
FNS = {name: getattr(M, name) for name in SPATIAL}


def pattern(h=24, w=32):
    """Deterministic smooth HDR-ish pattern in [0.1, 0.9] (used for the pinned values)."""
    i, j = np.mgrid[0:h, 0:w]
    return np.stack([0.5 + 0.4 * np.sin(0.7 * i + c) * np.cos(0.3 * j) for c in range(3)], -1)


@pytest.fixture
def pair():
    rng = np.random.default_rng(7)
    ref = rng.uniform(0.05, 3.0, (20, 28, 3))
    pred = np.clip(ref + rng.normal(0, 0.2, ref.shape), 0, None)
    return pred, ref


def ref_tonemap(x):
    """Independent spelling of the documented tone map: clamp, Reinhard, sRGB OETF (colour's)."""
    c = np.maximum(x, 0.0)
    return colour.cctf_encoding(c / (1.0 + c), "sRGB")


# --------------------------------------------------------------------------- tone map


def test_tonemap_matches_colour_srgb_encoding_and_pins():
    x = np.array([0.0, 1e-6, 0.001, 0.5, 1.0, 7.0, 1e6, -3.0])
    np.testing.assert_allclose(tm.tonemap(x), ref_tonemap(x), rtol=0, atol=1e-12)
    # radiance 1 → Reinhard 0.5 → 1.055·0.5^(1/2.4) − 0.055 (IEC 61966-2-1), by hand:
    assert tm.tonemap(np.array([1.0]))[0] == pytest.approx(0.7353569830524495, abs=1e-12)
    assert tm.tonemap(np.array([-5.0]))[0] == 0.0
    assert tm.reinhard(np.array([np.inf]))[0] == 1.0
    y = tm.tonemap(np.geomspace(1e-8, 1e8, 200))
    assert np.all(np.diff(y) > 0) and y.min() >= 0 and y.max() < 1


# --------------------------------------------------------------------------- numpy peers


def test_pixelwise_metrics_match_numpy_formulas(pair):
    p, r = pair
    d = p - r
    assert M.mse(p, r) == pytest.approx(np.mean(d**2), rel=1e-12)
    assert M.l1(p, r) == pytest.approx(np.mean(np.abs(d)), rel=1e-12)
    assert M.relmse(p, r) == pytest.approx(np.mean(d**2 / (r**2 + 0.01)), rel=1e-12)
    assert M.smape(p, r) == pytest.approx(np.mean(np.abs(d) / (np.abs(p) + np.abs(r) + 0.01)), rel=1e-12)
    np.testing.assert_allclose(M.relmse_map(p, r), (d**2 / (r**2 + 0.01)).mean(-1), rtol=1e-12)
    np.testing.assert_allclose(M.mse_map(p, r), (d**2).mean(-1), rtol=1e-12)
    for name in ("mse", "relmse", "smape", "l1"):
        m = getattr(M, name + "_map")(p, r)
        assert m.shape == (20, 28)
        assert np.mean(m) == pytest.approx(getattr(M, name)(p, r), rel=1e-12)


def test_pixelwise_pinned_by_hand():
    r = np.ones((4, 5, 3))
    p = r + 0.1
    assert M.relmse(p, r) == pytest.approx(0.01 / 1.01, rel=1e-12)  # (0.1)² / (1² + 0.01)
    assert M.smape(2 * r, r) == pytest.approx(1 / 3.01, rel=1e-12)  # |2−1| / (2 + 1 + 0.01)
    assert M.mse(p, r) == pytest.approx(0.01, rel=1e-12)
    # SMAPE never reaches its worst value 1 for finite input: p = 0, r = 1 → 1 / 1.01.
    assert M.smape(0 * r, r) == pytest.approx(1 / 1.01, rel=1e-12)


# --------------------------------------------------------------------------- scikit-image peers


def test_psnr_matches_scikit_image(pair):
    p, r = pair
    expected = peak_signal_noise_ratio(ref_tonemap(r), ref_tonemap(p), data_range=1.0)
    assert M.psnr(p, r) == pytest.approx(expected, rel=1e-12)


def test_ssim_matches_scikit_image(pair):
    p, r = pair
    kw = dict(gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0, channel_axis=-1)
    expected, full = structural_similarity(ref_tonemap(p), ref_tonemap(r), full=True, **kw)
    assert M.ssim(p, r) == pytest.approx(expected, rel=1e-10)
    np.testing.assert_allclose(M.ssim_map(p, r), full.mean(-1), rtol=1e-10, atol=1e-12)


def test_pinned_values_on_pattern():
    r = pattern()
    p = r * 1.1 + 0.02
    # Computed once with the peers directly on these inputs (numbers below):
    # scikit-image 0.26.0 structural_similarity(gaussian_weights, σ=1.5, sample cov False,
    #   data_range=1, channel_axis=-1) on tone-mapped images → 0.9980086802377377
    assert M.ssim(p, r) == pytest.approx(0.9980086802377377, abs=1e-9)
    # scikit-image 0.26.0 peak_signal_noise_ratio(data_range=1) on tone-mapped images → 31.860641040311066
    assert M.psnr(p, r) == pytest.approx(31.860641040311066, abs=1e-9)
    # flip-evaluator 1.7 evaluate(ref, test, "HDR") float32: mean 0.1267472803592682
    assert M.flip(p, r) == pytest.approx(0.1267472803592682, abs=1e-6)
    # colour-science 0.4.7 RGB_to_XYZ(sRGB, no decoding) → XYZ_to_Lab(D65) → delta_E "CIE 2000",
    #   on Reinhard-mapped inputs, mean → 2.0982019466158275
    assert M.deltae2000(p, r) == pytest.approx(2.0982019466158275, abs=1e-9)


# --------------------------------------------------------------------------- flip-evaluator peer


def test_flip_matches_flip_evaluator(pair):
    p, r = pair
    r32, p32 = r.astype(np.float32), p.astype(np.float32)
    emap, mean, _ = flip_evaluator.evaluate(r32, p32, "HDR", applyMagma=False)
    np.testing.assert_array_equal(M.flip_map(p, r), emap[..., 0])
    assert M.flip(p, r) == pytest.approx(mean, abs=1e-6)
    assert 0.0 < M.flip(p, r) < 1.0


def test_flip_clamps_negative_predictions():
    r = pattern(16, 16)
    p = r - 0.3  # negatives: FLIP wants non-negative HDR input; we clamp to 0
    emap, _, _ = flip_evaluator.evaluate(
        r.astype(np.float32), np.clip(p, 0, None).astype(np.float32), "HDR", applyMagma=False
    )
    assert M.flip(p, r) == pytest.approx(float(emap.mean(dtype=np.float64)), abs=1e-7)


def test_flip_black_reference_does_not_exit_the_process():
    # flip-evaluator calls exit(-1) for an all-black reference; run in a child so a regression
    # shows up as a failing test rather than a vanished pytest.
    code = (
        "import numpy as np\n"
        "from denoisebench.metrics import flip, flip_map\n"
        "z = np.zeros((16, 16, 3)); one = np.ones((16, 16, 3))\n"
        "tiny = np.full((16, 16, 3), 1e-9)\n"
        "vals = [flip(z, z), flip(one, z), flip(tiny, z), flip(z, tiny), flip(tiny * 50, tiny)]\n"
        "assert flip_map(one, z).shape == (16, 16)\n"
        "print(' '.join(repr(float(v)) for v in vals))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    same, one_vs_black, tiny_vs_black, black_vs_tiny, dim = map(float, out.stdout.split())
    assert same == 0.0
    assert 0.5 < one_vs_black <= 1.0  # a lit prediction of a black frame is badly wrong
    assert 0.0 < tiny_vs_black <= 1.0
    assert 0.0 < black_vs_tiny <= 1.0 and 0.0 < dim <= 1.0


# --------------------------------------------------------------------------- colour-science ΔE2000

# Sharma, Wu, Dalal 2005, "The CIEDE2000 color-difference formula: implementation notes,
# supplementary test data, and mathematical observations", Color Res. Appl. 30(1), Table 1:
# L1 a1 b1 L2 a2 b2 ΔE00 (all 34 pairs; the same data as ciede2000testdata.txt on G. Sharma's page).
SHARMA_2005 = """
50.0000 2.6772 -79.7751 50.0000 0.0000 -82.7485 2.0425
50.0000 3.1571 -77.2803 50.0000 0.0000 -82.7485 2.8615
50.0000 2.8361 -74.0200 50.0000 0.0000 -82.7485 3.4412
50.0000 -1.3802 -84.2814 50.0000 0.0000 -82.7485 1.0000
50.0000 -1.1848 -84.8006 50.0000 0.0000 -82.7485 1.0000
50.0000 -0.9009 -85.5211 50.0000 0.0000 -82.7485 1.0000
50.0000 0.0000 0.0000 50.0000 -1.0000 2.0000 2.3669
50.0000 -1.0000 2.0000 50.0000 0.0000 0.0000 2.3669
50.0000 2.4900 -0.0010 50.0000 -2.4900 0.0009 7.1792
50.0000 2.4900 -0.0010 50.0000 -2.4900 0.0010 7.1792
50.0000 2.4900 -0.0010 50.0000 -2.4900 0.0011 7.2195
50.0000 2.4900 -0.0010 50.0000 -2.4900 0.0012 7.2195
50.0000 -0.0010 2.4900 50.0000 0.0009 -2.4900 4.8045
50.0000 -0.0010 2.4900 50.0000 0.0010 -2.4900 4.8045
50.0000 -0.0010 2.4900 50.0000 0.0011 -2.4900 4.7461
50.0000 2.5000 0.0000 50.0000 0.0000 -2.5000 4.3065
50.0000 2.5000 0.0000 73.0000 25.0000 -18.0000 27.1492
50.0000 2.5000 0.0000 61.0000 -5.0000 29.0000 22.8977
50.0000 2.5000 0.0000 56.0000 -27.0000 -3.0000 31.9030
50.0000 2.5000 0.0000 58.0000 24.0000 15.0000 19.4535
50.0000 2.5000 0.0000 50.0000 3.1736 0.5854 1.0000
50.0000 2.5000 0.0000 50.0000 3.2972 0.0000 1.0000
50.0000 2.5000 0.0000 50.0000 1.8634 0.5757 1.0000
50.0000 2.5000 0.0000 50.0000 3.2592 0.3350 1.0000
60.2574 -34.0099 36.2677 60.4626 -34.1751 39.4387 1.2644
63.0109 -31.0961 -5.8663 62.8187 -29.7946 -4.0864 1.2630
61.2901 3.7196 -5.3901 61.4292 2.2480 -4.9620 1.8731
35.0831 -44.1164 3.7933 35.0232 -40.0716 1.5901 1.8645
22.7233 20.0904 -46.6940 23.0331 14.9730 -42.5619 2.0373
36.4612 47.8580 18.3852 36.2715 50.5065 21.2231 1.4146
90.8027 -2.0831 1.4410 91.1528 -1.6435 0.0447 1.4441
90.9257 -0.5406 -0.9208 88.6381 -0.8985 -0.7239 1.5381
6.7747 -0.2908 -2.4247 5.8714 -0.0985 -2.2286 0.6377
2.0776 0.0795 -1.1350 0.9033 -0.0636 -0.5514 0.9082
"""


def sharma():
    rows = np.array([[float(v) for v in line.split()] for line in SHARMA_2005.strip().splitlines()])
    assert rows.shape == (34, 7)
    return rows[:, 0:3], rows[:, 3:6], rows[:, 6]


def test_delta_e2000_lab_on_sharma_2005_pairs():
    lab1, lab2, expected = sharma()
    got = spatial.delta_e2000_lab(lab1, lab2)
    np.testing.assert_allclose(got, expected, atol=5e-5)  # table printed to 4 decimals
    np.testing.assert_allclose(spatial.delta_e2000_lab(lab2, lab1), expected, atol=5e-5)  # symmetric


def test_deltae2000_images_reproduce_sharma_pairs_in_gamut():
    """Sharma Lab pairs → linear sRGB → inverse Reinhard → HDR images → deltae2000_map."""
    lab1, lab2, expected = sharma()
    white = colour.RGB_COLOURSPACES["sRGB"].whitepoint

    # colour's sRGB matrices are IEC's rounded pair, not exact inverses (1e-3 in Lab, enough to
    # move the hue-discontinuity pairs 9–15): invert RGB_to_XYZ's matrix exactly instead.
    to_rgb = np.linalg.inv(colour.RGB_COLOURSPACES["sRGB"].matrix_RGB_to_XYZ)

    def to_linear_srgb(lab):
        return colour.Lab_to_XYZ(lab, white) @ to_rgb.T

    rgb1, rgb2 = to_linear_srgb(lab1), to_linear_srgb(lab2)
    ok = np.all((rgb1 > 0) & (rgb1 < 1) & (rgb2 > 0) & (rgb2 < 1), axis=1)
    assert ok.sum() >= 10  # the saturated blues of pairs 1–6 are out of sRGB gamut
    hdr1 = (rgb1 / (1 - rgb1))[ok][None]  # inverse of Reinhard c/(1+c): a 1×N image
    hdr2 = (rgb2 / (1 - rgb2))[ok][None]
    got = M.deltae2000_map(hdr1, hdr2)[0]
    np.testing.assert_allclose(got, expected[ok], atol=5e-5)  # table rounding
    assert M.deltae2000(hdr1, hdr2) == pytest.approx(expected[ok].mean(), abs=5e-5)


def test_linear_srgb_to_lab_matches_textbook_formula():
    """IEC 61966-2-1 matrix and CIE 1976 L*a*b* written out in numpy (no sRGB decoding)."""
    rng = np.random.default_rng(3)
    rgb = rng.random((50, 3))
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = rgb @ m.T
    wx, wy = 0.3127, 0.3290
    wn = np.array([wx / wy, 1.0, (1 - wx - wy) / wy])
    t = xyz / wn
    f = np.where(t > (6 / 29) ** 3, np.cbrt(t), t / (3 * (6 / 29) ** 2) + 4 / 29)
    lab = np.stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])], -1)
    np.testing.assert_allclose(spatial.linear_srgb_to_lab(rgb), lab, atol=0.02)  # 4-digit matrix


def test_deltae2000_matches_direct_colour_calls(pair):
    p, r = pair
    white = colour.RGB_COLOURSPACES["sRGB"].whitepoint

    def lab(x):
        y = np.maximum(x, 0) / (1 + np.maximum(x, 0))
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(y, "sRGB", apply_cctf_decoding=False), white)

    expected = colour.delta_E(lab(p), lab(r), method="CIE 2000")
    np.testing.assert_allclose(M.deltae2000_map(p, r), expected, rtol=1e-12)


def test_deltae2000_ignores_a_global_colour_scale(pair):
    p, r = pair
    before = M.deltae2000(p, r)
    with colour.domain_range_scale("100"):
        assert M.deltae2000(p, r) == pytest.approx(before, rel=1e-12)


# --------------------------------------------------------------------------- invariants

PERFECT = {
    "mse": 0.0,
    "relmse": 0.0,
    "smape": 0.0,
    "l1": 0.0,
    "psnr": math.inf,
    "ssim": 1.0,
    "flip": 0.0,
    "deltae2000": 0.0,
}


@pytest.mark.parametrize("name", SPATIAL)
def test_identical_images_give_the_perfect_score(name, pair):
    _, r = pair
    got = FNS[name](r, r.copy())
    assert got == pytest.approx(PERFECT[name], abs=1e-12)
    assert M.get_metric(name).perfect == PERFECT[name]


@pytest.mark.parametrize("name", SPATIAL)
def test_error_grows_monotonically_with_noise(name):
    rng = np.random.default_rng(11)
    r = 0.3 + pattern(24, 24)
    noise = rng.normal(0, 1, r.shape)
    values = [FNS[name](r + s * noise, r) for s in (0.01, 0.03, 0.1, 0.3, 1.0)]
    steps = np.diff(values)
    if M.get_metric(name).higher_is_better:
        assert np.all(steps < 0), values
    else:
        assert np.all(steps > 0), values


# --------------------------------------------------------------------------- hard inputs


@pytest.mark.parametrize("name", SPATIAL)
def test_all_black_reference(name):
    z = np.zeros((16, 16, 3))
    assert FNS[name](z, z) == pytest.approx(PERFECT[name], abs=1e-12)
    v = FNS[name](np.full_like(z, 0.5), z)
    assert math.isfinite(v)
    assert FNS[name](np.full_like(z, 0.5), z) != PERFECT[name]


def test_all_black_reference_values():
    z = np.zeros((16, 16, 3))
    p = np.full_like(z, 0.5)
    assert M.relmse(p, z) == pytest.approx(0.25 / 0.01)  # ε keeps it finite: 0.5² / 0.01
    assert M.smape(p, z) == pytest.approx(0.5 / 0.51)
    assert M.psnr(p, z) == pytest.approx(10 * math.log10(1 / tm.tonemap(np.array([0.5]))[0] ** 2))


@pytest.mark.parametrize("name", SPATIAL)
def test_extreme_dynamic_range(name):
    rng = np.random.default_rng(5)
    r = 10.0 ** rng.uniform(-6, 6, (16, 16, 3))
    p = r * (1 + 0.05 * rng.normal(size=r.shape))
    v = FNS[name](p, r)
    assert math.isfinite(v), v
    assert v != PERFECT[name]
    assert FNS[name](r, r) == pytest.approx(PERFECT[name], abs=1e-12)


def test_extreme_range_values_match_formulas():
    rng = np.random.default_rng(5)
    r = 10.0 ** rng.uniform(-6, 6, (16, 16, 3))
    p = r * (1 + 0.05 * rng.normal(size=r.shape))
    assert M.relmse(p, r) == pytest.approx(np.mean((p - r) ** 2 / (r**2 + 0.01)), rel=1e-10)
    assert 0 <= M.flip(p, r) <= 1


@pytest.mark.parametrize("name", SPATIAL)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_prediction_gives_the_worst_value(name, bad, pair):
    p, r = pair
    p = p.copy()
    p[3, 4, 1] = bad
    assert FNS[name](p, r) == M.get_metric(name).worst
    assert FNS[name](p, r) == spatial.WORST[name]


def test_worst_values_are_really_worst(pair):
    p, r = pair
    for name in SPATIAL:
        m = M.get_metric(name)
        v = FNS[name](p, r)
        assert not m.better(m.worst, v), name


def test_nonfinite_maps_mark_the_pixel(pair):
    p, r = pair
    p = p.copy()
    p[3, 4, 1] = np.nan
    for name, worst in (
        ("mse", math.inf),
        ("relmse", math.inf),
        ("smape", 1.0),
        ("l1", math.inf),
        ("deltae2000", math.inf),
    ):
        m = getattr(M, name + "_map")(p, r)
        assert m[3, 4] == worst
        assert np.isfinite(m[0, 0]) and np.count_nonzero(m == worst) == 1, name
    assert np.all(M.ssim_map(p, r) == -1.0)
    assert np.all(M.flip_map(p, r) == 1.0)


def test_nonfinite_reference_is_an_error(pair):
    p, r = pair
    r = r.copy()
    r[0, 0, 0] = np.nan
    for name in SPATIAL:
        with pytest.raises(ValueError, match="reference"):
            FNS[name](p, r)


@pytest.mark.parametrize("shape", [(1, 1, 3), (5, 7, 3), (1, 9, 3), (3, 1, 3)])
@pytest.mark.parametrize("name", [n for n in SPATIAL if n != "ssim"])
def test_tiny_and_odd_sizes(name, shape):
    rng = np.random.default_rng(1)
    r = rng.uniform(0.1, 2, shape)
    p = r * 1.2
    v = FNS[name](p, r)
    assert math.isfinite(v) and v != PERFECT[name]
    assert FNS[name](r, r) == pytest.approx(PERFECT[name], abs=1e-12)
    mapper = M.get_metric(name).map_fn
    if mapper is not None:
        assert mapper(p, r).shape == shape[:2]


def test_ssim_size_limits():
    rng = np.random.default_rng(1)
    for shape in [(1, 1, 3), (10, 40, 3), (40, 10, 3)]:
        r = rng.random(shape)
        with pytest.raises(ValueError, match="at least 11"):
            M.ssim(r * 1.1, r)
    r = rng.random((11, 13, 3))  # odd, smallest allowed
    expected = structural_similarity(
        ref_tonemap(r * 1.1),
        ref_tonemap(r),
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=1.0,
        channel_axis=-1,
    )
    assert M.ssim(r * 1.1, r) == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("name", SPATIAL)
def test_mismatched_shapes_name_both(name):
    a = np.ones((16, 16, 3))
    b = np.ones((16, 17, 3))
    with pytest.raises(ValueError, match=r"\(16, 16, 3\).*\(16, 17, 3\)"):
        FNS[name](a, b)


@pytest.mark.parametrize(
    "bad",
    [
        np.ones((16, 16)),
        np.ones((16, 16, 4)),
        np.ones((0, 16, 3)),
        np.ones((16, 16, 3), dtype=complex),
        np.ones((16, 16, 3), dtype=bool),
        "not an image",
    ],
)
def test_bad_layouts_are_errors(bad):
    good = np.ones((16, 16, 3))
    for fn in (M.mse, M.flip, M.deltae2000):
        with pytest.raises(ValueError):
            fn(bad, good)


def test_integer_and_float32_inputs(pair):
    p, r = pair
    assert M.mse(p.astype(np.float32), r) == pytest.approx(M.mse(p, r), rel=1e-6)
    ints = np.arange(16 * 16 * 3).reshape(16, 16, 3) % 7
    assert M.l1(ints, ints + 1) == pytest.approx(1.0)


def test_flip_ppd_is_validated_before_the_library():
    r = pattern(16, 16)
    for ppd in (0, -1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="pixels per degree"):
            M.flip(r, r, ppd=ppd)
    assert M.flip(r * 1.2, r, ppd=30) != M.flip(r * 1.2, r)
