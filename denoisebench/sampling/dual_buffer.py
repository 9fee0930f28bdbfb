"""The ``dual_buffer`` sampler: an error map from two independent half images, samples where it is large.

Rousselle, F., Knaus, C. and Zwicker, M. (2012), "Adaptive rendering with non-local means
filtering", ACM Transactions on Graphics 31(6) (SIGGRAPH Asia): the samples of every pixel are
split into two independent half buffers A and B, whose squared difference estimates the variance
of the image (``E[(A − B)²] = 4 · var(mean)`` with equal halves), smoothed over a neighbourhood to
tame its own noise; production renderers use the same dual-buffer estimate (e.g. RenderMan's and
Cycles' adaptive sampling). The sampler spends each round where the relative error
``var / (L² + ε)`` is large.

Rounds: two uniform half rounds of ``initial_spp / 2`` each, then ``rounds`` rounds, each rendered as
two equal half rounds (the same map twice, one per buffer), so that A and B keep equal counts in
every pixel. A round aims the final counts at ``n ∝ σ / √(L² + ε)`` (``σ`` the per-sample standard
deviation ``√(n · var)``), the allocation that minimises the relative MSE ``Σ σ² / (n (L² + ε))`` at a
fixed total (Lagrange), and gives each pixel what it lacks of that.

Notes
-----
* The halves are recovered from the renderer's accumulated means (a half round's sum is
  ``mean_after · n_after − mean_before · n_before``), so any renderer with the round interface will
  do; the final image is the mean of all samples (A and B together).
* ``filter_radius`` (a box of ``2r + 1`` pixels) smooths both the squared difference and ``L²``; the
  error map of a frame at a few spp is itself noisy, which spreads samples even over a constant
  image (the sampler card measures this).
* A budget under 2 spp is spent uniformly in one round: no pair of one-sample halves fits.
* A budget with an odd number of samples left in the last round leaves one sample unspent (the
  halves must match); the harness's 1 % tolerance covers it for every frame over 100 pixels.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter

from denoisebench.sampling.allocation import LUMINANCE_WEIGHTS, round_sums
from denoisebench.sampling.schedule import initial_samples, round_size, top_up, uniform


class DualBuffer:
    """Two half buffers, filtered squared difference as the error map (module docstring)."""

    name = "dual_buffer"

    def __init__(self, initial_spp: int = 4, rounds: int = 4, filter_radius: int = 2, epsilon: float = 1e-3):
        if not initial_spp >= 2 or not rounds >= 1 or not filter_radius >= 0 or not epsilon > 0:
            raise ValueError("dual_buffer needs initial_spp >= 2, rounds >= 1, filter_radius >= 0, epsilon > 0")
        self.initial_spp = int(initial_spp)
        self.rounds = int(rounds)
        self.filter_radius = int(filter_radius)
        self.epsilon = float(epsilon)

    def _half(self, rounds, counts, state) -> None:
        """Render ``counts`` once into buffer ``state['next']`` (A, then B)."""
        before_mean, before_n = state["mean"], rounds.counts.copy()
        result = rounds.render(counts)
        lum = round_sums(before_mean, before_n, result.buffers["color"], result.counts) @ LUMINANCE_WEIGHTS
        key = state["next"]
        state[key] = state[key] + lum
        state[key + "_n"] = state[key + "_n"] + counts
        state["mean"] = np.asarray(result.buffers["color"], dtype=np.float64)
        state["next"] = "b" if key == "a" else "a"

    def error_map(self, state) -> tuple[np.ndarray, np.ndarray]:
        """(var of the combined mean, luminance²), both box-filtered: the estimates a round is planned on."""
        n = np.maximum(state["a_n"], 1)
        mean_a, mean_b = state["a"] / n, state["b"] / n
        size = 2 * self.filter_radius + 1
        with np.errstate(over="ignore", invalid="ignore"):  # a firefly's square may overflow: it counts as none
            diff2 = np.nan_to_num((mean_a - mean_b) ** 2 / 4.0, nan=0.0, posinf=0.0)
            mean2 = np.nan_to_num(((mean_a + mean_b) / 2) ** 2, nan=0.0, posinf=0.0)
        var = uniform_filter(diff2, size=size, mode="nearest")
        lum2 = uniform_filter(mean2, size=size, mode="nearest")
        return var, lum2

    def sample(self, budget, rounds) -> None:
        zero = np.zeros((rounds.height, rounds.width))
        state = {"a": zero, "b": zero, "a_n": zero, "b_n": zero, "mean": None, "next": "a"}
        first = initial_samples(rounds, self.initial_spp) // 2
        if budget.spp is not None and rounds.remaining_samples() < 2 * rounds.pixels:
            rounds.render(uniform(rounds, rounds.remaining_samples()))  # no pair of halves fits: uniform
            return
        if budget.spp is not None:
            first = max(first, rounds.pixels)  # one sample per pixel in each half
        if first <= 0:
            return
        half = uniform(rounds, first)
        self._half(rounds, half, state)
        self._half(rounds, half, state)
        done = 0
        while not rounds.cut and (size := round_size(rounds, done, self.rounds) // 2) > 0:
            var, lum2 = self.error_map(state)
            sigma = np.sqrt(np.maximum(np.nan_to_num(var * rounds.counts, posinf=0.0), 0.0))
            half = top_up(sigma / np.sqrt(lum2 + self.epsilon), rounds.counts / 2, size)
            self._half(rounds, half, state)
            if rounds.cut:
                return
            self._half(rounds, half, state)
            done += 1
