"""Integer sample maps from real-valued weights, luminance, and what one round added.

Pure numpy helpers the built-in samplers share (and plugins may use): :func:`allocate` turns a
weight map into non-negative integer counts with an exact total, :func:`luminance` and
:func:`luminance_var` read the per-pixel luminance and its variance of the mean from a round's
buffers, :func:`round_sums` recovers what the latest round alone added from two accumulated means.

Notes
-----
* :func:`allocate` is deterministic (largest remainder, ties by pixel index): the same weights
  give the same counts on every machine, which keeps samplers deterministic per seed.
* ``luminance_var`` does not know the covariance of the colour channels (the renderer returns
  per-channel variances only); it returns ``(Σ w_c √var_c)²``, the variance when the channels are
  fully correlated, an upper bound on the true one (Cauchy–Schwarz) and exact for grey noise.
"""

from __future__ import annotations

import numpy as np

#: Rec. 709 luminance weights, the ones Mitsuba's ``luminance()`` uses.
LUMINANCE_WEIGHTS = np.array([0.212671, 0.715160, 0.072169], dtype=np.float64)


def allocate(weights: np.ndarray, total: int) -> np.ndarray:
    """Non-negative int64 counts proportional to ``weights`` summing to exactly ``total``.

    Weights that are all zero (or not finite) give a uniform split. No pixel gets more than
    ``ceil(weight · total / Σ weight)``, so ``allocate(request, k)`` with ``k <= request.sum()`` never
    exceeds any pixel's request (how the harness cuts a round down to what is left).
    """
    weights = np.nan_to_num(np.asarray(weights, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    weights = np.maximum(weights, 0.0)
    total = int(total)
    if total <= 0 or weights.size == 0:
        return np.zeros(weights.shape, dtype=np.int64)
    if not weights.sum() > 0:
        weights = np.ones(weights.shape)
    flat = weights.ravel()
    ideal = flat * (total / flat.sum())
    counts = np.floor(ideal).astype(np.int64)
    left = total - int(counts.sum())
    if left > 0:
        order = np.argsort(-(ideal - counts), kind="stable")
        counts[order[:left]] += 1
    elif left < 0:  # rounding of ``ideal`` pushed a floor over by one somewhere
        order = np.argsort(np.where(counts > 0, ideal - counts, np.inf), kind="stable")
        counts[order[:-left]] -= 1
    return counts.reshape(weights.shape)


def luminance(buffers: dict[str, np.ndarray]) -> np.ndarray:
    """H×W float64 luminance of ``buffers["color"]``."""
    return np.asarray(buffers["color"], dtype=np.float64) @ LUMINANCE_WEIGHTS


def luminance_var(buffers: dict[str, np.ndarray]) -> np.ndarray:
    """H×W float64 variance of the mean of the luminance (upper bound; see the module Notes)."""
    spread = np.sqrt(np.maximum(np.asarray(buffers["color_var"], dtype=np.float64), 0.0))
    return (spread @ LUMINANCE_WEIGHTS) ** 2


def round_sums(mean_before, count_before, mean_after, count_after) -> np.ndarray:
    """Sum of the samples the last round added per pixel: ``mean_after·n_after − mean_before·n_before``."""
    after = np.asarray(mean_after, dtype=np.float64) * np.asarray(count_after, dtype=np.float64)[..., None]
    if mean_before is None:
        return after
    before = np.asarray(mean_before, dtype=np.float64) * np.asarray(count_before, dtype=np.float64)[..., None]
    return after - before
