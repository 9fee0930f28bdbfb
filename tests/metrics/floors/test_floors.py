"""Reference-noise floors: corrected scores unbiased over many noise draws; scale-free temporal error.

Provenance of the tolerances: the synthetic truth R is known, so the score against it is exact; each
test draws hundreds of noisy references r = R + n (n Gaussian with the variance the floor is given)
and compares the mean corrected score with the truth in units of its standard error (the spread of
the draws / sqrt(draws)). The uncorrected score must sit one floor above the truth, far outside it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from denoisebench import metrics as M

DRAWS = 300


def _scene(seed=3, size=24):
    rng = np.random.default_rng(seed)
    truth = np.exp(rng.normal(-1.0, 1.5, (size, size, 3)))  # dark to bright: 0.004 .. 60
    var = (0.05 * truth) ** 2 + 1e-5  # a reference 5 % noisy, as a 64x-input-spp reference is
    return rng, truth, var


def _draws(metric, floor_fn, pred, truth, var, rng):
    raw, corrected, ses = [], [], []
    for _ in range(DRAWS):
        ref = truth + rng.normal(0.0, 1.0, truth.shape) * np.sqrt(var)
        score, floor = metric(pred, ref), floor_fn(pred, ref, var)
        raw.append(score)
        corrected.append(score - floor.floor)
        ses.append(floor.se)
    return np.array(raw), np.array(corrected), np.array(ses)


@pytest.mark.parametrize("kind", ["zero-mean error", "10 % too dark", "perfect"])
@pytest.mark.parametrize("name", ["relmse", "mse"])
def test_corrected_score_is_unbiased_and_the_raw_one_biased_by_the_floor(name, kind):
    rng, truth, var = _scene()
    pred = {
        "zero-mean error": truth * (1.0 + rng.normal(0.0, 0.1, truth.shape)),
        "10 % too dark": 0.9 * truth,
        "perfect": truth.copy(),
    }[kind]
    metric = M.get_metric(name)
    target = metric.fn(pred, truth)
    raw, corrected, ses = _draws(metric.fn, metric.floor_fn, pred, truth, var, rng)
    se = corrected.std(ddof=1) / math.sqrt(DRAWS)
    assert abs(corrected.mean() - target) < 3.0 * se, (corrected.mean(), target, se)
    floor = raw.mean() - target
    assert floor > 10.0 * se  # the uncorrected score is biased by the floor ...
    assert abs((raw - corrected).mean() - floor) < 3.0 * se  # ... and the floor is that bias
    # the reported se is the spread the reference's noise causes: within 15 %, or above it (never
    # below) where the prediction is near perfect and max(d² − v, 0) overestimates e², or where a
    # few bright pixels carry the whole (linear) mse
    spread = corrected.std(ddof=1)
    assert 0.85 * spread < ses.mean() < (1.6 if kind == "perfect" or name == "mse" else 1.15) * spread


def test_relmse_floor_with_firefly_noise_in_the_reference_is_low_but_positive():
    # 5 % of the values 70 % noisy (a glossy scene's reference): the expansion does not hold there,
    # they get the first-order term only (SECOND_ORDER_LIMIT). Measured: floor 0.195, true share 0.36.
    rng, truth, var = _scene()
    hot = rng.random(truth.shape) < 0.05
    var[hot] = (0.7 * truth[hot]) ** 2
    raw, corrected, _ = _draws(M.relmse, M.relmse_floor, truth, truth, var, rng)
    share, floor = raw.mean(), (raw - corrected).mean()
    assert 0.4 * share < floor < share


def test_relmse_floor_of_a_perfect_prediction_is_the_variance_over_the_denominator():
    _, truth, var = _scene()
    floor = M.relmse_floor(truth, truth, var)  # to first order in the relative noise (5 % here)
    assert floor.floor == pytest.approx(np.mean(var / (truth**2 + 0.01)), rel=0.03)
    assert M.mse_floor(truth, truth, var).floor == pytest.approx(var.mean())


def test_floors_refuse_bad_variance_and_give_nan_se_for_a_nonfinite_prediction():
    _, truth, var = _scene(size=8)
    with pytest.raises(ValueError, match="negative"):
        M.mse_floor(truth, truth, -var)
    with pytest.raises(ValueError, match="non-finite"):
        M.relmse_floor(truth, truth, np.full_like(var, np.nan))
    with pytest.raises(ValueError, match="shape"):
        M.mse_floor(truth, truth, var[:4])
    bad = truth.copy()
    bad[0, 0, 0] = np.nan
    assert math.isnan(M.relmse_floor(bad, truth, var).se)
    assert M.mse_floor(truth, truth, var[..., :1]).floor == pytest.approx(var[..., :1].mean())  # H×W×1 broadcasts


# --------------------------------------------------------------------------- temporal_relmse


def _sequence(scale, seed, frames=6, size=24, denoised=False):
    """A panning bright/dark scene at ``scale``; noisy input or a smooth, slightly wrong prediction."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:size, 0 : size + frames]
    base = scale * (0.2 + np.sin(xx / 3.0) ** 2 + 0.5 * (yy / size))[..., None] * np.array([1.0, 0.8, 0.6])
    ref = np.stack([base[:, t : t + size] for t in range(frames)])  # moves one pixel left per frame
    motion = np.zeros((frames, size, size, 2))
    motion[..., 0] = 1.0  # the point at x was at x + 1 in the previous frame
    if denoised:
        pred = ref * (1.0 + 0.02 * rng.normal(0.0, 1.0, (frames, 1, 1, 3)))  # small per-frame gain error
    else:
        pred = ref * rng.gamma(2.0, 0.5, ref.shape)  # Monte Carlo-like noise, mean preserving
    return pred, ref, motion


def test_temporal_relmse_is_scale_free_and_ranks_a_smooth_prediction_above_noise_across_scenes():
    scales = (0.05, 10.0, 300.0)  # a dark scene, a plain one, a glossy_fireflies-like bright one
    rel = M.get_metric("temporal_relmse")
    for denoised in (False, True):
        values = [rel.fn(*_sequence(s, 7, denoised=denoised)[:2], motion=_sequence(s, 7)[2]) for s in scales]
        # same relative content: the value barely moves with brightness (the 0.01 matters only when dark)
        assert values[1] == pytest.approx(values[2], rel=0.02)
    for s in scales:
        noisy, ref, motion = _sequence(s, 1)
        smooth, _, _ = _sequence(s, 1, denoised=True)
        assert rel.fn(smooth, ref, motion=motion) < rel.fn(noisy, ref, motion=motion)
    assert rel.aggregate == "mean" and rel.floor_fn is not None


def test_temporal_relmse_warps_ignores_a_constant_offset_and_masks_disocclusions():
    _, ref, motion = _sequence(1.0, 2)
    assert M.temporal_relmse(ref + 0.5, ref, motion=motion) == pytest.approx(0.0, abs=1e-20)
    # without motion a pan is flicker; with it, the warped differences match exactly
    moved = ref.copy()
    assert M.temporal_relmse(moved * 1.1, ref, motion=motion) < M.temporal_relmse(moved * 1.1, ref)
    maps = M.temporal_relmse_map(ref * 1.1, ref, motion=motion)
    assert maps.shape == (5, 24, 24) and np.all(maps[:, :, -1] == 0.0)  # last column came from outside
    bad = ref.copy()
    bad[2, 3, 3, 0] = np.inf
    assert M.temporal_relmse(bad, ref, motion=motion) == math.inf


def test_temporal_relmse_floor_matches_the_noise_of_hundreds_of_references():
    rng = np.random.default_rng(5)
    _, truth, motion = _sequence(1.0, 3, frames=4, size=16)
    var = (0.05 * truth) ** 2
    motion[..., 0] = 0.5  # half-pixel motion: bilinear taps mix two pixels' noise
    pred = truth * (1.0 + 0.05 * rng.normal(0.0, 1.0, truth.shape))
    target = M.temporal_relmse(pred, truth, motion=motion)
    raw, corrected = [], []
    for _ in range(DRAWS):
        ref = truth + rng.normal(0.0, 1.0, truth.shape) * np.sqrt(var)
        score = M.temporal_relmse(pred, ref, motion=motion)
        raw.append(score)
        corrected.append(score - M.temporal_relmse_floor(pred, ref, var, motion=motion).floor)
    raw, corrected = np.array(raw), np.array(corrected)
    se = corrected.std(ddof=1) / math.sqrt(DRAWS)
    # m (a 3x3 mean) carries a ninth of the noise: the first-order floor leaves < 1 % of it
    assert abs(corrected.mean() - target) < 3.0 * se + 0.01 * (raw.mean() - target)
    assert raw.mean() - target > 20.0 * se
