"""Robust (trimmed) relMSE and temporal_relmse: one firefly cannot decide them (metrics/ours/robust.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from denoisebench.metrics import compute_metrics, get_metric, relmse, relmse_floor, temporal_relmse
from denoisebench.metrics.ours import robust as rb
from denoisebench.metrics.ours.temporal import temporal_relmse_floor, temporal_relmse_map


def _textured(rng, shape=(32, 32, 3), low=0.05, high=1.0):
    return rng.uniform(low, high, shape)


def _naive_trimmed(pred, ref, trim):
    """Peer: sort the per-pixel errors and average all but the ceil(trim·N) largest."""
    e = ((pred - ref) ** 2 / (ref**2 + 0.01)).mean(axis=-1).ravel()
    k = min(math.ceil(trim * e.size - 1e-9), e.size - 1) if trim > 0 else 0
    return float(np.sort(e)[: e.size - k].mean())


# --------------------------------------------------------------------------- pure functions


def test_trimmed_count_and_trim_zero_is_plain_relmse():
    assert rb.trimmed_count(6400, 0.001) == 7  # an 80×80 frame
    assert rb.trimmed_count(1920 * 1080, 0.001) == 2074
    assert rb.trimmed_count(1000, 0.001) == 1  # exactly 0.1 %
    assert rb.trimmed_count(100, 0.001) == 1  # at least one pixel when trim > 0
    assert rb.trimmed_count(1, 0.4) == 0 and rb.trimmed_count(10, 0.0) == 0
    rng = np.random.default_rng(1)
    ref = _textured(rng)
    pred = ref + rng.normal(0, 0.1, ref.shape)
    assert rb.relmse_robust(pred, ref, trim=0.0) == pytest.approx(relmse(pred, ref), rel=1e-12)
    assert rb.relmse_robust(ref, ref) == 0.0


@pytest.mark.parametrize("trim", [0.001, 0.01, 0.2])
def test_matches_a_sort_based_peer(trim):
    rng = np.random.default_rng(2)
    ref = _textured(rng, (24, 40, 3))
    pred = ref * rng.exponential(1.0, ref.shape)
    assert rb.relmse_robust(pred, ref, trim=trim) == pytest.approx(_naive_trimmed(pred, ref, trim), rel=1e-12)
    m = rb.relmse_robust_map(pred, ref, trim=trim)
    assert m.shape == (24, 40) and np.count_nonzero(m == 0) >= rb.trimmed_count(960, trim)


def test_bad_trim_and_nonfinite_prediction():
    rng = np.random.default_rng(3)
    ref = _textured(rng, (16, 16, 3))
    for bad in (-0.1, 0.5, 1.0, math.nan, "x", None):
        with pytest.raises(ValueError, match="trim fraction"):
            rb.relmse_robust(ref, ref, trim=bad)
    pred = ref.copy()
    pred[0, 0, 0] = np.nan  # trimming never hides a NaN
    assert rb.relmse_robust(pred, ref) == math.inf
    seq = np.stack([ref, ref, pred])
    assert rb.temporal_relmse_robust(seq, np.stack([ref] * 3)) == math.inf


def test_hard_cases_are_finite():
    z = np.zeros((16, 16, 3))
    huge = np.full((16, 16, 3), 1e30)
    rng = np.random.default_rng(4)
    hdr = np.exp(rng.uniform(-20, 30, (16, 16, 3)))  # 50 stops of dynamic range
    for pred, ref in ((z, z), (huge, z), (z, huge), (hdr, hdr[::-1]), (hdr * 2, hdr)):
        assert math.isfinite(rb.relmse_robust(pred, ref))
        seq_p, seq_r = np.stack([pred, ref, pred]), np.stack([ref, ref, pred])
        assert math.isfinite(rb.temporal_relmse_robust(seq_p, seq_r))
        f = rb.relmse_robust_floor(pred, ref, np.full(ref.shape, 1e-3))
        assert math.isfinite(f.floor) and math.isfinite(f.se)
    assert rb.relmse_robust(z, z) == 0.0 and rb.temporal_relmse_robust(np.stack([z, z]), np.stack([z, z])) == 0.0


# --------------------------------------------------------------------------- one firefly


def test_one_firefly_moves_the_robust_score_by_at_most_its_stated_bound():
    rng = np.random.default_rng(5)
    ref = _textured(rng)  # 1024 pixels: k = ceil(1.024) = 2 dropped
    pred = ref + rng.normal(0, 0.05, ref.shape)
    n = 32 * 32
    k = rb.trimmed_count(n, rb.DEFAULT_TRIM)
    errors = np.sort(((pred - ref) ** 2 / (ref**2 + 0.01)).mean(axis=-1).ravel())
    bound = errors[n - k] / (n - k)  # e_(N−k+1) / (N − k): the smallest dropped error over the kept count
    before_raw, before = relmse(pred, ref), rb.relmse_robust(pred, ref)
    i, j = np.unravel_index(np.argmin(ref.mean(axis=-1)), ref.shape[:2])  # the darkest pixel
    fire = pred.copy()
    fire[i, j] = 100.0  # one firefly, radiance 100 in a dark pixel
    after_raw, after = relmse(fire, ref), rb.relmse_robust(fire, ref)
    assert after_raw / before_raw > 1000  # raw relMSE: orders of magnitude
    assert 0.0 <= after - before <= bound * (1 + 1e-9)
    assert bound < 0.02 * before  # here the bound is under 2 % of the score
    # the bound holds for a firefly of any size, and for a firefly in any pixel
    for value in (1e3, 1e8):
        for pixel in ((0, 0), (17, 5)):
            f = pred.copy()
            f[pixel] = value
            assert 0.0 <= rb.relmse_robust(f, ref) - before <= bound * (1 + 1e-9)


def test_one_firefly_in_one_frame_barely_moves_the_robust_flicker_score():
    rng = np.random.default_rng(6)
    ref = np.stack([_textured(rng)] * 4)
    pred = ref + rng.normal(0, 0.05, ref.shape)
    before_raw, before = temporal_relmse(pred, ref), rb.temporal_relmse_robust(pred, ref)
    pred[2, 7, 9] = 100.0
    assert temporal_relmse(pred, ref) / before_raw > 1000
    assert rb.temporal_relmse_robust(pred, ref) == pytest.approx(before, rel=0.02)


def test_temporal_trim_zero_is_the_raw_score_with_motion_and_masks():
    rng = np.random.default_rng(7)
    ref = rng.uniform(0.1, 1.0, (3, 16, 16, 3))
    pred = ref + rng.normal(0, 0.1, ref.shape)
    motion = np.zeros((3, 16, 16, 2))
    motion[..., 0] = 0.6
    masks = rng.random((16, 16)) > 0.2
    kw = dict(motion=motion, masks=masks)
    assert rb.temporal_relmse_robust(pred, ref, trim=0.0, **kw) == pytest.approx(temporal_relmse(pred, ref, **kw))
    np.testing.assert_allclose(
        rb.temporal_relmse_robust_map(pred, ref, trim=0.0, **kw), temporal_relmse_map(pred, ref, **kw)
    )
    var = np.full(ref.shape, 1e-3)
    assert rb.temporal_relmse_robust_floor(pred, ref, var, trim=0.0, **kw) == pytest.approx(
        temporal_relmse_floor(pred, ref, var, **kw)
    )


# --------------------------------------------------------------------------- ranking over noise draws


def _monte_carlo(rng, ref, spp, q, firefly):
    """Mean of ``spp`` samples ref·g + F·[u < q] (g ~ Exp(1)): heavy-tailed per-pixel noise whose
    expectation is ref + q·F (per pixel, the same firefly in every channel)."""
    h, w, _ = ref.shape
    g = rng.exponential(1.0, (spp, h, w, 3)).mean(axis=0)
    hits = (rng.random((spp, h, w)) < q).sum(axis=0)
    return ref * g + firefly * hits[..., None] / spp


def test_over_100_noise_draws_the_robust_score_ranks_a_4x_noisier_input_worse():
    rng = np.random.default_rng(8)
    shape = (64, 64, 3)  # 4096 pixels: 5 dropped
    base = _textured(rng, shape, 0.02, 1.0)
    q, firefly = 1.0 / (4 * 4096), 200.0  # about one firefly pixel per 4-spp frame
    truth = base + q * firefly
    robust_right = raw_right = 0
    for _ in range(100):
        good = _monte_carlo(rng, base, 4, q, firefly)  # 4 spp
        bad = _monte_carlo(rng, base, 1, q, firefly)  # 1 spp: 4× the variance
        robust_right += rb.relmse_robust(bad, truth) > rb.relmse_robust(good, truth)
        raw_right += relmse(bad, truth) > relmse(good, truth)
    assert robust_right == 100
    assert raw_right < 80  # raw relMSE: the fireflies decide the ranking in many draws (measured 52)


# --------------------------------------------------------------------------- floors


def test_floor_with_trim_zero_is_relmse_floor_and_a_perfect_prediction_scores_its_floor():
    rng = np.random.default_rng(9)
    truth = _textured(rng, (32, 32, 3), 0.2, 1.0)
    var = (0.03 * truth) ** 2
    pred = truth * 1.05
    ref = truth + rng.normal(0, 1, truth.shape) * np.sqrt(var)
    assert rb.relmse_robust_floor(pred, ref, var, trim=0.0) == relmse_floor(pred, ref, var)
    scores, floors = [], []
    for _ in range(200):
        ref = truth + rng.normal(0, 1, truth.shape) * np.sqrt(var)
        scores.append(rb.relmse_robust(truth, ref))
        floors.append(rb.relmse_robust_floor(truth, ref, var).floor)
    # the floor is the kept pixels' noise share: within 2 % of a perfect denoiser's mean score
    assert np.mean(floors) == pytest.approx(np.mean(scores), rel=0.02)


# --------------------------------------------------------------------------- registry and compute


def test_registry_entries_and_compute_metrics_pass_the_trim():
    for name, kind, floor in (
        ("relmse_robust", "spatial", rb.relmse_robust_floor),
        ("temporal_relmse_robust", "temporal", rb.temporal_relmse_robust_floor),
    ):
        m = get_metric(name)
        assert (m.kind, m.higher_is_better, m.aggregate, m.floor_fn, m.perfect) == (kind, False, "mean", floor, 0.0)
        assert "trim" in m.accepts and m.worst == math.inf
    assert get_metric("robust_relmse").name == "relmse_robust"
    rng = np.random.default_rng(10)
    ref = rng.uniform(0.1, 1.0, (3, 32, 32, 3))
    pred = ref + rng.normal(0, 0.1, ref.shape)
    names = ["relmse_robust", "temporal_relmse_robust"]
    default = compute_metrics(pred, ref, names, ref_var=np.full(ref.shape, 1e-4))
    wide = compute_metrics(pred, ref, names, trim=0.2)
    assert default["relmse_robust"].value == pytest.approx(np.mean([rb.relmse_robust(p, r) for p, r in zip(pred, ref)]))
    assert wide["relmse_robust"].value == pytest.approx(
        np.mean([rb.relmse_robust(p, r, trim=0.2) for p, r in zip(pred, ref)])
    )
    assert wide["relmse_robust"].value < default["relmse_robust"].value
    assert wide["temporal_relmse_robust"].value < default["temporal_relmse_robust"].value
    assert default["relmse_robust"].floor > 0 and default["temporal_relmse_robust"].floor > 0


def test_run_benchmark_rejects_a_bad_trim_and_records_a_given_one(tmp_path, capsys):
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.cli import main

    assert main(["benchmark", "--data", str(tmp_path), "--trim", "0.7"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--trim" in err[0]
    assert BenchmarkConfig(denoisers=["identity"], spp=[1], trim=0.002).as_dict()["trim"] == 0.002
    assert "trim" not in BenchmarkConfig(denoisers=["identity"], spp=[1]).as_dict()  # the default keeps old runs' ids
