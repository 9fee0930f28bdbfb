"""Round sizes and the target-allocation step the adaptive built-ins share.

Notes
-----
* Round sizes come from ``rounds.remaining_samples()`` each time: exact for spp budgets, the
  harness's estimate for seconds budgets, so the same code spends either kind.
* :func:`top_up` turns a per-pixel weight map into one round: it aims the *final* counts at
  ``(spent + size) · w / Σw`` and gives each pixel what it lacks of its target (pixels already over
  their target get nothing), so a round never undoes earlier rounds and a constant weight map keeps
  a uniform image uniform.
* Pixels without a sample have no error estimate (a zero variance is no evidence): :func:`top_up`
  gives each of them one sample first, so an adaptive round never leaves a pixel at 0 samples when it can fill it.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.sampling.allocation import allocate


def initial_samples(rounds, initial_spp: float, share: float = 0.25) -> int:
    """Samples of a sampler's first, uniform round: ``initial_spp`` per pixel, at most ``share`` of what is
    left (seconds budgets: the harness's one-sample probe), at least one per pixel when that fits."""
    left = rounds.remaining_samples()
    if rounds.budget.seconds is not None:
        return left
    size = min(int(round(initial_spp * rounds.pixels)), int(share * left))
    return min(max(size, rounds.pixels), left)


def round_size(rounds, rounds_done: int, rounds_planned: int) -> int:
    """Samples of the next round: what is left split evenly over the planned rounds still to come."""
    left = rounds.remaining_samples()
    to_come = rounds_planned - rounds_done
    return left if to_come <= 1 else max(math.ceil(left / to_come), 1)


def uniform(rounds, size: int) -> np.ndarray:
    """``size`` samples spread evenly (counts differ by at most 1)."""
    return allocate(np.ones((rounds.height, rounds.width)), size)


def top_up(weights: np.ndarray, counts: np.ndarray, size: int) -> np.ndarray:
    """A round of ``size`` samples moving ``counts`` towards final counts proportional to ``weights``."""
    counts = np.asarray(counts, dtype=np.float64)
    unseen = counts < 1
    fill = allocate(unseen, min(size, int(unseen.sum()))) if unseen.any() else np.zeros(counts.shape, np.int64)
    size -= int(fill.sum())
    if size <= 0:
        return fill
    counts = counts + fill
    weights = np.nan_to_num(np.maximum(np.asarray(weights, dtype=np.float64), 0.0), posinf=0.0)
    if not weights.sum() > 0:
        weights = np.ones(counts.shape)
    target = (counts.sum() + size) * weights / weights.sum()
    lack = np.maximum(target - counts, 0.0)
    return fill + allocate(lack if lack.sum() > 0 else weights, size)
