"""Robust (trimmed) relMSE scores: a handful of firefly pixels cannot decide them.

``relmse_robust(pred, ref, trim=0.001)`` is relMSE of one frame without its highest ``trim``
fraction of per-pixel errors; ``temporal_relmse_robust`` is ``temporal_relmse`` without the
highest fraction of each frame pair's per-pixel errors. Both are lower-is-better, scale-free
(they aggregate over scenes by the mean, like their raw forms), and carry reference-noise floors.

Why (docs/architecture.md "Metrics")
-----------------------------------
relMSE squares the error and divides by ``r² + 0.01``: one firefly of radiance 100 in a pixel
whose reference is 0.05 contributes ``100² / 0.0125 = 8·10⁵`` to a sum that the other pixels fill
with values near 0.1–1, so over a 6400-pixel frame that single pixel adds ≈ 125 to the mean and
decides the score, the ranking and the "render more" curve (measured on the demo: the noisy
input's relMSE *rose* from 0.854 at 1 spp to 2.18 at 4 spp because of one caustic firefly). The
rendering literature therefore reports relMSE over the image without its worst pixels, beside
SMAPE (Vogels et al. 2018, "Denoising with Kernel Prediction and Asymmetric Loss Functions",
ACM TOG 37(4): ``|p − r| / (|p| + |r| + ε)``, bounded by 1 per value; :func:`.spatial.smape`).
The raw relMSE stays beside the robust one in every table.

Definition
----------
Per-pixel errors ``e_i`` are the channel mean of ``(p − r)² / (r² + 0.01)`` (``relmse_map``);
with N pixels, the ``k = ceil(trim · N)`` largest are dropped (at least one pixel whenever
``trim > 0``, never all: k ≤ N − 1) and the score is the mean of the N − k others. ``trim = 0``
is plain relMSE. Ties at the cut are broken by pixel order (stable sort), so the value is
deterministic. The default fraction, :data:`DEFAULT_TRIM` = 0.001 (0.1 %), drops 7 pixels of an
80×80 frame and 2074 of a 1920×1080 one; ``run-benchmark --trim F`` changes it and records it
in the run's config.

What one firefly can do (the bound ``tests/metrics/ours/test_robust.py`` checks): raising one
pixel's error to any value, however large, raises the robust score by at most
``e_(N−k+1) / (N − k)``, where ``e_(N−k+1)`` is the smallest error the trim dropped from the
unchanged image: the firefly either is dropped itself or pushes the kept set's largest value out
and that value in. The raw relMSE moves by the firefly's full ``e / N``.

Temporal: ``temporal_relmse``'s per-pixel values of each pair t (the warped frame differences'
``(Δp − Δr)² / (m_t² + 0.01)``, channel mean, disoccluded and masked pixels already left out)
are trimmed the same way *per pair* (k from that pair's valid pixel count), and the kept values
of all pairs are pooled (each kept pixel weighs the same), as the raw score pools them.

Notes
-----
* Floors (:mod:`.floors`): the floor of a trimmed score is the reference's noise share over the
  **kept** pixels, i.e. the raw floors with the dropped pixels masked out. The kept set is chosen
  from the noisy difference itself, so pixels where the reference noise happened to add error
  are more likely dropped: the floor is then slightly high, by at most the noise share of the
  k dropped pixels, 0.1 % of the pixels: small unless the reference's noise sits in exactly
  those pixels (fireflies in the reference; then :func:`.floors.relmse_floor`'s caveats apply).
* A non-finite prediction gives ``+inf`` (validation's policy), like relMSE: trimming never hides
  a NaN.
* Bad ``trim`` (not a number in [0, 0.5)) is a ``ValueError``.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.metrics.floors.closed_form import Floor, as_variance, relmse_floor, squared_error_floor
from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.ours import temporal as tm
from denoisebench.metrics.ours.spatial import _pixelwise_map, _rel_sq
from denoisebench.metrics.validation import check_pair

__all__ = [
    "DEFAULT_TRIM",
    "MAX_TRIM",
    "METRICS",
    "WORST",
    "check_trim",
    "trimmed_count",
    "kept_mask",
    "relmse_robust",
    "relmse_robust_map",
    "relmse_robust_floor",
    "temporal_relmse_robust",
    "temporal_relmse_robust_map",
    "temporal_relmse_robust_floor",
]

#: Fraction of the highest per-pixel errors a robust score drops (0.1 %).
DEFAULT_TRIM = 0.001
#: A trim fraction must lie in [0, MAX_TRIM).
MAX_TRIM = 0.5


def check_trim(trim) -> float:
    """``trim`` as a float in [0, 0.5); anything else is a ``ValueError`` with a one-line message."""
    try:
        value = float(trim)
    except (TypeError, ValueError):
        raise ValueError(f"the trim fraction must be a number in [0, {MAX_TRIM}), got {trim!r}") from None
    if not (math.isfinite(value) and 0.0 <= value < MAX_TRIM):
        raise ValueError(f"the trim fraction must be a number in [0, {MAX_TRIM}), got {trim!r}")
    return value


def trimmed_count(n: int, trim: float) -> int:
    """How many of ``n`` values a trim of ``trim`` drops: ceil(trim · n), 0 for trim 0, at most n − 1."""
    trim = check_trim(trim)
    if n <= 1 or trim == 0.0:
        return 0
    return min(int(math.ceil(trim * n - 1e-9)), n - 1)


def kept_mask(values: np.ndarray, trim: float, valid: np.ndarray | None = None) -> np.ndarray:
    """Bool mask (shape of ``values``) of the values kept: ``valid`` ones without the ``trimmed_count``
    highest (ties broken by flat index, stable)."""
    values = np.asarray(values, dtype=np.float64)
    keep = np.ones(values.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool).copy()
    index = np.flatnonzero(keep)
    k = trimmed_count(index.size, trim)
    if k:
        order = np.argsort(values.ravel()[index], kind="stable")
        keep.ravel()[index[order[index.size - k :]]] = False
    return keep


def _frame(pred, ref, trim):
    c = check_pair(pred, ref)
    trim = check_trim(trim)
    errors = _pixelwise_map(c, _rel_sq, math.inf)
    return c, errors, kept_mask(errors, trim)


def relmse_robust(pred, ref, *, trim: float = DEFAULT_TRIM) -> float:
    """relMSE without the ``ceil(trim · N)`` highest per-pixel errors (module docstring). Lower is better."""
    c, errors, keep = _frame(pred, ref, trim)
    if c.nonfinite_count:
        return WORST["relmse_robust"]
    return float(errors[keep].mean())


def relmse_robust_map(pred, ref, *, trim: float = DEFAULT_TRIM) -> np.ndarray:
    """Per-pixel relMSE (H×W) with the dropped pixels set to 0 (their mean over kept pixels is the score)."""
    _, errors, keep = _frame(pred, ref, trim)
    return np.where(keep, errors, 0.0)


def relmse_robust_floor(pred, ref, ref_var, *, trim: float = DEFAULT_TRIM) -> Floor:
    """Reference-noise floor and se of :func:`relmse_robust`: relMSE's floor over the kept pixels."""
    c, errors, keep = _frame(pred, ref, trim)
    if c.nonfinite_count:
        return relmse_floor(pred, ref, ref_var)  # se is nan: the score is the worst value anyway
    return relmse_floor(c.pred, c.ref, ref_var, valid=keep)


# --------------------------------------------------------------------------- temporal


def _pairs(pred_seq, ref_seq, motion, depth, masks, depth_tolerance, trim, ref_var=None):
    """(c, per-pair values (T−1)×H×W, kept (T−1)×H×W, diff, denom, var) of temporal_relmse, trimmed per pair."""
    c, mask, mot, dep = tm._relative_setup(pred_seq, ref_seq, motion, depth, masks, depth_tolerance)
    trim = check_trim(trim)
    var = None if ref_var is None else as_variance(ref_var, c.ref.shape)
    pred = np.where(np.isfinite(c.pred), c.pred, np.nan) if c.nonfinite_count else c.pred
    diff, denom, valid, pair_var = tm._relative_pairs(c._replace(pred=pred), mask, mot, dep, depth_tolerance, var)
    with np.errstate(invalid="ignore"):
        values = (np.square(diff) / denom).mean(axis=-1)
    if not valid.any():
        raise ValueError("no pixel is left after masking and disocclusion: nothing to measure")
    keep = np.stack([kept_mask(np.nan_to_num(v, nan=np.inf), trim, ok) for v, ok in zip(values, valid)])
    return c, values, keep, diff, denom, pair_var


def temporal_relmse_robust(
    pred_seq,
    ref_seq,
    motion=None,
    *,
    depth=None,
    masks=None,
    depth_tolerance: float = tm.DEPTH_TOLERANCE,
    trim: float = DEFAULT_TRIM,
) -> float:
    """``temporal_relmse`` without each pair's ``ceil(trim · N)`` highest per-pixel values, pooled."""
    c, values, keep, *_ = _pairs(pred_seq, ref_seq, motion, depth, masks, depth_tolerance, trim)
    if c.nonfinite_count:
        return WORST["temporal_relmse_robust"]
    return float(values[keep].mean())


def temporal_relmse_robust_map(
    pred_seq,
    ref_seq,
    motion=None,
    *,
    depth=None,
    masks=None,
    depth_tolerance: float = tm.DEPTH_TOLERANCE,
    trim: float = DEFAULT_TRIM,
) -> np.ndarray:
    """(T−1)×H×W per-pixel values; 0 at dropped, disoccluded or masked pixels."""
    c, values, keep, *_ = _pairs(pred_seq, ref_seq, motion, depth, masks, depth_tolerance, trim)
    if c.nonfinite_count:
        return np.full(values.shape, WORST["temporal_relmse_robust"])
    return np.where(keep, values, 0.0)


def temporal_relmse_robust_floor(
    pred_seq,
    ref_seq,
    ref_var,
    motion=None,
    *,
    depth=None,
    masks=None,
    depth_tolerance: float = tm.DEPTH_TOLERANCE,
    trim: float = DEFAULT_TRIM,
) -> Floor:
    """Reference-noise floor and se of :func:`temporal_relmse_robust`: temporal_relmse's over the kept pixels."""
    _, _, keep, diff, denom, var = _pairs(pred_seq, ref_seq, motion, depth, masks, depth_tolerance, trim, ref_var)
    return squared_error_floor(diff, var, denom, valid=keep[..., None], correlation=3.0)


# --------------------------------------------------------------------------- entries

METRICS: tuple[Metric, ...] = (
    Metric(
        name="relmse_robust",
        fn=relmse_robust,
        map_fn=relmse_robust_map,
        higher_is_better=False,
        domain="linear",
        kind="spatial",
        worst=math.inf,
        perfect=0.0,
        description="relMSE without the highest 0.1 % of per-pixel errors (--trim; robust.py)",
        accepts=("trim",),
        floor_fn=relmse_robust_floor,
    ),
    Metric(
        name="temporal_relmse_robust",
        fn=temporal_relmse_robust,
        map_fn=temporal_relmse_robust_map,
        higher_is_better=False,
        domain="linear",
        kind="temporal",
        worst=math.inf,
        perfect=0.0,
        description="temporal_relmse without each pair's highest 0.1 % of per-pixel values (--trim; robust.py)",
        accepts=("motion", "depth", "masks", "trim"),
        floor_fn=temporal_relmse_robust_floor,
    ),
)

#: Worst value of each metric, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
