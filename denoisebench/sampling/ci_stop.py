"""The ``ci_stop`` sampler: Mitsuba 0.6's ``adaptive`` integrator rule, a per-pixel confidence-interval stop.

Jakob, W. (2010), Mitsuba renderer 0.6, ``src/integrators/misc/adaptive.cpp`` and the
documentation's "Adaptive integrator": a pixel takes blocks of samples until the half-width of the
confidence interval of its mean luminance, ``z_{1-p/2} · √(var/n)`` (a Z-test at ``p_value``), is
below ``max_error`` times the mean (the mean clamped below by a small epsilon), or until it holds
``max_sample_factor`` times the first block's samples.

Here the blocks are rounds: a first uniform round of ``initial_spp``, then every pixel still open
gets ``initial_spp`` more per round (Mitsuba's block = its base sampler's sample count).

Notes
-----
* The variance is the renderer's variance of the mean of the colour channels folded into luminance
  as ``(Σ w_c √var_c)²`` (:func:`~denoisebench.sampling.allocation.luminance_var`), an upper bound of
  Mitsuba's per-sample luminance variance: it stops no earlier than Mitsuba would.
* Mitsuba stops when every pixel has stopped and leaves the rest of the time unspent. At equal mean
  spp that would judge a sampler that spends less against one that spends all, so with
  ``spend_all`` (default) the rule is run again with ``max_error`` and ``max_sample_factor``
  doubled/halved until the budget is spent; a frame whose variance is zero everywhere (nothing to
  test) gets the rest uniformly. ``spend_all=False`` is Mitsuba's rule as it is.
* Stopping on the sample variance biases the mean when the variance correlates with the mean
  (skewed Monte Carlo noise: a pixel whose few samples are low also looks converged). The bias
  shrinks as the threshold does; the convergence check measures it.
"""

from __future__ import annotations

from statistics import NormalDist

import numpy as np

from denoisebench.sampling.allocation import luminance, luminance_var
from denoisebench.sampling.schedule import initial_samples, uniform

#: Mitsuba's Epsilon, the floor of the mean in the relative error.
EPSILON = 1e-4
#: How often ``spend_all`` tightens the rule before giving the rest uniformly.
MAX_TIGHTENINGS = 30


class ConfidenceStop:
    """Per-pixel Z-test stop on luminance (module docstring). Mitsuba's defaults: 5 % error, p = 0.05, factor 32."""

    name = "ci_stop"

    def __init__(
        self,
        max_error: float = 0.05,
        p_value: float = 0.05,
        initial_spp: int = 4,
        max_sample_factor: float = 32.0,
        spend_all: bool = True,
    ):
        if not 0 < p_value < 1 or not max_error > 0 or not initial_spp >= 1 or not max_sample_factor >= 1:
            raise ValueError("ci_stop needs 0 < p_value < 1, max_error > 0, initial_spp >= 1, max_sample_factor >= 1")
        self.max_error = float(max_error)
        self.quantile = NormalDist().inv_cdf(1 - p_value / 2)
        self.initial_spp = int(initial_spp)
        self.max_sample_factor = float(max_sample_factor)
        self.spend_all = bool(spend_all)

    def open_pixels(self, buffers, counts: np.ndarray, max_error: float, cap: float) -> np.ndarray:
        """Pixels whose interval is still wider than ``max_error`` of their mean and that are under ``cap``."""
        mean = luminance(buffers)
        half_width = self.quantile * np.sqrt(luminance_var(buffers))
        wide = (half_width > max_error * np.maximum(mean, EPSILON)) | (counts < 2)
        return wide & (counts < cap)

    def sample(self, budget, rounds) -> None:
        first = initial_samples(rounds, self.initial_spp)
        if first <= 0:
            return
        result = rounds.render(uniform(rounds, first))
        block = self.initial_spp if budget.seconds is not None else max(int(round(rounds.counts.mean())), 1)
        max_error, cap = self.max_error, self.max_sample_factor * block
        tightenings = 0
        while not rounds.cut and (left := rounds.remaining_samples()) > 0:
            open_ = self.open_pixels(result.buffers, rounds.counts, max_error, cap)
            if not open_.any():
                if not self.spend_all:
                    return
                if tightenings >= MAX_TIGHTENINGS or not (luminance_var(result.buffers) > 0).any():
                    result = rounds.render(uniform(rounds, left))
                    continue
                max_error, cap, tightenings = max_error / 2, cap * 2, tightenings + 1
                continue
            request = np.where(open_, block, 0)
            result = rounds.render(request)
