"""An example sampler plugin: each round goes where a pixel's own relative standard error is largest.

No filtering of the error map (compare the built-in ``dual_buffer``): a pixel's per-sample
standard deviation ``σ = √(n · var)`` over its mean luminance ``L`` decides its share, and every
round aims the final counts at ``n ∝ σ / (L + 0.01)`` (the relative-MSE optimum for known ``σ``),
topping up the pixels below their target.

Notes
-----
* Uses only denoisebench's public sampling helpers (``allocation``, ``schedule``); the harness gives
  it the budget and the round handle, cuts a round that asks for too much, and records the rounds.
* A one-pixel error estimate at a few spp is noisy; ``rounds`` small (4) keeps decisions few.
"""

from __future__ import annotations

import numpy as np

from denoisebench.sampling.allocation import luminance, luminance_var
from denoisebench.sampling.schedule import initial_samples, round_size, top_up, uniform


class PixelVariance:
    """Per-pixel relative-error sampler (module docstring)."""

    name = "example_variance"

    def __init__(self, initial_spp: int = 4, rounds: int = 4):
        if initial_spp < 1 or rounds < 1:
            raise ValueError("example_variance needs initial_spp >= 1 and rounds >= 1")
        self.initial_spp = int(initial_spp)
        self.rounds = int(rounds)

    def sample(self, budget, rounds) -> None:
        first = initial_samples(rounds, self.initial_spp)
        if first <= 0:
            return
        result = rounds.render(uniform(rounds, first))
        done = 0
        while not rounds.cut and (size := round_size(rounds, done, self.rounds)) > 0:
            counts = rounds.counts
            sigma = np.sqrt(np.where(counts > 0, luminance_var(result.buffers) * counts, 0.0))
            result = rounds.render(top_up(sigma / (luminance(result.buffers) + 0.01), counts, size))
            done += 1
