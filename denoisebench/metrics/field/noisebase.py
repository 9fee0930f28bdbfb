"""Noisebase's metric definitions ("Path Tracing Denoising v1"), so our rows sit beside theirs.

Noisebase (Balint et al., https://github.com/balintio/noisebase, benchmark page
``docs/benchmarks/rendering_v1.md``) scores a method's outputs *as saved 8-bit images*: every
definition below reproduces theirs, with its source file in that repository.

Frame encoding (``nb_encode``), ``noisebase/loaders/torch/test_sample_v1.py`` (``Sequence.save``)
and ``noisebase/data.py`` (``ACES``):
  1. ACES filmic tone map, the BakingLab fit of the RRT+ODT: ``v = M_in · rgb``;
     ``v' = (v (v + 0.0245786) − 0.000090537) / (v (0.983729 v + 0.4329510) + 0.238081)``;
     ``rgb' = M_out · v'`` with their 3×3 matrices (``ACES_INPUT``, ``ACES_OUTPUT`` here). No
     exposure: radiance is used as rendered.
  2. clip to [0, 1], gamma ``1/2.2`` (a pure power, not the sRGB curve);
  3. 8-bit by **truncation**, ``(x · 255).astype(uint8)`` (not rounding), read back as
     ``uint8 / 255`` in float32 (``nb_compute_metrics.np_to_torch``).
Both prediction and reference go through the same encoding (their reference PNGs are saved by
the same ``Sequence.save``). Negative or NaN prediction values: NaN/Inf give the worst value
(project policy); negatives are clipped by step 2 as in theirs.

Metrics, ``noisebase/scripts/nb_compute_metrics.py``; per frame, then the mean over frames:
* ``nb_psnr``: ``10 log10(1 / mean((p − r)²))`` over all pixels and channels of the encoded
  frames (peak 1). Identical frames: +inf (theirs would divide by zero).
* ``nb_ssim``: ``pytorch_msssim.ssim`` (Gaussian window 11, σ 1.5, K = (0.01, 0.03),
  data_range 1) of the *luminance* ``0.2126 R^2.2 + 0.7152 G^2.2 + 0.0722 B^2.2`` of the encoded
  frames (``srgb_to_lum``).
* ``nb_msssim``: ``pytorch_msssim.ms_ssim`` of the same luminance. Their frames are 1920×1024;
  below 161 px we use fewer scales exactly as :mod:`.msssim` does (then not comparable).
* ``nb_flip``: LDR-FLIP of the encoded frames read as sRGB at 67.02 pixels per degree
  (``(0.7 · 3840 / 0.7) · π / 180``, ``noisebase/metrics/flip.py``); computed with
  flip-evaluator (``evaluate(ref, test, "LDR", parameters={"ppd": ...})``), NVIDIA's package of
  the same FLIP whose PyTorch version Noisebase vendors.
Temporal metrics, ``TemporalMetricAdapter``: a spatial metric applied to the frame
*differences* of the encoded frames, ``m(p_t − p_{t−1}, r_t − r_{t−1})``, mean over t = 1..T−1:
* ``nb_tpsnr``: ``nb_psnr`` of the differences (their ``tpsnr``).
* ``nb_trmae``: ``mean(|Δp − Δr| / (|Δr| + 0.01)) / 3`` (their ``rmae`` keeps its ``/ 3``, though
  the mean already covers the channels; reproduced as published).
Not reproduced: their ``fvvdp`` (FovVideoVDP, package ``pyfvvdp``): we carry its successor
ColorVideoVDP as ``cvvdp`` (:mod:`.colorvideovdp`), whose JOD values are not the same scale.
Their warm-up (the first frames of a sequence excluded) is a property of their test set; we
score the frames given.

Checked against Noisebase's own code (``noisebase`` 1.1.1, tests/metrics/field/test_noisebase.py): their
``Sequence.save`` PNGs equal :func:`nb_encode` exactly, and their script's ``psnr``, ``ssim``,
``msssim``, ``tpsnr``, ``trmae`` and their PyTorch LDR-FLIP (run on the CPU) give our values to
2e-7 (dB, or relative for FLIP).
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.metrics.field.msssim import ms_ssim_tensor
from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.torch_threads import one_torch_thread
from denoisebench.metrics.validation import MetricNotApplicable, check_pair, check_sequences

# Lazy imports: torch (1 s), pytorch-msssim and flip-evaluator are imported when a Noisebase
# score is computed, so that the metric registry stays cheap to import.

__all__ = [
    "ACES_INPUT",
    "ACES_OUTPUT",
    "FLIP_PPD",
    "METRICS",
    "WORST",
    "nb_aces",
    "nb_encode",
    "nb_luminance",
    "nb_psnr",
    "nb_ssim",
    "nb_msssim",
    "nb_flip",
    "nb_tpsnr",
    "nb_trmae",
    "NOISEBASE_METRICS",
]

ACES_INPUT = np.array(
    [
        [0.59719, 0.35458, 0.04823],
        [0.07600, 0.90834, 0.01566],
        [0.02840, 0.13383, 0.83777],
    ]
)
ACES_OUTPUT = np.array(
    [
        [1.60475, -0.53108, -0.07367],
        [-0.10208, 1.10813, -0.00605],
        [-0.00327, -0.07276, 1.07602],
    ]
)
GAMMA = 2.2
FLIP_PPD = (0.7 * 3840 / 0.7) * math.pi / 180
RMAE_EPS = 0.01


def nb_aces(rgb: np.ndarray) -> np.ndarray:
    """Their ACES fit (steps 1–2 of the module Notes), float64 in [0, 1], gamma-encoded."""
    x = np.asarray(rgb, dtype=np.float64) @ ACES_INPUT.T
    x = (x * (x + 0.0245786) - 0.000090537) / (x * (0.983729 * x + 0.4329510) + 0.238081)
    x = x @ ACES_OUTPUT.T
    return np.power(np.clip(x, 0.0, 1.0), 1.0 / GAMMA)


def nb_encode(rgb: np.ndarray) -> np.ndarray:
    """Linear radiance (…×3) → their saved 8-bit frame read back: ``trunc(255·ACES) / 255``, float32."""
    return (nb_aces(rgb) * 255).astype(np.uint8).astype(np.float32) / np.float32(255)


def nb_luminance(encoded: np.ndarray) -> np.ndarray:
    """Their ``srgb_to_lum``: ``0.2126 R^2.2 + 0.7152 G^2.2 + 0.0722 B^2.2`` of encoded values, float32."""
    e = np.power(np.asarray(encoded, dtype=np.float32), np.float32(2.2))
    return np.float32(0.2126) * e[..., 0] + np.float32(0.7152) * e[..., 1] + np.float32(0.0722) * e[..., 2]


def _psnr(p: np.ndarray, r: np.ndarray) -> float:
    mse = float(np.mean(np.square(p.astype(np.float64) - r.astype(np.float64))))
    return math.inf if mse == 0.0 else 10.0 * math.log10(1.0 / mse)


def _gray_tensor(y: np.ndarray):
    import torch

    return torch.from_numpy(np.ascontiguousarray(y, dtype=np.float32)[None, None])


def nb_psnr(pred, ref) -> float:
    """PSNR (dB) of the 8-bit ACES-encoded frames, peak 1. Higher is better."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return WORST["nb_psnr"]
    return _psnr(nb_encode(c.pred), nb_encode(c.ref))


def _luminance_pair(pred, ref, what: str):
    """Gray N×C×H×W tensors of the encoded frames' luminance, or None when ``pred`` is not finite.

    A ValueError for frames under 11×11 px (the SSIM window).
    """
    c = check_pair(pred, ref)
    if min(c.ref.shape[:2]) < 11:
        raise MetricNotApplicable(f"{what} needs images of at least 11×11 px, got {c.ref.shape[0]}×{c.ref.shape[1]}")
    if c.nonfinite_count:
        return None
    return _gray_tensor(nb_luminance(nb_encode(c.pred))), _gray_tensor(nb_luminance(nb_encode(c.ref)))


def nb_ssim(pred, ref) -> float:
    """pytorch-msssim SSIM of the encoded frames' luminance (their ``ssim``). Higher is better."""
    pair = _luminance_pair(pred, ref, "SSIM")
    if pair is None:
        return WORST["nb_ssim"]
    import torch
    from pytorch_msssim import ssim

    with one_torch_thread(), torch.no_grad():
        return float(ssim(*pair, data_range=1.0))


def nb_msssim(pred, ref) -> float:
    """pytorch-msssim MS-SSIM of the encoded frames' luminance (their ``msssim``). Higher is better."""
    pair = _luminance_pair(pred, ref, "MS-SSIM")
    if pair is None:
        return WORST["nb_msssim"]
    import torch

    with one_torch_thread(), torch.no_grad():
        return float(ms_ssim_tensor(*pair))


def nb_flip(pred, ref) -> float:
    """LDR-FLIP (flip-evaluator, 67.02 ppd) of the encoded frames read as sRGB. Lower is better."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return WORST["nb_flip"]
    import flip_evaluator

    error_map, _, _ = flip_evaluator.evaluate(
        np.ascontiguousarray(nb_encode(c.ref)),
        np.ascontiguousarray(nb_encode(c.pred)),
        "LDR",
        inputsRGB=True,
        applyMagma=False,
        computeMeanError=False,
        parameters={"ppd": FLIP_PPD},
    )
    return float(np.mean(error_map, dtype=np.float64))


def _differences(pred_seq, ref_seq):
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    if c.nonfinite_count:
        return None
    p = nb_encode(c.pred)
    r = nb_encode(c.ref)
    return np.diff(p, axis=0), np.diff(r, axis=0)


def nb_tpsnr(pred_seq, ref_seq) -> float:
    """Mean over frame pairs of the PSNR of encoded frame differences (their ``tpsnr``). Higher is better.

    A pair with identical differences scores +inf, and so does the mean.
    """
    d = _differences(pred_seq, ref_seq)
    if d is None:
        return WORST["nb_tpsnr"]
    return float(np.mean([_psnr(dp, dr) for dp, dr in zip(*d)]))


def nb_trmae(pred_seq, ref_seq) -> float:
    """Mean over frame pairs of ``mean(|Δp − Δr| / (|Δr| + 0.01)) / 3`` (their ``trmae``). Lower is better."""
    d = _differences(pred_seq, ref_seq)
    if d is None:
        return WORST["nb_trmae"]
    values = [
        float(np.mean(np.abs(dp.astype(np.float64) - dr) / (np.abs(dr.astype(np.float64)) + RMAE_EPS))) / 3.0
        for dp, dr in zip(*d)
    ]
    return float(np.mean(values))


# --------------------------------------------------------------------------- entries

METRICS: tuple[Metric, ...] = (
    Metric(
        name="nb_psnr",
        fn=nb_psnr,
        higher_is_better=True,
        domain="noisebase",
        kind="spatial",
        worst=0.0,  # encoded values lie in [0, 1]: MSE ≤ 1
        perfect=math.inf,
        description="Noisebase PSNR: 8-bit ACES (gamma 2.2, truncated) frames, peak 1",
        unit="dB",
    ),
    Metric(
        name="nb_ssim",
        fn=nb_ssim,
        higher_is_better=True,
        domain="noisebase",
        kind="spatial",
        worst=-1.0,
        perfect=1.0,
        description="Noisebase SSIM (pytorch-msssim) of the 8-bit frames' luminance",
    ),
    Metric(
        name="nb_msssim",
        fn=nb_msssim,
        higher_is_better=True,
        domain="noisebase",
        kind="spatial",
        worst=0.0,
        perfect=1.0,
        description="Noisebase MS-SSIM (pytorch-msssim) of the 8-bit frames' luminance",
    ),
    Metric(
        name="nb_flip",
        fn=nb_flip,
        higher_is_better=False,
        domain="noisebase",
        kind="spatial",
        worst=1.0,
        perfect=0.0,
        description="Noisebase LDR-FLIP of the 8-bit frames at 67.02 ppd",
    ),
    Metric(
        name="nb_tpsnr",
        fn=nb_tpsnr,
        higher_is_better=True,
        domain="noisebase",
        kind="temporal",
        worst=20.0 * math.log10(0.5),  # differences lie in [−1, 1]: MSE ≤ 4
        perfect=math.inf,
        description="Noisebase tPSNR: mean over pairs of PSNR of 8-bit frame differences",
        unit="dB",
    ),
    Metric(
        name="nb_trmae",
        fn=nb_trmae,
        higher_is_better=False,
        domain="noisebase",
        kind="temporal",
        worst=math.inf,
        perfect=0.0,
        description="Noisebase tRMAE: mean over pairs of mean(|dp-dr|/(|dr|+0.01))/3 of 8-bit frames",
    ),
)

#: Worst value of each metric, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
#: The set ``--metrics noisebase`` selects, in their table's order.
NOISEBASE_METRICS: tuple[str, ...] = tuple(m.name for m in METRICS)
