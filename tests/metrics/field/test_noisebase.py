"""Noisebase's metric set: each definition recomputed here independently (numpy, scikit-image).

The expected values below are computed from the published definitions
(github.com/balintio/noisebase: data.py ACES, loaders/torch/test_sample_v1.py Sequence.save,
scripts/nb_compute_metrics.py) written out again in numpy, not by calling the module under test;
the last tests run the ``noisebase`` package's own code on the same frames.
"""

import math

import numpy as np
import pytest
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from denoisebench.benchmark.runner import split_metrics
from denoisebench.metrics import compute_metrics, get_metric
from denoisebench.metrics.field import noisebase as nb
from denoisebench.metrics.registry import default_metric_names, expand_metric_names


def _hand_encode(rgb):
    """Their ACES (BakingLab fit), gamma 1/2.2, ``(x*255).astype(uint8) / 255``."""
    m_in = np.array([[0.59719, 0.35458, 0.04823], [0.07600, 0.90834, 0.01566], [0.02840, 0.13383, 0.83777]])
    m_out = np.array([[1.60475, -0.53108, -0.07367], [-0.10208, 1.10813, -0.00605], [-0.00327, -0.07276, 1.07602]])
    x = np.einsum("ji,...i->...j", m_in, np.asarray(rgb, dtype=np.float64))
    x = (x * (x + 0.0245786) - 0.000090537) / (x * (0.983729 * x + 0.4329510) + 0.238081)
    x = np.einsum("ji,...i->...j", m_out, x)
    return (np.power(np.clip(x, 0, 1), 1 / 2.2) * 255).astype(np.uint8) / 255.0


def _hand_lum(e):
    e = np.power(e, 2.2)
    return 0.2126 * e[..., 0] + 0.7152 * e[..., 1] + 0.0722 * e[..., 2]


def _scene(t=3, size=48, sigma=0.08, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    base = np.stack([0.6 + 0.5 * np.sin(6 * x), 0.5 + 0.4 * np.cos(4 * y), 0.3 + 0.3 * x], -1)
    ref = np.stack([base * (1 + 0.05 * k) for k in range(t)])
    pred = np.clip(ref + sigma * rng.standard_normal(ref.shape), 0, None)
    return pred.astype(np.float32), ref.astype(np.float32)


def test_encoding_pinned_levels():
    # 8-bit levels of grey radiance computed by hand from their formula (truncation, not rounding)
    grey = np.array([[[0.0] * 3, [0.18] * 3, [1.0] * 3, [100.0] * 3]])
    levels = np.round(nb.nb_encode(grey)[0, :, 0] * 255).astype(int).tolist()
    assert levels == np.round(_hand_encode(grey)[0, :, 0] * 255).astype(int).tolist()
    # by hand: 0.18 -> fit 0.105591 -> ^(1/2.2) 0.35993 -> 91.78 -> 91 (truncated); 1.0 -> 0.619113
    # -> 0.80418 -> 205.07 -> 205; 100 -> fit above 1 -> clipped -> 255 (the matrices' rows sum to 1)
    assert levels == [0, 91, 205, 255]


def test_psnr_matches_scikit_image_on_encoded_frames():
    pred, ref = _scene(t=1)
    expected = peak_signal_noise_ratio(_hand_encode(ref[0]), _hand_encode(pred[0]), data_range=1.0)
    assert nb.nb_psnr(pred[0], ref[0]) == pytest.approx(expected, abs=1e-4)
    assert nb.nb_psnr(ref[0], ref[0]) == math.inf


def test_ssim_is_luminance_ssim_as_scikit_image_computes_it():
    pred, ref = _scene(t=1)
    expected = structural_similarity(
        _hand_lum(_hand_encode(pred[0])),
        _hand_lum(_hand_encode(ref[0])),
        data_range=1.0,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
    )
    assert nb.nb_ssim(pred[0], ref[0]) == pytest.approx(expected, abs=2e-4)


def test_msssim_small_image_is_their_luminance_with_fewer_scales():
    pred, ref = _scene(t=1)  # 48 px: 3 scales; one scale below 21 px equals nb_ssim's luminance SSIM
    assert 0.0 < nb.nb_msssim(pred[0], ref[0]) < 1.0
    small_p, small_r = pred[0, :16, :16], ref[0, :16, :16]
    assert nb.nb_msssim(small_p, small_r) == pytest.approx(max(nb.nb_ssim(small_p, small_r), 0.0), abs=1e-6)


def test_temporal_metrics_on_frame_differences_by_hand():
    pred, ref = _scene(t=3)
    p, r = _hand_encode(pred), _hand_encode(ref)
    dp, dr = np.diff(p, axis=0), np.diff(r, axis=0)
    tpsnr = np.mean([10 * np.log10(1 / np.mean((a - b) ** 2)) for a, b in zip(dp, dr)])
    trmae = np.mean([np.mean(np.abs(a - b) / (np.abs(b) + 0.01)) / 3 for a, b in zip(dp, dr)])
    assert nb.nb_tpsnr(pred, ref) == pytest.approx(tpsnr, abs=1e-4)
    assert nb.nb_trmae(pred, ref) == pytest.approx(trmae, rel=1e-5)
    # a constant offset in every frame leaves frame differences (almost: 8-bit steps) unchanged
    assert nb.nb_trmae(ref, ref) == 0.0 and nb.nb_tpsnr(ref, ref) == math.inf


def test_flip_ldr_at_their_ppd():
    pred, ref = _scene(t=1)
    assert nb.FLIP_PPD == pytest.approx(67.0206, abs=1e-4)
    assert nb.nb_flip(ref[0], ref[0]) == 0.0
    noisier = _scene(t=1, sigma=0.3)[0]
    assert 0.0 < nb.nb_flip(pred[0], ref[0]) < nb.nb_flip(noisier[0], ref[0]) < 1.0


def test_nan_prediction_gets_worst_values():
    pred, ref = _scene(t=2)
    pred[1, 2, 2, 0] = np.inf
    results = compute_metrics(pred, ref, ["noisebase"])
    for name, result in results.items():
        assert result.value == get_metric(name).worst, name


def test_metric_set_is_opt_in_and_selected_by_name():
    assert expand_metric_names(["noisebase"]) == list(nb.NOISEBASE_METRICS)
    assert not set(nb.NOISEBASE_METRICS) & set(default_metric_names())
    spatial, temporal = split_metrics(["noisebase"])
    assert {"nb_psnr", "nb_ssim", "nb_msssim", "nb_flip"} <= set(spatial)
    assert temporal[:2] == ["nb_tpsnr", "nb_trmae"]  # then the always-computed ones
    with pytest.raises(ValueError, match="sets: noisebase"):
        expand_metric_names(["noisebase2"])


def test_msssim_at_their_size_is_pytorch_msssim_on_the_hand_luminance():
    import torch
    from pytorch_msssim import ms_ssim

    pred, ref = _scene(t=1, size=176)  # ≥ 161 px: the library's five scales, as on their 1920×1024 frames

    def lum(a):
        return torch.from_numpy(_hand_lum(_hand_encode(a)).astype(np.float32)[None, None])

    expected = float(ms_ssim(lum(pred[0]), lum(ref[0]), data_range=1.0))
    assert nb.nb_msssim(pred[0], ref[0]) == pytest.approx(expected, abs=1e-5)


# --------------------------------------------------------------------------- Noisebase's own code
# The checks above restate Noisebase's definitions; these run the `noisebase` package's own code
# (1.1.1, installed --no-deps) on the same frames: Sequence.save writes their 8-bit PNGs, and
# scripts/nb_compute_metrics.py scores them. That script imports pyfvvdp (FovVideoVDP) at the top,
# whose 1.2.0 release imports numpy.lib.shape_base (gone in numpy 2): the two FovVideoVDP modules
# are replaced by empty ones for the import; nothing compared here uses them.


@pytest.fixture(scope="module")
def noisebase_scripts():
    import importlib
    import sys
    import types

    pytest.importorskip("noisebase.loaders.torch")
    stubs = {"pyfvvdp": types.ModuleType("pyfvvdp"), "pyfvvdp.fvvdp": types.ModuleType("pyfvvdp.fvvdp")}
    stubs["pyfvvdp.fvvdp"].reshuffle_dims = None
    stubs["noisebase.metrics.fvvdp"] = types.ModuleType("noisebase.metrics.fvvdp")
    stubs["noisebase.metrics.fvvdp"].nb_fvvdp = None
    saved = {name: sys.modules.get(name) for name in [*stubs, "noisebase.scripts.nb_compute_metrics"]}
    sys.modules.update(stubs)
    try:
        module = importlib.import_module("noisebase.scripts.nb_compute_metrics")
    finally:
        for name, old in saved.items():
            if name == "noisebase.scripts.nb_compute_metrics":
                continue
            if old is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = old
    return module


def _their_frames(tmp_path, name, frames):
    """Linear T×H×W×3 frames -> Noisebase's saved PNGs (their Sequence.save) read back as their
    metric script reads them (imageio, then HWC -> NCHW float32 / 255)."""
    import imageio.v3 as iio
    import torch
    from noisebase.loaders.torch.test_sample_v1 import Sequence

    output = "{sequence_name}/frame{index:04d}.png"
    sequence = Sequence(src={}, sequence={"name": name}, save_dir=str(tmp_path), output=output)
    for i, frame in enumerate(frames):
        sequence.save(i, torch.from_numpy(np.ascontiguousarray(frame.transpose(2, 0, 1)))[None])
    sequence.join()
    read = [iio.imread(tmp_path / output.format(sequence_name=name, index=i)) for i in range(len(frames))]
    return [torch.from_numpy(r).permute(2, 0, 1)[None].to(torch.float32) / 255 for r in read]


def test_scores_equal_noisebase_metric_script(noisebase_scripts, tmp_path):
    nbm = noisebase_scripts
    pred, ref = _scene(t=3, size=176, sigma=0.1)  # 176 px: pytorch_msssim's five scales, as theirs
    tp, tr = _their_frames(tmp_path, "pred", pred), _their_frames(tmp_path, "ref", ref)
    # their 8-bit frames are ours
    for ours, theirs in zip(pred, tp):
        np.testing.assert_array_equal(nb.nb_encode(ours), theirs[0].permute(1, 2, 0).numpy())
    for i in range(3):
        # measured: |Δ| ≤ 2.1e-7 dB (PSNR), ≤ 1e-7 (SSIM, MS-SSIM): float32 torch against float64 numpy
        assert nb.nb_psnr(pred[i], ref[i]) == pytest.approx(nbm.psnr(tp[i], tr[i]), abs=1e-5)
        assert nb.nb_ssim(pred[i], ref[i]) == pytest.approx(nbm.ssim(tp[i], tr[i]), abs=1e-6)
        assert nb.nb_msssim(pred[i], ref[i]) == pytest.approx(nbm.msssim(tp[i], tr[i]), abs=1e-6)
    tpsnr, trmae = nbm.TemporalMetricAdapter(nbm.psnr), nbm.TemporalMetricAdapter(nbm.rmae)
    for a, b in zip(tp, tr):
        tpsnr.feed(a, b)
        trmae.feed(a, b)
    assert nb.nb_tpsnr(pred, ref) == pytest.approx(tpsnr.compute(), abs=1e-5)
    assert nb.nb_trmae(pred, ref) == pytest.approx(trmae.compute(), rel=1e-5)


class _CpuTorch:
    """``torch`` for Noisebase's FLIP module with its hard-wired ``device='cuda'`` dropped."""

    def __init__(self, torch):
        self._torch = torch

    def zeros(self, *args, device=None, **kwargs):
        return self._torch.zeros(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._torch, name)


def test_flip_equals_noisebase_flip_run_on_the_cpu(tmp_path, monkeypatch):
    """Their LDR-FLIP (noisebase/metrics/flip.py, PyTorch) against ours (flip-evaluator, C++)."""
    import torch

    pytest.importorskip("noisebase.loaders.torch")
    from noisebase.metrics import flip as their_flip

    monkeypatch.setattr(torch.Tensor, "cuda", lambda self, *a, **k: self)
    monkeypatch.setattr(their_flip, "torch", _CpuTorch(torch))
    pred, ref = _scene(t=1, size=64, sigma=0.1)
    tp, tr = _their_frames(tmp_path, "pred", pred), _their_frames(tmp_path, "ref", ref)
    with torch.no_grad():
        theirs = their_flip.flip(tp[0], tr[0])
    # measured: 0.1278116 (ours) against 0.1278115 (theirs), relative 2e-7
    assert nb.nb_flip(pred[0], ref[0]) == pytest.approx(theirs, rel=1e-5)
