"""OIDN's image comparison (``training/compare_image.py``), so our rows sit beside OIDN's numbers.

Intel Open Image Denoise (https://github.com/RenderKit/oidn) scores a denoised HDR image against
its reference with ``training/compare_image.py``, which prints ``psnr`` and ``ssim`` by default.
Both images go through the same transfer before scoring; the definitions below reproduce theirs,
with the file of that repository each step comes from.

HDR → display transform (``oidn_srgb``), ``training/dataset.py`` (``transform_feature(image, 'hdr',
'srgb', exposure)``) and ``training/color.py``:
  1. ``x = max(rgb, 0) · exposure``: their evaluation loads HDR images clamped at 0
     (``load_image_features``) and clamps the network's output at 0 (``infer.py``); the exposure is
     1 unless a ``<name>.json`` beside the images says otherwise (``load_image_metadata``; our
     datasets have none).
  2. Hable's filmic curve (``color.py`` ``tonemap``, "Uncharted 2"): ``f(v) = (v(Av + CB) + DE) /
     (v(Av + B) + DF) − E/F`` with A = 0.22, B = 0.30, C = 0.10, D = 0.20, E = 0.01, F = 0.30,
     evaluated at ``v = 1.758141 x`` (their exposure bias putting 18 % grey at mid grey), divided by
     ``f(W)`` for the white point W = 11.2 and clipped above at 1 (radiance ≥ 6.37 is white).
  3. the sRGB OETF (IEC 61966-2-1, ``color.py`` ``srgb_forward``): :func:`.tonemap.srgb_oetf`.

Metrics, ``training/image.py`` ``compare_images``, on the transformed N×C×H×W tensors:
* ``oidn_psnr``: ``10 log10(1 / mean((p − r)²))`` over all pixels and channels (peak 1).
* ``oidn_ssim``: ``training/ssim.py`` ``ssim(a, b, data_range=1.)``, their copy of pytorch-msssim's
  SSIM: Gaussian window 11 px, σ 1.5, valid (unpadded) filtering, K = (0.01, 0.03), the mean of the
  SSIM map per channel, then over R, G, B. Computed here with pytorch-msssim itself.
Both higher is better. Their script's other choices (``mse``, ``msssim``, asserting frames over
160 px) are not registered.

Notes
-----
* Negative radiance: ``compare_image.py`` itself loads an EXR without clamping, and its Hable curve
  is not monotone below 0 (a pole at ``x ≈ −0.138``, values below ``x ≈ −0.64`` map to near white).
  We clamp at 0 as their dataset loader and ``infer.py`` do (step 1): on non-negative images our
  numbers are those ``compare_image.py`` prints; on images with negative pixels they are those of
  their ``infer.py`` evaluation.
* Huge values: their float32 evaluation of the curve overflows ``v²`` above ``x ≈ 2e19`` and gives
  NaN (NaN PSNR and SSIM). The curve is evaluated here in float64, in the form divided by ``v²``
  above ``v = 1``, whose limit is white: any finite radiance gets a finite score.
* Identical images: their ``1. / mse.item()`` raises ZeroDivisionError; ours is +inf (as our
  other PSNRs). Non-finite predictions: their loader turns NaN into 0 (``np.nan_to_num``); ours get
  the worst value (project policy, :mod:`.validation`).
* Precision: theirs runs in float32 torch, ours in float64; measured against their own code on
  six frames (``bench/oidn_compare_pins.py``, ``tests/metrics/field/test_oidn.py``) the two differ by at
  most 3.4e-6 dB and 5.1e-6 SSIM (largest on near-white frames, where float32 variances cancel),
  below the 4 decimals their script prints.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.tonemap import srgb_oetf
from denoisebench.metrics.torch_threads import one_torch_thread
from denoisebench.metrics.validation import MetricNotApplicable, check_pair

__all__ = [
    "HABLE",
    "HABLE_SCALE",
    "HABLE_WHITE",
    "SSIM_WINDOW",
    "METRICS",
    "WORST",
    "OIDN_METRICS",
    "hable_filmic",
    "oidn_srgb",
    "oidn_psnr",
    "oidn_ssim",
]

#: Hable's curve constants (A, B, C, D, E, F) as ``color.py`` states them.
HABLE = (0.22, 0.30, 0.10, 0.20, 0.01, 0.30)
HABLE_SCALE = 1.758141  # their exposure bias: 18 % grey to mid grey
HABLE_WHITE = 11.2
SSIM_WINDOW = 11


def _hable_raw(v: np.ndarray) -> np.ndarray:
    """``f(v)`` of Hable's curve for ``v ≥ 0``, float64, without overflow for any finite ``v``.

    Up to ``v = 1`` the rational function is evaluated as written; above it, numerator and
    denominator are divided by ``v²`` (the same function, whose limit at +inf is ``1 − E/F``).
    """
    a, b, c, d, e, f = HABLE
    v = np.asarray(v, dtype=np.float64)
    small = v <= 1.0
    vs = np.where(small, v, 0.0)
    with np.errstate(divide="ignore"):
        t = np.where(small, 0.0, 1.0 / np.where(small, 1.0, v))
    direct = (vs * (a * vs + c * b) + d * e) / (vs * (a * vs + b) + d * f)
    inverse = (a + t * (c * b + t * d * e)) / (a + t * (b + t * d * f))
    return np.where(small, direct, inverse) - e / f


_WHITE_VALUE = float(_hable_raw(np.array(HABLE_WHITE)))


def hable_filmic(x: np.ndarray) -> np.ndarray:
    """OIDN's tone map (``color.py`` ``tonemap``) of non-negative linear values: in [0, 1], float64."""
    return np.minimum(_hable_raw(np.asarray(x, dtype=np.float64) * HABLE_SCALE) / _WHITE_VALUE, 1.0)


def oidn_srgb(rgb: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear HDR radiance → OIDN's display values: ``srgb_oetf(hable(max(rgb, 0) · exposure))``, [0, 1]."""
    x = np.maximum(np.asarray(rgb, dtype=np.float64), 0.0) * float(exposure)
    return srgb_oetf(hable_filmic(x))


def oidn_psnr(pred, ref, *, exposure: float = 1.0) -> float:
    """PSNR (dB, peak 1) of OIDN's sRGB-transformed images (``compare_images(..., 'psnr')``). Higher is better."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return WORST["oidn_psnr"]
    diff = oidn_srgb(c.pred, exposure) - oidn_srgb(c.ref, exposure)
    mse = float(np.mean(np.square(diff)))
    return float("inf") if mse == 0.0 else float(10.0 * np.log10(1.0 / mse))


def _nchw(a: np.ndarray):
    import torch

    return torch.from_numpy(np.ascontiguousarray(a.transpose(2, 0, 1))[None])


def oidn_ssim(pred, ref, *, exposure: float = 1.0) -> float:
    """SSIM of OIDN's sRGB-transformed images, mean over R, G, B (``compare_images(..., 'ssim')``). Higher is better.

    Frames under 11×11 px are :class:`~.validation.MetricNotApplicable` (their valid-window
    convolution has no output there).
    """
    c = check_pair(pred, ref)
    if min(c.ref.shape[:2]) < SSIM_WINDOW:
        raise MetricNotApplicable(
            f"OIDN SSIM needs images of at least {SSIM_WINDOW}×{SSIM_WINDOW} px, got {c.ref.shape[0]}×{c.ref.shape[1]}"
        )
    if c.nonfinite_count:
        return WORST["oidn_ssim"]
    import torch
    from pytorch_msssim import ssim

    p, r = _nchw(oidn_srgb(c.pred, exposure)), _nchw(oidn_srgb(c.ref, exposure))
    with one_torch_thread(), torch.no_grad():
        return float(ssim(p, r, data_range=1.0, win_size=SSIM_WINDOW, win_sigma=1.5, size_average=True))


# --------------------------------------------------------------------------- entries

METRICS: tuple[Metric, ...] = (
    Metric(
        name="oidn_psnr",
        fn=oidn_psnr,
        higher_is_better=True,
        domain="oidn",
        kind="spatial",
        worst=0.0,  # transformed values lie in [0, 1]: MSE ≤ 1
        perfect=math.inf,
        description="OIDN compare_image.py PSNR: Hable filmic + sRGB of max(x, 0), peak 1",
        unit="dB",
    ),
    Metric(
        name="oidn_ssim",
        fn=oidn_ssim,
        higher_is_better=True,
        domain="oidn",
        kind="spatial",
        worst=-1.0,
        perfect=1.0,
        description=(
            "OIDN compare_image.py SSIM (win 11, sigma 1.5, data_range 1) of the Hable + sRGB images, mean of R, G, B"
        ),
    ),
)

#: Worst value of each metric, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
#: The set ``--metrics oidn`` selects: the two scores ``compare_image.py`` prints by default.
OIDN_METRICS: tuple[str, ...] = tuple(m.name for m in METRICS)
