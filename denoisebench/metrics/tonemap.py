"""The one tone map of the tone-mapped metrics (PSNR, SSIM, tPSNR) and of ΔE2000.

``tonemap(x) = srgb_oetf(reinhard(x))`` with

1. ``reinhard(x) = c / (1 + c)`` per channel, where ``c = max(x, 0)`` (negatives clamp to 0,
   ``+inf`` maps to 1): linear display values in [0, 1);
2. ``srgb_oetf`` the IEC 61966-2-1 sRGB encoding (12.92·y below 0.0031308, else
   1.055·y^(1/2.4) − 0.055): display-encoded values in [0, 1).

Notes
-----
* Per-channel Reinhard is exposure-free: radiance 1 maps to 0.5 before encoding. It desaturates
  bright colours; that is the price of one fixed, documented map that needs no per-image statistic
  (an exposure chosen from the reference would make two predictions' scores depend on each other).
* ΔE2000 uses the *linear* stage, ``reinhard(x)``, as linear sRGB (no OETF and no decoding): see
  :func:`denoisebench.metrics.ours.spatial.deltae2000`.
* NaN propagates; the metrics never pass non-finite predictions here (see ``validation``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["reinhard", "srgb_oetf", "tonemap", "TONEMAP_DESCRIPTION"]

TONEMAP_DESCRIPTION = "clamp negatives to 0, Reinhard c/(1+c) per channel, then the sRGB OETF; output in [0, 1)"


def reinhard(x: np.ndarray) -> np.ndarray:
    """Per-channel Reinhard ``c/(1+c)`` of ``c = max(x, 0)``, float64, in [0, 1] (1 only for +inf)."""
    x = np.asarray(x)
    c = np.maximum(x, 0.0, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        np.divide(c, c + 1.0, out=c)
    if np.isnan(c.sum()):  # +inf / +inf (a NaN input stays NaN)
        c[np.isposinf(x)] = 1.0
    return c


def srgb_oetf(y: np.ndarray) -> np.ndarray:
    """sRGB encoding of linear values in [0, 1] (IEC 61966-2-1), float64.

    The power is computed as ``exp(log(y) / 2.4)`` (within 1 ulp of ``y ** (1/2.4)``, faster).
    """
    y = np.asarray(y, dtype=np.float64)
    out = np.maximum(y, 0.0031308)
    np.log(out, out=out)
    out *= 1.0 / 2.4
    np.exp(out, out=out)
    out *= 1.055
    out -= 0.055
    np.multiply(y, 12.92, out=out, where=y <= 0.0031308)
    return out


def tonemap(x: np.ndarray) -> np.ndarray:
    """Linear HDR radiance → display-encoded [0, 1): ``srgb_oetf(reinhard(x))``."""
    return srgb_oetf(reinhard(x))
