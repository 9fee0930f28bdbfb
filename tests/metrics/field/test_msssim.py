"""MS-SSIM (pytorch-msssim) as a registered spatial metric: checked against the library itself."""

import numpy as np
import pytest
import torch
from pytorch_msssim import ms_ssim, ssim

from denoisebench.metrics import compute_metrics, get_metric
from denoisebench.metrics.field.msssim import ms_ssim_tensor, msssim, msssim_scales
from denoisebench.metrics.tonemap import tonemap


def _pair(size, sigma=0.1, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    ref = np.stack([0.5 + 0.4 * np.sin(7 * x), 0.4 + 0.3 * np.cos(5 * y), 0.3 + 0.2 * x * y], -1)
    pred = np.clip(ref + sigma * rng.standard_normal(ref.shape), 0, None)
    return pred.astype(np.float32), ref.astype(np.float32)


def _nchw(a):
    return torch.from_numpy(np.ascontiguousarray(np.moveaxis(tonemap(a), -1, 0)[None], dtype=np.float32))


def test_five_scales_is_the_library_on_the_same_input():
    pred, ref = _pair(176)
    expected = float(ms_ssim(_nchw(pred), _nchw(ref), data_range=1.0))
    assert msssim(pred, ref) == pytest.approx(expected, abs=1e-6)
    # our own scale loop, forced to five scales, is the library's combination
    assert float(ms_ssim_tensor(_nchw(pred), _nchw(ref), scales=5)) == pytest.approx(expected, abs=1e-5)


def test_one_scale_is_the_library_ssim():
    pred, ref = _pair(16)
    assert msssim_scales(16, 16) == 1
    expected = float(ssim(_nchw(pred), _nchw(ref), data_range=1.0))
    assert msssim(pred, ref) == pytest.approx(max(expected, 0.0), abs=1e-6)


def test_scale_count_for_small_images():
    assert [msssim_scales(s, s) for s in (11, 20, 21, 40, 41, 80, 81, 160, 161, 512)] == [1, 1, 2, 2, 3, 3, 4, 4, 5, 5]
    assert msssim_scales(64, 200) == 3  # the smaller side decides
    with pytest.raises(ValueError, match="at least 11"):
        msssim(*_pair(10))


def test_more_noise_scores_lower_and_identity_scores_one():
    values = [msssim(*_pair(64, s)) for s in (0.02, 0.1, 0.3)]
    assert values[0] > values[1] > values[2]
    assert msssim(_pair(64)[1], _pair(64)[1]) == pytest.approx(1.0, abs=1e-6)


def test_registered_spatial_higher_is_better_with_worst_for_nan():
    m = get_metric("msssim")
    assert (m.kind, m.higher_is_better, m.domain) == ("spatial", True, "tonemapped")
    pred, ref = _pair(32)
    pred[3, 3, 1] = np.nan
    result = compute_metrics(pred, ref, ["msssim"])["msssim"]
    assert result.value == 0.0 and result.nonfinite_count == 1
