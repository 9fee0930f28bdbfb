"""Reference-noise floors of the MSE-family scores: how much of a score is the reference's own noise.

A reference rendered at finite spp is ``r = R + n``: the noise-free image ``R`` plus zero-mean noise
``n`` of per-pixel variance ``v`` (the reference file's ``color_var``, the variance of the pixel
mean). Every squared-error score of a prediction ``p`` against ``r`` then carries ``v``:

    E_n[(p − r)²] = (p − R)² + v        (p independent of the reference's noise)

so a perfect denoiser (``p = R``) scores ``mean(v)`` instead of 0. That expected score of a
perfect denoiser is the **floor**; ``score − floor`` (the **corrected** score) is an unbiased
estimate of the error against the noise-free image.

Functions return a :class:`Floor`: ``floor`` and ``se``, the standard error of the score that the
reference's noise causes (the reference's uncertainty, used to widen bootstrap intervals and to
tell when two denoisers cannot be told apart at this reference quality).

Notes
-----
* **mse**: floor = mean(v), exact (unbiased for any p that does not depend on the reference noise).
* **relmse** = mean((p − r)²/(r² + 0.01)): the reference enters the denominator too, so the
  noise's share of the score depends a little on the prediction. With D = R² + 0.01 and
  e = p − R, expanding 1/((R + n)² + 0.01) to second order in n gives

      E_n[(e − n)²/((R + n)² + 0.01)] ≈ (e² + v)/D + v·e²(4R² − D)/D³ + 4v·e·R/D²

  The floor is the estimate of everything but e²/D, from the observed d = p − r and r
  (E[d²] = e² + v, E[d·r] = e·R − v): mean(v/Dr + v·d²(4r² − Dr)/Dr³ + 4v(d·r + v)/Dr²
  − v²(13r² + 0.01)/Dr³), Dr = r² + 0.01; the last term removes the v² part that the plug-in
  terms themselves add in expectation (checked against Gauss–Hermite quadrature: the estimate is
  within 0.5 % of the true noise share for 5 % reference noise and |e| ≤ 10 % of R).
  The expansion diverges where the reference's noise is comparable to its value (fireflies in a
  glossy scene's reference): values with v > 0.1·(r² + 0.01) (:data:`SECOND_ORDER_LIMIT`) get
  the first-order term alone. Measured on the demo's glossy_fireflies reference, 4.7 % of the
  values are beyond it, and summing the second-order terms there too made OIDN's floor negative
  (−0.073 against a first-order 0.019); with the limit it is 0.018. Such a reference's relMSE
  floor is approximate and low: with 5 % of the values at 70 % relative noise the floor was 0.195
  where the true noise share was 0.36 (300 draws, tests/metrics/floors/test_floors.py). Render such
  references with a lower ``--ref-error``. The floor estimates the noise's
  share of *this* prediction's score, so it can be slightly negative (a prediction darker than
  the reference, e·R < 0); it is not clamped, which would bias the corrected score. For a perfect denoiser it is mean(v/D) to first order, its expected score; for
  others it differs from that by the two terms (measured: a prediction 10 % too dark has its
  noise share 40 % below mean(v/D) when the reference is 5 % noisy: left out, the corrected score
  is biased by that much). What is left is third order in the relative noise √v/R (for a 5 %
  reference, ~0.3 % of the floor). The approximation needs v ≪ D: a reference whose noise is
  comparable to its signal has no meaningful relMSE floor. tests/metrics/floors/test_floors.py checks
  unbiasedness over hundreds of noise draws.
* **se**: with Gaussian noise, Var_n[(e − n)²] = 4e²v + 2v²; e² is estimated by max(d² − v, 0),
  d = p − r; values are taken as independent (box-filtered noise: docs/architecture.md), so
  se = sqrt(Σ (4ê²v + 2v²)/D²) / N over the N values (pixels × channels). Measured against the
  spread of 300 noise draws: within 15 %; up to 1.5× above it (conservative) for a near-perfect
  prediction, where max(d² − v, 0) overestimates e².
* A non-finite prediction gets ``se = nan`` (its score is the worst value anyway); a non-finite or
  negative variance is a ``ValueError`` (bad data, like a non-finite reference).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from denoisebench.metrics.validation import check_pair

#: relMSE's ε: relmse = mean((p − r)² / (r² + EPS_RELMSE)) (:func:`.spatial.relmse`).
EPS_RELMSE = 0.01
#: relmse_floor adds its second-order terms only where v ≤ this × (r² + 0.01) (relative noise ≲ 30 %).
SECOND_ORDER_LIMIT = 0.1

__all__ = [
    "EPS_RELMSE",
    "SECOND_ORDER_LIMIT",
    "Floor",
    "as_variance",
    "squared_error_floor",
    "mse_floor",
    "relmse_floor",
    "noisy_value_share",
]


class Floor(NamedTuple):
    """A score's reference-noise floor and the standard error the reference's noise causes."""

    floor: float
    se: float


def as_variance(ref_var, shape: tuple[int, ...], name: str = "ref_var") -> np.ndarray:
    """``ref_var`` as float64 broadcast to ``shape`` (H×W×1 and H×W broadcast over channels)."""
    try:
        v = np.asarray(ref_var, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} is not an array of numbers: {exc}") from None
    if v.ndim == len(shape) - 1:
        v = v[..., None]
    try:
        v = np.broadcast_to(v, shape)
    except ValueError:
        raise ValueError(f"{name} has shape {v.shape}, the reference {shape}") from None
    if not np.isfinite(v).all():
        raise ValueError(f"{name} has non-finite values (NaN/Inf)")
    if (v < 0).any():
        raise ValueError(f"{name} has negative values: a variance is ≥ 0")
    return v


def squared_error_floor(
    diff: np.ndarray, var: np.ndarray, denom: np.ndarray | float, *, valid=None, correlation: float = 1.0
) -> Floor:
    """Floor and se of ``mean(diff² / denom)`` where ``diff`` carries reference noise of variance ``var``.

    ``valid`` (broadcastable bool) selects the values counted; ``correlation`` multiplies the
    variance of the sum (≥ 1 when counted values share noise, see ``temporal``).
    """
    diff = np.asarray(diff, dtype=np.float64)
    denom = np.broadcast_to(np.asarray(denom, dtype=np.float64), diff.shape)
    var = np.broadcast_to(var, diff.shape)
    if valid is not None:
        keep = np.broadcast_to(valid, diff.shape)
        diff, var, denom = diff[keep], var[keep], denom[keep]
    n = diff.size
    if n == 0:
        raise ValueError("no value is left after masking: nothing to measure")
    floor = float(np.sum(var / denom) / n)
    if not np.isfinite(diff).all():
        return Floor(floor, math.nan)
    e2 = np.maximum(np.square(diff) - var, 0.0)
    variance = np.sum((4.0 * e2 * var + 2.0 * np.square(var)) / np.square(denom)) * correlation
    return Floor(floor, float(math.sqrt(variance) / n))


def mse_floor(pred, ref, ref_var) -> Floor:
    """Floor (mean of the reference variance) and se of ``mse(pred, ref)``."""
    c = check_pair(pred, ref)
    v = as_variance(ref_var, c.ref.shape)
    return squared_error_floor(c.pred.astype(np.float64) - c.ref, v, 1.0)


def relmse_floor(pred, ref, ref_var, *, valid=None) -> Floor:
    """Reference-noise share and se of ``relmse(pred, ref)``, to second order (module Notes).

    ``valid`` (H×W bool): count only those pixels (the kept pixels of a trimmed score, :mod:`.robust`).
    """
    c = check_pair(pred, ref)
    v = as_variance(ref_var, c.ref.shape)
    r = c.ref.astype(np.float64)
    d = c.pred.astype(np.float64) - r
    denom = np.square(r) + EPS_RELMSE
    keep = None
    if valid is not None:
        keep = np.asarray(valid, dtype=bool)
        if keep.shape != c.ref.shape[:2]:
            raise ValueError(f"valid has shape {keep.shape}, the image {c.ref.shape[:2]}")
        keep = np.broadcast_to(keep[..., None], c.ref.shape)
    first = squared_error_floor(d, v, denom, valid=keep)
    if not math.isfinite(first.se):
        return first
    # the reference's noise in the denominator (module Notes): E[d²] = e² + v, E[d·r] = e·R − v
    r2 = np.square(r)
    second = (
        v * np.square(d) * (4.0 * r2 - denom) / denom**3
        + 4.0 * v * (d * r + v) / np.square(denom)
        - np.square(v) * (13.0 * r2 + EPS_RELMSE) / denom**3
    )
    # the expansion holds only where the reference's noise is small against its value (module Notes)
    second = np.where(v <= SECOND_ORDER_LIMIT * denom, second, 0.0)
    return Floor(first.floor + float(np.mean(second if keep is None else second[keep])), first.se)


def noisy_value_share(ref, ref_var) -> float:
    """Share of a reference's values whose noise is comparable to their signal (0 … 1).

    The values with ``v > SECOND_ORDER_LIMIT · (r² + 0.01)`` (relative noise above ~30 %): there the
    relMSE floor's expansion does not hold (module Notes) and only its first-order term is used, which
    underestimates the noise's share. A reference where many values are so has no usable floor: the
    leaderboard sets its scene apart above 5 % (``analysis.aggregate.NOISY_VALUES_LIMIT``).
    """
    r = np.asarray(ref, dtype=np.float64)
    v = as_variance(ref_var, r.shape)
    if r.size == 0:
        return 0.0
    return float(np.mean(v > SECOND_ORDER_LIMIT * (np.square(r) + EPS_RELMSE)))
