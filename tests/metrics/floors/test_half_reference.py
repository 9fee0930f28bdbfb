"""Scores without a closed-form floor, corrected from two half references.

Truth: a smooth image ``R``; a prediction ``p`` = R with its own error; references ``R + n`` with
Gaussian noise of variance ``v / N`` made as the mean of two independent halves. Over many reference
draws the raw score against the reference is biased by its noise; the half-reference correction
(:mod:`denoisebench.metrics.floors.half_reference`) removes most of that bias (it is first order: 64-75 % of it
here, where the reference's noise is as large as the prediction's own error). Plus the generator's side
(the even rounds' mean is kept, the odd rounds' follows from the full mean) and the runner's (a frame
with halves carries floors for FLIP and SSIM).
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench import metrics as M
from denoisebench.generator.render.reference import RoundMerger
from denoisebench.metrics.floors.half_reference import half_reference_floor, other_half


def _truth(size=32, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    base = 0.2 + 0.6 * np.stack([x, y, 0.5 * (x + y)], axis=-1)
    return (base + 0.02 * rng.standard_normal(base.shape)).clip(0.01).astype(np.float64)


@pytest.mark.parametrize("metric", ["ssim", "psnr", "flip"])
def test_half_reference_correction_removes_most_of_the_reference_bias(metric):
    truth = _truth()
    rng = np.random.default_rng(1)
    pred = truth * (1 + 0.05 * rng.standard_normal(truth.shape))
    fn = M.get_metric(metric).fn
    exact = fn(pred, truth)
    sigma_half = 0.025  # per-pixel noise of one half reference (a few % of the signal, as a modest reference)
    raw, corrected = [], []
    draws = 60 if metric == "flip" else 200
    for _ in range(draws):
        a = truth + sigma_half * rng.standard_normal(truth.shape)
        b = truth + sigma_half * rng.standard_normal(truth.shape)
        full = (a + b) / 2
        s_full = fn(pred, full)
        floor = half_reference_floor(s_full, (fn(pred, a), fn(pred, b)), 64, (32, 32))
        raw.append(s_full)
        corrected.append(s_full - floor.floor)
    raw_bias, corrected_bias = np.mean(raw) - exact, np.mean(corrected) - exact
    spread = np.std(corrected) / np.sqrt(len(corrected))
    assert abs(raw_bias) > 5 * spread  # the reference's noise moves the raw score measurably
    # first order in the reference's noise: measured here, 64 % (PSNR, log of a near-perfect match) to
    # 75 % (FLIP) of the bias removed with noise comparable to the prediction's own error
    assert abs(corrected_bias) < 0.5 * abs(raw_bias), (metric, exact, raw_bias, corrected_bias)


def test_half_reference_floor_is_the_richardson_step_and_refuses_bad_halves():
    # equal halves: floor = S_half − S_full
    floor = half_reference_floor(0.8, (0.7, 0.74), 64, (32, 32))
    assert floor.floor == pytest.approx(0.72 - 0.8) and floor.se == pytest.approx(0.02)
    # unequal halves (odd number of rounds): M_h is their harmonic mean
    m_h = 2 / (1 / 48 + 1 / 32)
    assert half_reference_floor(0.5, (0.6, 0.6), 80, (48, 32)).floor == pytest.approx(m_h * 0.1 / (80 - m_h))
    assert np.isnan(half_reference_floor(float("nan"), (0.1, 0.2), 64, (32, 32)).floor)
    with pytest.raises(ValueError, match="do not add up"):
        other_half(np.zeros((2, 2, 3)), np.zeros((2, 2, 3)), 64, (32, 16))


def test_the_merger_keeps_the_even_rounds_and_the_odd_ones_follow():
    rng = np.random.default_rng(3)
    merger = RoundMerger(4)
    rounds = [rng.random((5, 5, 3)) for _ in range(5)]
    for r in rounds:
        merger.add({"color": r, "color_var": np.full_like(r, 0.01)})
    out = merger.buffers()
    assert merger.half_spp == (12, 8)
    np.testing.assert_allclose(out["color_half"], np.mean(rounds[0::2], axis=0), rtol=1e-6)
    odd = other_half(out["color"], out["color_half"], 20, merger.half_spp)
    np.testing.assert_allclose(odd, np.mean(rounds[1::2], axis=0), rtol=1e-5, atol=1e-6)
    one = RoundMerger(4)
    one.add({"color": rounds[0], "color_var": np.full_like(rounds[0], 0.01)})
    assert one.half_spp is None and "color_half" not in one.buffers()


def test_a_frame_with_half_references_carries_floors_for_its_open_scores():
    from denoisebench.benchmark.measure import _frame_metrics

    truth = _truth(24)
    rng = np.random.default_rng(5)
    a = truth + 0.05 * rng.standard_normal(truth.shape)
    b = truth + 0.05 * rng.standard_normal(truth.shape)
    full = ((a + b) / 2).astype(np.float32)
    pred = (truth * 1.02).astype(np.float32)
    var = np.full_like(full, 0.05**2 / 2)
    names = ["relmse", "ssim", "flip", "psnr"]
    values, floors, ses, skipped = _frame_metrics(pred, full, names, ref_var=var, halves=((a, b), 64, (32, 32)))
    assert not skipped and set(floors) == set(names) and all(ses[n] >= 0 for n in names)
    assert floors["ssim"] < 0 and floors["psnr"] < 0  # a noisy reference lowers them: corrected is higher
    assert floors["flip"] > 0
    plain = _frame_metrics(pred, full, names, ref_var=var)[1]
    assert set(plain) == {"relmse"}  # without halves only the closed-form floor
    assert plain["relmse"] == floors["relmse"]
