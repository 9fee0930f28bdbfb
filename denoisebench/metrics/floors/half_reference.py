"""The reference's effect on scores without a closed-form floor, measured from two half references.

A reference of ``N`` spp is noisy, and every score against it moves with that noise. For the MSE
family the move has a closed form (:mod:`.floors`); for FLIP, SSIM, PSNR, SMAPE, ΔE2000 and the
gradient scores it does not, but it can be **measured**: the generator keeps two independent halves
of each adaptive reference (``color_half``, the even rounds, and the odd rounds, recovered as
``(N · full − N_a · half) / N_b``; ``generator.render.reference``). To first order in the
reference's noise the expected score against an ``M``-spp reference is ``S∞ + c / M`` (every term
of a smooth score that the noise enters is proportional to its variance, which falls as 1/M), so
the score against the halves (``S_half``, the mean of the two, at ``1/M_h = (1/N_a + 1/N_b) / 2``)
and against the full reference (``S_full``) give (Richardson's extrapolation)

    S∞ ≈ (N · S_full − M_h · S_half) / (N − M_h)        floor = S_full − S∞ = M_h (S_half − S_full) / (N − M_h)

and :func:`half_reference_floor` returns that ``floor`` as a :class:`.floors.Floor`, so the corrected
score ``score − floor`` is aggregated like the MSE family's. Its ``se`` is ``|S_a − S_b| / 2``: the
two halves' scores differ by the reference's noise alone, and the corrected value is, to first
order, the mean of the two half scores plus a deterministic term, whose spread that is.

Notes
-----
* For a higher-is-better score (SSIM, PSNR) the floor is negative: a noisy reference lowers it, and
  the corrected score is higher than the raw one.
* The estimate is first order: where the score is far from linear in the reference's noise (PSNR's
  logarithm near a perfect match, a score dominated by a few firefly pixels of the reference) it is
  rough, and one frame's se is a one-draw estimate; aggregated over frames and scenes both settle.
* A non-finite score (any of the three) gives a nan floor and se: the frame then keeps its raw score.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.metrics.floors.closed_form import Floor

__all__ = ["other_half", "half_reference_floor"]


def other_half(full, half, full_spp: int, half_spp: tuple[int, int]) -> np.ndarray:
    """The second half reference, from the full mean and the first half: ``(N · full − N_a · half) / N_b``."""
    n_a, n_b = int(half_spp[0]), int(half_spp[1])
    if n_a < 1 or n_b < 1 or n_a + n_b != int(full_spp):
        raise ValueError(f"half spp {half_spp} do not add up to the reference's {full_spp}")
    full = np.asarray(full, dtype=np.float64)
    return ((n_a + n_b) * full - n_a * np.asarray(half, dtype=np.float64)) / n_b


def half_reference_floor(full_score: float, half_scores: tuple[float, float], full_spp: int, half_spp) -> Floor:
    """``S_full − S∞`` and its se from the scores against the full reference and its two halves (module
    docstring); nan for non-finite scores."""
    s_a, s_b = (float(v) for v in half_scores)
    if not all(math.isfinite(v) for v in (full_score, s_a, s_b)):
        return Floor(math.nan, math.nan)
    n = float(full_spp)
    m_h = 2.0 / (1.0 / float(half_spp[0]) + 1.0 / float(half_spp[1]))
    if not 0 < m_h < n:
        raise ValueError(f"half spp {half_spp} are not halves of {full_spp}")
    floor = m_h * ((s_a + s_b) / 2.0 - float(full_score)) / (n - m_h)
    return Floor(float(floor), abs(s_a - s_b) / 2.0)
