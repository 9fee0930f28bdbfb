"""The ``uniform`` sampler: the same number of samples in every pixel, as the stored dataset inputs.

The baseline every adaptive sampler is judged against: Monte Carlo integration at a fixed sample
count per pixel (Cook, Porter and Carpenter 1984, "Distributed ray tracing"; Kajiya 1986,
"The rendering equation").

Notes
-----
* An spp budget is spent in one round; a fractional mean (8.5 spp) gives counts that differ by one,
  the extra samples in raster order. A seconds budget takes the harness's one-sample probe first,
  then what the measured rate says fits, round after round, until the time is up.
"""

from __future__ import annotations

from denoisebench.sampling.schedule import uniform


class Uniform:
    """Every pixel the same count (counts differ by at most one)."""

    name = "uniform"

    def sample(self, budget, rounds) -> None:
        while (left := rounds.remaining_samples()) > 0:
            rounds.render(uniform(rounds, left))
            if rounds.cut:
                return
