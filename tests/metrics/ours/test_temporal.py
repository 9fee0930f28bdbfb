"""Temporal metrics: numpy / scipy / scikit-image peers, invariants (p = r, p = r + c, camera pan),
disocclusion handling, and hard inputs. Sequences are 2–5 frames of ≤ 40 px."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter, map_coordinates
from skimage.metrics import peak_signal_noise_ratio

from denoisebench import metrics as M
from denoisebench.metrics.ours import temporal
from denoisebench.metrics.tonemap import tonemap


def random_seq(t=4, h=12, w=15, seed=0):
    rng = np.random.default_rng(seed)
    ref = rng.uniform(0.1, 2.0, (t, h, w, 3))
    pred = ref + rng.normal(0, 0.1, ref.shape)
    return pred, ref


def pan(shift=2, t=4, h=20, w=28, seed=0):
    """A camera pan over a textured plane: frame t shows columns [shift·t, shift·t + w) of it.

    Pixel (i, j) of frame t shows plane column j + shift·t, which frame t−1 showed at column
    j + shift: the motion is (+shift, 0). The prediction is a fixed function of the plane
    (blurred, scaled, offset): wrong, but temporally stable.
    """
    rng = np.random.default_rng(seed)
    plane = gaussian_filter(rng.random((h, w + shift * t, 3)), (1.0, 1.0, 0)) * 2 + 0.1
    stable = 0.8 * gaussian_filter(plane, (1.5, 1.5, 0)) + 0.05
    ref = np.stack([plane[:, shift * k : shift * k + w] for k in range(t)])
    pred = np.stack([stable[:, shift * k : shift * k + w] for k in range(t)])
    motion = np.zeros((t, h, w, 2))
    motion[..., 0] = shift
    return pred, ref, motion


# --------------------------------------------------------------------------- peers


def test_temporal_l1_matches_numpy():
    p, r = random_seq()
    expected = np.mean(np.abs(np.diff(p, axis=0) - np.diff(r, axis=0)))
    assert M.temporal_l1(p, r) == pytest.approx(expected, rel=1e-12)
    maps = M.temporal_l1_map(p, r)
    assert maps.shape == (3, 12, 15)
    np.testing.assert_allclose(maps, np.abs(np.diff(p, axis=0) - np.diff(r, axis=0)).mean(-1), rtol=1e-12)
    assert M.temporal_l1(list(p), list(r)) == M.temporal_l1(p, r)  # lists of frames work too


def test_tpsnr_matches_scikit_image_on_frame_differences():
    p, r = random_seq()
    dp = np.diff(tonemap(p), axis=0)
    dr = np.diff(tonemap(r), axis=0)
    expected = peak_signal_noise_ratio(dr, dp, data_range=1.0)
    assert M.tpsnr(p, r) == pytest.approx(expected, rel=1e-12)


def test_warp_matches_scipy_map_coordinates():
    rng = np.random.default_rng(3)
    prev = rng.random((12, 15, 3))
    motion = rng.uniform(-3, 3, (12, 15, 2))
    warped, inside = M.warp_previous(prev, motion)
    i, j = np.mgrid[0:12, 0:15]
    # Previous position (x = j + 0.5 + mx, y = i + 0.5 + my) in pixel-centre coordinates is
    # array index (row = i + my, col = j + mx); "nearest" replicates the edge like our clamp.
    coords = [i + motion[..., 1], j + motion[..., 0]]
    for c in range(3):
        expected = map_coordinates(prev[..., c], coords, order=1, mode="nearest")
        np.testing.assert_allclose(warped[..., c], expected, rtol=1e-12, atol=1e-12)
    x = j + 0.5 + motion[..., 0]
    y = i + 0.5 + motion[..., 1]
    np.testing.assert_array_equal(inside, (x >= 0) & (x <= 15) & (y >= 0) & (y <= 12))
    assert 0 < inside.sum() < inside.size


def test_warp_conventions_by_hand():
    prev = np.arange(12.0).reshape(3, 4)[..., None].repeat(3, -1)
    m = np.zeros((3, 4, 2))
    m[..., 0] = 1.0  # surface point was one pixel to the right in the previous frame
    warped, inside = M.warp_previous(prev, m)
    np.testing.assert_array_equal(warped[:, :3, 0], prev[:, 1:, 0])
    np.testing.assert_array_equal(inside[:, :3], True)
    np.testing.assert_array_equal(inside[:, 3], False)  # x = 3.5 + 1 > W = 4: left the image
    m[..., 0] = 0.5
    m[..., 1] = -0.5
    warped, _ = M.warp_previous(prev, m)
    # pixel (1, 1) samples x = 2.0, y = 1.0: halfway between columns 1 and 2 and rows 0 and 1.
    assert warped[1, 1, 0] == pytest.approx((prev[0, 1, 0] + prev[0, 2, 0] + prev[1, 1, 0] + prev[1, 2, 0]) / 4)


def test_warped_matches_explicit_loop():
    p, r = random_seq(t=3, seed=4)
    rng = np.random.default_rng(8)
    motion = rng.uniform(-2, 2, (3, 12, 15, 2))
    i, j = np.mgrid[0:12, 0:15]
    total, count = 0.0, 0
    for t in range(1, 3):
        coords = [i + motion[t, ..., 1], j + motion[t, ..., 0]]
        wp = np.stack([map_coordinates(p[t - 1, ..., c], coords, order=1, mode="nearest") for c in range(3)], -1)
        wr = np.stack([map_coordinates(r[t - 1, ..., c], coords, order=1, mode="nearest") for c in range(3)], -1)
        x, y = j + 0.5 + motion[t, ..., 0], i + 0.5 + motion[t, ..., 1]
        valid = (x >= 0) & (x <= 15) & (y >= 0) & (y <= 12)
        err = np.abs((p[t] - wp) - (r[t] - wr)).mean(-1)
        total += err[valid].sum()
        count += valid.sum()
    assert M.temporal_l1_warped(p, r, motion) == pytest.approx(total / count, rel=1e-10)
    maps = M.temporal_l1_warped_map(p, r, motion)
    masks = M.warped_valid_masks(motion)
    assert maps.shape == masks.shape == (2, 12, 15)
    assert np.all(maps[~masks] == 0)
    assert maps[masks].mean() == pytest.approx(total / count, rel=1e-10)


# --------------------------------------------------------------------------- invariants


@pytest.mark.parametrize("offset", [0.0, 0.37, -0.05])
def test_zero_for_reference_and_reference_plus_constant(offset):
    _, r = random_seq(seed=1)
    rng = np.random.default_rng(2)
    motion = rng.uniform(-2, 2, r.shape[:3] + (2,))
    depth = rng.uniform(1, 2, r.shape[:3])
    p = r + offset
    assert M.temporal_l1(p, r) == pytest.approx(0.0, abs=1e-12)
    assert M.temporal_l1_warped(p, r, motion) == pytest.approx(0.0, abs=1e-12)
    assert M.temporal_l1_warped(p, r, motion, depth=depth, depth_tolerance=1.0) == pytest.approx(0.0, abs=1e-12)
    if offset == 0.0:
        assert M.tpsnr(p, r) == math.inf
    # tPSNR is tone-mapped (non-linear): an offset keeps it perfect only on a static reference.
    static = np.repeat(r[:1], 3, axis=0)
    assert M.tpsnr(static + abs(offset), static) == math.inf


def test_pan_warped_error_is_far_below_unwarped():
    p, r, motion = pan(shift=2)
    unwarped = M.temporal_l1(p, r)
    warped = M.temporal_l1_warped(p, r, motion)
    assert unwarped > 0.02
    assert warped == pytest.approx(0.0, abs=1e-12)  # integer pan: exact, the entering strip masked
    masks = M.warped_valid_masks(motion)
    assert masks[:, :, :26].all() and not masks[:, :, 26:].any()  # x = j + 0.5 + 2 > 28 for j ≥ 26


def test_subpixel_pan_warped_error_is_far_below_unwarped():
    t, h, w, s = 4, 20, 28, 0.5
    i, j = np.mgrid[0:h, 0:w]

    def plane(x, y, c):  # smooth radiance on the panned plane
        return 1.0 + 0.5 * np.sin(0.15 * x + c) * np.cos(0.12 * y)

    ref = np.stack([np.stack([plane(j + s * k, i, c) for c in range(3)], -1) for k in range(t)])
    pred = 0.7 * ref + 0.2  # stable: a fixed function of the plane
    motion = np.zeros((t, h, w, 2))
    motion[..., 0] = s
    # bilinear resampling blurs a little (error ∝ frequency², the frame difference ∝ frequency)
    assert M.temporal_l1_warped(pred, ref, motion) < 0.1 * M.temporal_l1(pred, ref)


@pytest.mark.parametrize("name", ["temporal_l1", "temporal_l1_warped", "tpsnr"])
def test_error_grows_monotonically_with_noise(name):
    p0, r, motion = pan(shift=1, t=3, h=16, w=16)
    noise = np.random.default_rng(9).normal(size=r.shape)
    fn = M.get_metric(name)
    kw = {"motion": motion} if name == "temporal_l1_warped" else {}
    values = [fn.fn(r + s * noise, r, **kw) for s in (0.01, 0.03, 0.1, 0.3)]
    steps = np.diff(values)
    assert np.all(steps < 0) if fn.higher_is_better else np.all(steps > 0), values


# --------------------------------------------------------------------------- disocclusion


def moving_square(t=3, h=16, w=24, step=2):
    """Static textured background (depth 10) with a square (depth 1) moving right by ``step``."""
    rng = np.random.default_rng(5)
    background = 0.2 + 0.5 * rng.random((h, w, 3))
    ref = np.repeat(background[None], t, 0).copy()
    depth = np.full((t, h, w), 10.0)
    motion = np.zeros((t, h, w, 2))
    disoccluded = np.zeros((t, h, w), dtype=bool)
    rows = slice(5, 10)
    for k in range(t):
        cols = slice(3 + step * k, 8 + step * k)
        ref[k, rows, cols] = 1.5
        depth[k, rows, cols] = 1.0
        motion[k, rows, cols, 0] = -step
        if k:
            disoccluded[k, rows, 3 + step * (k - 1) : 3 + step * k] = True
    return ref, depth, motion, disoccluded


def test_depth_test_masks_exactly_the_disoccluded_background():
    ref, depth, motion, disoccluded = moving_square()
    masks = M.warped_valid_masks(motion, depth=depth)
    np.testing.assert_array_equal(masks, ~disoccluded[1:])
    pred = 0.9 * ref  # stable per surface
    assert M.temporal_l1_warped(pred, ref, motion, depth=depth) == pytest.approx(0.0, abs=1e-12)
    assert M.temporal_l1_warped(pred, ref, motion) > 0.001  # without the depth test, they count
    single = M.disocclusion_mask(motion[1], depth[1], depth[0])
    np.testing.assert_array_equal(single, ~disoccluded[1])


def test_depth_test_rejects_every_tap_of_another_surface():
    d_prev = np.ones((4, 4))
    d_prev[:, 2:] = 5.0
    d_now = np.ones((4, 4))
    m = np.zeros((4, 4, 2))
    m[..., 0] = 0.5  # samples halfway between columns j and j + 1
    valid = M.disocclusion_mask(m, d_now, d_prev)
    np.testing.assert_array_equal(valid[:, 0], True)
    np.testing.assert_array_equal(valid[:, 1], False)  # reads column 2 (depth 5) with weight 1/2
    with pytest.raises(ValueError, match="both"):
        M.disocclusion_mask(m, d_now)


def test_masks_restrict_the_mean():
    p, r = random_seq(seed=6)
    mask = np.zeros((12, 15), dtype=bool)
    mask[2:8, 3:11] = True
    full = np.abs(np.diff(p, axis=0) - np.diff(r, axis=0)).mean(-1)
    assert M.temporal_l1(p, r, masks=mask) == pytest.approx(full[:, mask].mean(), rel=1e-12)
    per_frame = np.stack([mask, ~mask, mask, ~mask])  # pair t uses masks[t]
    expected = np.concatenate([full[0][~mask], full[1][mask], full[2][~mask]]).mean()
    assert M.temporal_l1(p, r, masks=per_frame) == pytest.approx(expected, rel=1e-12)
    zero = np.zeros((4, 12, 15, 2))
    assert M.temporal_l1_warped(p, r, zero, masks=mask) == pytest.approx(full[:, mask].mean(), rel=1e-12)
    with pytest.raises(ValueError, match="no pixel"):
        M.temporal_l1(p, r, masks=np.zeros((12, 15), dtype=bool))
    with pytest.raises(ValueError, match="boolean"):
        M.temporal_l1(p, r, masks=mask.astype(float))


def test_everything_disoccluded_is_an_error():
    p, r = random_seq(t=2)
    away = np.full((2, 12, 15, 2), 100.0)
    with pytest.raises(ValueError, match="no pixel"):
        M.temporal_l1_warped(p, r, away)


# --------------------------------------------------------------------------- hard inputs


@pytest.mark.parametrize("name", ["temporal_l1", "temporal_l1_warped", "tpsnr"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_nonfinite_prediction_is_worst(name, bad):
    p, r = random_seq()
    p[2, 3, 4, 0] = bad
    motion = np.zeros(r.shape[:3] + (2,))
    m = M.get_metric(name)
    kw = {"motion": motion} if name == "temporal_l1_warped" else {}
    assert m.fn(p, r, **kw) == m.worst == temporal.WORST[name]
    if m.map_fn is not None:
        assert np.all(m.map_fn(p, r, **kw) == m.worst)


def test_worst_tpsnr_is_attainable_bound():
    black = np.zeros((2, 4, 4, 3))
    flash = black.copy()
    flash[1] = 1e30  # tone-mapped difference → 1 against a reference going the other way
    ref = black.copy()
    ref[0] = 1e30
    assert M.tpsnr(flash, ref) == pytest.approx(temporal.WORST["tpsnr"], abs=1e-9)


def test_black_extreme_tiny_and_odd_sequences():
    z = np.zeros((3, 16, 16, 3))
    assert M.temporal_l1(z, z) == 0.0 and M.tpsnr(z, z) == math.inf
    flicker = z.copy()
    flicker[1] = 0.5
    assert M.temporal_l1(flicker, z) == pytest.approx(0.5)
    assert math.isfinite(M.tpsnr(flicker, z))
    rng = np.random.default_rng(7)
    hdr = 10.0 ** rng.uniform(-6, 6, (3, 16, 16, 3))
    assert math.isfinite(M.temporal_l1(hdr * 1.01, hdr))
    assert math.isfinite(M.temporal_l1_warped(hdr * 1.01, hdr, np.zeros((3, 16, 16, 2))))
    assert math.isfinite(M.tpsnr(hdr * 1.01, hdr))
    for shape in [(2, 1, 1, 3), (3, 5, 7, 3)]:
        r = rng.random(shape)
        p = r * 1.3
        motion = np.zeros(shape[:3] + (2,))
        for v in (M.temporal_l1(p, r), M.temporal_l1_warped(p, r, motion), M.tpsnr(p, r)):
            assert math.isfinite(v)


def test_bad_temporal_inputs_are_clear_errors():
    p, r = random_seq()
    with pytest.raises(ValueError, match=r"\(4, 12, 15, 3\).*\(3, 12, 15, 3\)"):
        M.temporal_l1(p, r[:3])
    with pytest.raises(ValueError, match="at least 2 frames"):
        M.temporal_l1(p[:1], r[:1])
    with pytest.raises(ValueError, match="motion"):
        M.temporal_l1_warped(p, r, None)
    with pytest.raises(ValueError, match="motion must have shape"):
        M.temporal_l1_warped(p, r, np.zeros((3, 12, 15, 2)))  # one per frame, frame 0 included
    nan_motion = np.zeros((4, 12, 15, 2))
    nan_motion[1, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        M.temporal_l1_warped(p, r, nan_motion)
    with pytest.raises(ValueError, match="depth must have shape"):
        M.temporal_l1_warped(p, r, np.zeros((4, 12, 15, 2)), depth=np.ones((4, 12, 14)))
    bad_ref = r.copy()
    bad_ref[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="reference"):
        M.tpsnr(p, bad_ref)
    with pytest.raises(ValueError, match="mixes frame shapes"):
        M.temporal_l1([p[0], p[1][:5]], [r[0], r[1]])
    depth_11 = np.ones((4, 12, 15, 1))  # H×W×1 per frame, like Frame.buffers["depth"], is accepted
    assert math.isfinite(M.temporal_l1_warped(p, r, np.zeros((4, 12, 15, 2)), depth=depth_11))


# --------------------------------------------------------------------------- a bright emitter in front of black


def _emitter_in_front_of_black(size=24):
    """Two frames of a small emitter (radiance 1e4, 2×1 px) in front of a black background, as on the
    demo's glossy_fireflies (main 3a0b9b0, seed 915): the background's motion is −2.9 px per frame (the
    camera's), the emitter's −0.6 px, so warping a background pixel right of the emitter reads the
    emitter from the previous frame. The prediction is the reference with a 10 % error on the emitter."""
    ref = np.zeros((2, size, size, 3))
    ref[:, 5, 12:14] = 1e4
    motion = np.zeros((2, size, size, 2))
    motion[1, ..., 0] = -2.9
    motion[1, 5, 12:14, 0] = -0.6
    pred = ref * 1.1
    return pred, ref, motion


@pytest.mark.parametrize("name", ["temporal_relmse", "temporal_relmse_robust"])
def test_a_bright_value_carried_onto_black_is_measured_against_its_own_brightness(name):
    # With frame t's local magnitude alone the background pixels that read the emitter scored
    # (0.1 · 1e4)² / 0.01 = 1e8 and the pair ~1e5 (the demo's 1.5e5 for every denoiser); the
    # denominator of both frames' magnitude holds them to the emitter's own 10 % error.
    pred, ref, motion = _emitter_in_front_of_black()
    value = M.compute_metrics(pred, ref, [name], motion=motion)[name].value
    per_pixel = temporal.temporal_relmse_map(pred, ref, motion)
    assert value < 1.0 and per_pixel.max() < 100.0
    # the scene does carry the emitter onto black: frame t's magnitude alone puts those pixels at ≥ 1e6
    checked = temporal.check_sequences(pred, ref, min_frames=2)
    diff, _, valid, _ = temporal._relative_pairs(checked, None, motion, None, temporal.DEPTH_TOLERANCE)
    alone = np.square(diff[0]) / (np.square(temporal._local_magnitude(ref[1])) + 0.01)
    assert alone.mean(axis=-1)[valid[0]].max() > 1e6
    assert temporal.temporal_relmse(ref, ref, motion) == 0.0
