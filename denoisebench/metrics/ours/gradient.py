"""Gradient-domain metrics of one frame, linear HDR: mean |∇p − ∇r| and HFEN.

Notes
-----
* ``grad_l1``: ∇ is the forward difference along x (columns) and y (rows), zero past the last
  column/row (replicate boundary), and |∇p − ∇r| the L1 norm of the 2-vector,
  |Δx(p−r)| + |Δy(p−r)|, averaged over channels and pixels. A 1×1 image has no gradient: 0.
  Equivalently ``(Σ|diff(e, axis=1)| + Σ|diff(e, axis=0)|) / (H·W·3)`` with e = p − r.
* ``hfen``: high-frequency error norm (Ravishankar & Bresler 2011) with their Laplacian of
  Gaussian, MATLAB's ``fspecial('log', 15, 1.5)`` (15×15, σ = 1.5, shifted to sum 0 so that a
  constant maps to 0; scipy's ``gaussian_laplace`` leaks ≈ 2e-4 of the DC), applied per channel
  with a mirror boundary (scipy ``reflect``):
  ``HFEN = rms(LoG(p) − LoG(r)) / (rms(LoG(r)) + 0.01)``. The ε = 0.01 (radiance units, like
  relMSE's) keeps a flat or black reference finite; it makes HFEN of very dark images small.
  ``hfen_map`` is the per-pixel RMS over channels of ``LoG(p) − LoG(r)`` divided by the same
  denominator, so ``hfen == sqrt(mean(hfen_map**2))``.
* Both are 0 for identical images and +inf for a prediction with NaN/Inf (the map is then +inf
  everywhere: differences and the LoG spread a non-finite value to its neighbours).
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.ours.spatial import mean_of_map
from denoisebench.metrics.validation import Checked, check_pair

# Lazy imports: scipy (0.3 s) is imported inside the functions that filter.

__all__ = [
    "HFEN_SIGMA",
    "HFEN_SIZE",
    "EPS_HFEN",
    "grad_l1",
    "grad_l1_map",
    "hfen",
    "hfen_map",
    "laplacian_of_gaussian",
    "METRICS",
    "WORST",
]

HFEN_SIGMA = 1.5
HFEN_SIZE = 15  # kernel width, as in Ravishankar & Bresler 2011 (fspecial('log', 15, 1.5))
EPS_HFEN = 0.01


def _error(c: Checked) -> np.ndarray:
    with np.errstate(over="ignore", invalid="ignore"):
        return c.pred.astype(np.float64) - c.ref


def _grad_l1_map(c: Checked) -> np.ndarray:
    e = _error(c)
    g = np.zeros(e.shape[:2])
    with np.errstate(over="ignore", invalid="ignore"):
        g[:, :-1] += np.abs(np.diff(e, axis=1)).mean(axis=-1)
        g[:-1, :] += np.abs(np.diff(e, axis=0)).mean(axis=-1)
    return g


def grad_l1(pred, ref) -> float:
    """Mean L1 norm of the forward-difference gradient error, linear HDR. Lower is better."""
    return mean_of_map(pred, ref, _grad_l1_map, WORST["grad_l1"])


def grad_l1_map(pred, ref) -> np.ndarray:
    """Per-pixel |Δx(p−r)| + |Δy(p−r)| averaged over channels (H×W)."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return np.full(c.ref.shape[:2], WORST["grad_l1"])
    return _grad_l1_map(c)


def _log_kernels(sigma: float, size: int):
    """1-D pieces of MATLAB's ``fspecial('log', size, sigma)``: g, a and the zero-sum correction.

    The 2-D kernel is h(x, y) = G(x, y)·(x² + y² − 2σ²)/σ⁴ with G the sampled Gaussian normalised to
    sum 1, minus its mean so that it sums to 0. With g(x) = normalised 1-D Gaussian and
    a(x) = g(x)·(x² − σ²)/σ⁴ this is g(y)·a(x) + a(y)·g(x) − m, m = mean of the first two terms.
    """
    r = size // 2
    x = np.arange(-r, r + 1, dtype=np.float64)
    g = np.exp(-0.5 * x**2 / sigma**2)
    g /= g.sum()
    a = g * (x**2 - sigma**2) / sigma**4
    m = 2.0 * a.sum() * g.sum() / size**2
    return g, a, m


def laplacian_of_gaussian(image: np.ndarray, sigma: float = HFEN_SIGMA, size: int = HFEN_SIZE) -> np.ndarray:
    """Per-channel zero-sum LoG (MATLAB ``fspecial('log', 15, 1.5)``), mirror boundary, float64.

    Applied separably: ``corr(g ⊗ a) + corr(a ⊗ g) − m·box(size)``; "reflect" boundary
    (d c b a | a b c d). A constant image maps to 0.
    """
    from scipy.ndimage import correlate1d, uniform_filter

    image = np.asarray(image, dtype=np.float64)
    g, a, m = _log_kernels(sigma, size)
    out = correlate1d(correlate1d(image, g, axis=0, mode="reflect"), a, axis=1, mode="reflect")
    out += correlate1d(correlate1d(image, a, axis=0, mode="reflect"), g, axis=1, mode="reflect")
    out -= (m * size * size) * uniform_filter(image, size=(size, size, 1), mode="reflect")
    return out


def _hfen_parts(c: Checked) -> tuple[np.ndarray, float]:
    log_r = laplacian_of_gaussian(c.ref)
    with np.errstate(over="ignore", invalid="ignore"):
        diff = laplacian_of_gaussian(c.pred.astype(np.float64) - c.ref)  # LoG is linear
        per_pixel = np.sqrt(np.mean(np.square(diff), axis=-1))
    denom = math.sqrt(float(np.mean(np.square(log_r)))) + EPS_HFEN
    return per_pixel, denom


def hfen(pred, ref) -> float:
    """HFEN: ``rms(LoG(p) − LoG(r)) / (rms(LoG(r)) + 0.01)``, LoG σ = 1.5. Lower is better."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return WORST["hfen"]
    per_pixel, denom = _hfen_parts(c)
    with np.errstate(over="ignore"):
        return math.sqrt(float(np.mean(np.square(per_pixel)))) / denom


def hfen_map(pred, ref) -> np.ndarray:
    """Per-pixel RMS (over channels) of LoG(p) − LoG(r), over HFEN's denominator (H×W)."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return np.full(c.ref.shape[:2], WORST["hfen"])
    per_pixel, denom = _hfen_parts(c)
    return per_pixel / denom


# --------------------------------------------------------------------------- entries

METRICS: tuple[Metric, ...] = (
    Metric(
        name="grad_l1",
        fn=grad_l1,
        map_fn=grad_l1_map,
        higher_is_better=False,
        domain="linear",
        kind="gradient",
        worst=math.inf,
        perfect=0.0,
        description="mean |grad p - grad r| (forward differences)",
        aggregate="relative_to_input",
    ),
    Metric(
        name="hfen",
        fn=hfen,
        map_fn=hfen_map,
        higher_is_better=False,
        domain="linear",
        kind="gradient",
        worst=math.inf,
        perfect=0.0,
        description="rms(LoG(p) - LoG(r)) / (rms(LoG(r)) + 0.01), LoG sigma 1.5",
        aggregate="relative_to_input",
    ),
)

#: Worst value of each metric, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
