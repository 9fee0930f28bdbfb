"""ColorVideoVDP (cvvdp) as a registered temporal metric: what the model predicts, and the install.

Pinned predictions were measured here with cvvdp 0.5.7 through ``metrics.colorvideovdp.cvvdp``
(32×32 textured static reference, 8 frames, 30 fps, standard_hdr_linear display, the reference's
log-average luminance shown at 100 cd/m²): ±15 % alternating brightness 5.23 JOD, static +15 %
10.00, dynamic Gaussian noise σ 0.03 → 9.86, σ 0.1 → 9.22, static noise σ 0.1 → 9.08 (64×64:
5.23 / 10.00 / 9.91 / 9.28 / 9.11). The issue measured 7.0 / 10.0 / 9.9 / 9.0 / 8.4 with a
plain ×100 cd/m² scale; the tests hold the orderings and the size of the flicker penalty, with
margins, not the digits.
"""

import importlib.metadata
import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from denoisebench.metrics import compute_metrics, get_metric
from denoisebench.metrics.colorvideovdp import cvvdp, exposure_from_reference

ROOT = Path(__file__).resolve().parent.parent
T, H, W = 8, 32, 32


@pytest.fixture(scope="module")
def ref():
    y, x = np.mgrid[0:H, 0:W]
    base = 0.5 + 0.4 * np.sin(x / 3.0) * np.cos(y / 5.0)
    return np.repeat(np.repeat(base[None, :, :, None], 3, axis=3), T, axis=0).astype(np.float32)


def test_flicker_scores_far_below_the_same_change_held_static(ref):
    gain = np.where(np.arange(T) % 2 == 0, 1.15, 0.85)[:, None, None, None]
    flicker = cvvdp((ref * gain).astype(np.float32), ref)
    static = cvvdp((ref * 1.15).astype(np.float32), ref)
    assert static >= 9.9  # a steady global gain is nearly invisible (contrast constancy)
    assert 4.5 <= flicker <= 6.0  # measured 5.23
    assert static - flicker >= 2.5


def test_more_noise_scores_lower_and_static_noise_lower_than_dynamic(ref):
    rng = np.random.default_rng(0)
    dyn = {
        s: cvvdp(np.clip(ref + s * rng.standard_normal(ref.shape), 0, None).astype(np.float32), ref)
        for s in (0.03, 0.1)
    }
    still = cvvdp(np.clip(ref + 0.1 * rng.standard_normal(ref.shape[1:]), 0, None).astype(np.float32), ref)
    assert 10.0 > dyn[0.03] > dyn[0.1] > still  # measured 9.86 > 9.22 > 9.08
    assert dyn[0.03] - dyn[0.1] >= 0.3


def test_identical_is_ten_nan_is_worst_and_scale_invariant(ref):
    threads = torch.get_num_threads()
    assert cvvdp(ref, ref) == pytest.approx(10.0, abs=1e-4)
    assert torch.get_num_threads() == threads  # one thread inside the call, restored after
    rng = np.random.default_rng(1)
    pred = np.clip(ref + 0.1 * rng.standard_normal(ref.shape), 0, None).astype(np.float32)
    # exposure comes from the reference: the same scene 7x brighter scores the same
    assert cvvdp(pred * 7, ref * 7) == pytest.approx(cvvdp(pred, ref), abs=2e-3)
    pred[3, 1, 1, 2] = np.nan
    result = compute_metrics(pred, ref, ["cvvdp"])["cvvdp"]
    assert result.value == -math.inf and result.nonfinite_count == 1


def test_exposure_is_the_reference_key_at_100_nits():
    flat = np.full((2, 4, 4, 3), 0.5)
    assert exposure_from_reference(flat) == pytest.approx(200.0)
    assert exposure_from_reference(np.zeros((2, 4, 4, 3))) == 100.0
    half_black = flat.copy()
    half_black[:, :2] = 0.0  # black floored at 1/1000 of the mean (0.25): key = sqrt(0.5 * 0.00025)
    assert exposure_from_reference(half_black) == pytest.approx(100.0 / math.sqrt(0.5 * 0.00025), rel=1e-9)


def test_registered_as_temporal_jod_higher_is_better():
    m = get_metric("cvvdp")
    assert (m.kind, m.higher_is_better, m.unit, m.perfect) == ("temporal", True, "JOD", 10.0)
    with pytest.raises(ValueError, match="at least 2 frames"):
        cvvdp(np.ones((1, 16, 16, 3)), np.ones((1, 16, 16, 3)))


def test_install_keeps_torch_and_pins_what_make_setup_installs():
    assert torch.__version__.split("+")[0] == "2.13.0"
    nodeps = (ROOT / "requirements-nodeps.txt").read_text()
    pin = re.search(r"^cvvdp==(\S+)$", nodeps, re.M)
    assert pin and importlib.metadata.version("cvvdp") == pin.group(1)
    reqs = (ROOT / "requirements.txt").read_text()
    for name in ("torchvision", "pytorch-msssim", "einops", "ffmpeg-python", "huggingface_hub"):
        line = re.search(rf"^{re.escape(name)}==(\S+)$", reqs, re.M)
        assert line, name
        assert importlib.metadata.version(name) == line.group(1), name
    makefile = (ROOT / "Makefile").read_text()
    assert "--no-deps -r requirements-nodeps.txt" in makefile
    assert re.search(r"^\$\(STAMP\):.*requirements-nodeps\.txt", makefile, re.M)


def test_hard_cases_are_finite_and_quiet(caplog):
    black = np.zeros((3, 16, 16, 3), np.float32)
    firefly = black.copy()
    firefly[1, 5, 5] = 1e4
    rng = np.random.default_rng(2)
    ref = rng.random((3, 16, 16, 3)).astype(np.float32)
    huge = ref.copy()
    huge[0, 0, 0] = 3e38  # near float32's maximum: scaled in float64, then capped
    with caplog.at_level("WARNING"):
        assert cvvdp(black, black) == pytest.approx(10.0, abs=1e-4)
        values = [cvvdp(firefly, black), cvvdp(huge, ref), cvvdp(ref - 0.5, ref)]
    assert all(math.isfinite(v) and v < 10.0 for v in values)
    assert not [r for r in caplog.records if r.levelname == "WARNING"]


def test_torchvision_compiled_ops_still_fail_loudly():
    from denoisebench.metrics.colorvideovdp import load_pycvvdp

    load_pycvvdp()
    import torchvision

    if torchvision.extension._has_ops():
        pytest.skip("torchvision's compiled operators load here: nothing was declared")
    with pytest.raises(RuntimeError):
        torchvision.ops.nms(torch.zeros(1, 4), torch.zeros(1), 0.5)
