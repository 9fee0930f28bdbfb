"""OIDN's comparison scores (``--metrics oidn``): against OIDN's own code, pinned values and hard cases.

Pinned values: OIDN's own evaluation path (``dataset.load_image_features`` → ``transform_feature
(..., 'hdr', 'srgb', 1.)`` → ``image.compare_images``), full precision, on
``bench/oidn_compare_pins.py``'s frames, from
``OIDN_TRAINING=/tmp/oidn/training OIDN_COMMIT=e050ac80deca5c2f76633f0054b73c6cb7d2d251
.venv/bin/python bench/oidn_compare_pins.py`` run 2026-12-02 (RenderKit/oidn commit e050ac80,
2026-01-14, ``training/`` extracted with ``git archive``; torch 2.13 CPU, OpenImageIO 3.2.2).
With ``OIDN_TRAINING`` set the same frames are scored live by their code and their
``compare_image.py`` script.
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from denoisebench.metrics import compute_metrics, get_metric
from denoisebench.metrics.field import oidn_compare as oc
from denoisebench.metrics.registry import default_metric_names, expand_metric_names
from denoisebench.metrics.validation import MetricNotApplicable
from tests.support.paths import REPO

ROOT = REPO

#: (PSNR dB, SSIM) from OIDN's own code (module docstring for the provenance).
PINS = {
    "noisy": (20.88718084224851, 0.5184094905853271),
    "dark": (51.452504793717615, 0.9927327036857605),
    "bright": (42.6413250804565, 0.9843196868896484),
    "fireflies": (20.578687269114408, 0.4867742955684662),
    "blurred": (25.978104034739356, 0.4514400064945221),
    "negative": (14.180599610512264, 0.39167866110801697),
}
# Measured when pinning: largest |ours − theirs| 3.4e-6 dB and 5.1e-6 SSIM (theirs float32 torch,
# ours float64; the SSIM gap is largest on "bright", whose near-white frames cancel in float32).
PSNR_TOL = 2e-5
SSIM_TOL = 2e-5


def _load_pins_script():
    spec = importlib.util.spec_from_file_location("oidn_compare_pins", ROOT / "bench" / "oidn_compare_pins.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def pins_script():
    return _load_pins_script()


@pytest.fixture(scope="module")
def frames(pins_script):
    return pins_script.pin_frames()


def test_frames_are_the_pinned_ones(frames):
    assert list(frames) == list(PINS)
    for pred, ref in frames.values():
        assert pred.shape == ref.shape == (36, 44, 3) and pred.dtype == np.float32
    # the hard cases are what their names say
    assert frames["dark"][1].max() < 1e-2
    assert np.mean(frames["bright"][1] > 6.37) > 0.5  # most of the reference past the white point
    assert frames["fireflies"][0].max() > 1e5
    assert frames["negative"][0].min() < 0


@pytest.mark.parametrize("name", list(PINS))
def test_scores_equal_the_pinned_oidn_values(frames, name):
    pred, ref = frames[name]
    psnr, ssim = PINS[name]
    assert oc.oidn_psnr(pred, ref) == pytest.approx(psnr, abs=PSNR_TOL)
    assert oc.oidn_ssim(pred, ref) == pytest.approx(ssim, abs=SSIM_TOL)


def test_transfer_restated_from_the_published_formulas():
    # Hable's curve written out again (color.py tonemap, dataset.py transform_feature), float64
    def hable(v):
        a, b, c, d, e, f = 0.22, 0.30, 0.10, 0.20, 0.01, 0.30
        return (v * (a * v + c * b) + d * e) / (v * (a * v + b) + d * f) - e / f

    x = np.array([0.0, 1e-6, 1e-3, 0.05, 0.18, 0.5, 0.568, 0.569, 1.0, 3.0, 6.0, 6.3, 6.4, 50.0])
    by_hand = np.minimum(hable(1.758141 * x) / hable(11.2), 1.0)
    np.testing.assert_allclose(oc.hable_filmic(x), by_hand, rtol=1e-13, atol=1e-15)
    assert oc.hable_filmic(np.array([0.0]))[0] == 0.0
    assert np.all(oc.hable_filmic(np.array([6.4, 1e3, 1e30, 1e300])) == 1.0)  # white point 11.2 / 1.758141
    dense = oc.hable_filmic(np.linspace(0, 8, 20001))
    assert np.all(np.diff(dense) >= 0)  # monotone, and continuous across the v = 1 switch of forms
    srgb = oc.oidn_srgb(np.array([[[0.18, 1.0, -2.0]]]))[0, 0]
    enc = lambda y: 12.92 * y if y <= 0.0031308 else 1.055 * y ** (1 / 2.4) - 0.055  # noqa: E731
    assert srgb[0] == pytest.approx(enc(by_hand[4]), abs=1e-12)
    assert srgb[1] == pytest.approx(enc(by_hand[8]), abs=1e-12)
    assert srgb[2] == 0.0  # negatives clamp to 0 (their loader and infer.py)


def test_psnr_is_the_mse_of_the_transformed_images(frames):
    pred, ref = frames["noisy"]
    mse = np.mean((oc.oidn_srgb(pred) - oc.oidn_srgb(ref)) ** 2)
    assert oc.oidn_psnr(pred, ref) == pytest.approx(-10 * math.log10(mse), abs=1e-12)
    # exposure scales radiance before the curve: a dark frame scored at exposure 1000 is the bright one
    dp, dr = frames["dark"]
    assert oc.oidn_psnr(dp, dr, exposure=1000.0) == pytest.approx(oc.oidn_psnr(dp * 1000.0, dr * 1000.0), abs=1e-9)


def test_hard_cases_finite_and_perfect_scores(frames):
    zeros = np.zeros((16, 16, 3), np.float32)
    assert oc.oidn_psnr(zeros, zeros) == math.inf  # theirs: ZeroDivisionError in 1. / mse
    assert oc.oidn_ssim(zeros, zeros) == 1.0
    for pred, ref in frames.values():
        assert oc.oidn_psnr(ref, ref) == math.inf
        assert oc.oidn_ssim(ref, ref) == pytest.approx(1.0, abs=1e-12)
    grey, white = np.full_like(zeros, 0.18), np.full_like(zeros, 7.0)
    for a, b in ((grey, zeros), (zeros, white), (grey, white)):
        p, s = oc.oidn_psnr(a, b), oc.oidn_ssim(a, b)
        assert math.isfinite(p) and p >= 0.0 and -1.0 <= s < 1.0
    # white (y = 1) against black: MSE 1, PSNR 0 = the worst value; constant SSIM = C1 / (1 + C1)
    # up to the Gaussian window's float32 rounding (its weights sum to 1 − O(1e-7), theirs alike:
    # a variance of ~1.7e-7 on a constant image, 2e-4 of C2), measured 9.99832e-5 for 9.99900e-5
    assert oc.oidn_psnr(white, zeros) == pytest.approx(0.0, abs=1e-12)
    assert oc.oidn_ssim(white, zeros) == pytest.approx(1e-4 / (1 + 1e-4), rel=1e-3)
    huge = np.full_like(zeros, 3e38)  # near float32's maximum: their float32 curve gives NaN above ~2e19
    huge[::2] = 1e25
    assert oc.oidn_psnr(huge, white) == math.inf  # both entirely white
    assert oc.oidn_ssim(huge, white) == pytest.approx(1.0, abs=1e-12)
    assert math.isfinite(oc.oidn_psnr(huge, grey)) and math.isfinite(oc.oidn_ssim(huge, grey))


def test_nonfinite_prediction_worst_and_small_frames_not_applicable(frames):
    pred, ref = (a.copy() for a in frames["noisy"])
    pred[3, 4, 1] = np.nan
    results = compute_metrics(pred, ref, ["oidn"])
    assert list(results) == ["oidn_psnr", "oidn_ssim"]
    for name, result in results.items():
        assert result.value == get_metric(name).worst and result.nonfinite_count == 1
    small = np.ones((10, 32, 3))
    with pytest.raises(MetricNotApplicable, match="11×11"):
        oc.oidn_ssim(small, small)
    assert oc.oidn_psnr(small, small) == math.inf


def test_set_is_opt_in_and_registered_higher_is_better():
    assert expand_metric_names(["oidn"]) == ["oidn_psnr", "oidn_ssim"]
    assert not {"oidn_psnr", "oidn_ssim"} & set(default_metric_names())
    for name in ("oidn_psnr", "oidn_ssim"):
        m = get_metric(name)
        assert m.higher_is_better and m.domain == "oidn" and m.kind == "spatial"
    assert get_metric("oidn_psnr").perfect == math.inf and get_metric("oidn_ssim").perfect == 1.0


# --------------------------------------------------------------------------- OIDN's own code, live
# Set OIDN_TRAINING to an OIDN training/ folder (torch and OpenImageIO are in the venv). Each of
# their runs is a subprocess (their modules are named color, image, util): about a minute in all.


@pytest.fixture(scope="module")
def oidn_live(pins_script, frames, tmp_path_factory):
    training = os.environ.get("OIDN_TRAINING")
    if not training:
        pytest.skip("OIDN_TRAINING not set (an OIDN training/ folder)")
    pytest.importorskip("OpenImageIO")
    training = Path(training).resolve()
    folder = tmp_path_factory.mktemp("oidn_frames")
    pins_script.write_frames(folder, frames)
    theirs = pins_script.their_evaluation(training, folder, list(frames))
    printed = {name: pins_script.their_compare_image(training, folder, name) for name in frames}
    return theirs, printed


@pytest.mark.parametrize("name", list(PINS))
def test_scores_equal_oidn_code_live(oidn_live, frames, name):
    theirs, printed = oidn_live
    pred, ref = frames[name]
    psnr, ssim = oc.oidn_psnr(pred, ref), oc.oidn_ssim(pred, ref)
    assert psnr == pytest.approx(theirs[name]["psnr"], abs=PSNR_TOL)
    assert ssim == pytest.approx(theirs[name]["ssim"], abs=SSIM_TOL)
    if name == "negative":
        # compare_image.py does not clamp negatives: its non-monotone curve scores this frame apart
        assert printed[name]["psnr"] < psnr - 1.0, json.dumps(printed[name])
    else:  # compare_image.py prints "psnr = %.4f, ssim = %.4f": ours rounds to the same digits
        assert abs(printed[name]["psnr"] - psnr) <= 0.5e-4 + PSNR_TOL
        assert abs(printed[name]["ssim"] - ssim) <= 0.5e-4 + SSIM_TOL


# --------------------------------------------------------------------------- the command line


def test_run_benchmark_metrics_oidn(tmp_path):
    """``run-benchmark --metrics oidn`` stores both scores, per frame equal to the functions on the same frames."""
    from denoisebench.cli import main
    from denoisebench.dataset.synthetic import make_synthetic_dataset, synthetic_frame

    data = make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=16, width=16, spp=(1,))
    argv = ["--data", str(data), "--db", str(tmp_path / "db.sqlite"), "--out", str(tmp_path / "report")]
    assert main(["benchmark", *argv, "--denoisers", "identity", "--metrics", "oidn", "--time-size", "64x64"]) == 0
    results = json.loads((tmp_path / "report" / "results.json").read_text())
    row = next(r for r in results["summary"] if r["denoiser"] == "identity")
    assert {"oidn_psnr", "oidn_ssim"} <= set(row["metrics"])
    frames = [f for f in results["frames"] if f["denoiser"] == "identity" and f["status"] == "ok"]
    assert frames
    for f in frames:  # identity: the noisy 1-spp colour against the reference, as make_synthetic_dataset wrote them
        i = int(f["scene"].rsplit("_", 1)[1])
        buffers, ref = synthetic_frame(16, 16, f["frame"], 1, (1.0, 0.0), seed=i, phase=i)
        assert f["metrics"]["oidn_psnr"] == pytest.approx(oc.oidn_psnr(buffers["color"], ref), abs=1e-9)
        assert f["metrics"]["oidn_ssim"] == pytest.approx(oc.oidn_ssim(buffers["color"], ref), abs=1e-9)
