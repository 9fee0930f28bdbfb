"""Per-pixel sample counts: render a frame in rounds, each pixel continuing its own sample stream.

This is the handle adaptive samplers (:mod:`denoisebench.sampling`, docs/architecture.md, "Sampler protocol")
render through. :class:`ProgressiveFrame` is the feature renderer's
:class:`~denoisebench.generator.render.frame.FrameStream` with the samplers' entry point: every call of
:meth:`ProgressiveFrame.render_round` traces the *additional* samples a count map asks for and
returns the accumulated per-pixel buffers of all samples so far (:class:`RoundBuffers`).

Conventions:

* Unbiased: each pixel's buffers are the mean of its own samples, whatever the other pixels got;
  the counts decide which samples exist, never how they are weighted.
* A pixel's ``j``-th sample is the same sample in every render with the same seed (random numbers
  depend on seed, frame, stream, pixel and sample index only), so the buffers after any sequence
  of rounds depend on the accumulated counts alone: a uniform map of ``k`` (in one round or in
  several) gives the same bytes as ``render_frame(..., spp=k)`` with the same seed, and one sampler
  run is deterministic per round.
* ``<name>_var`` is the variance of the mean (unbiased sample variance / count). A pixel with 0
  samples has mean **0** and variance **inf**; with 1 sample its variance is **0** (unknown, but
  finite, as in a 1-spp dataset frame). ``counts`` tells the three apart.
* ``seconds`` is the render time of the round alone, timed like dataset frames: Dr.Jit's kernel
  compilation (the first round of a new configuration) is left out (:class:`RenderClock`).
* Per-sample data (``keep_samples=True``, not for references) holds the round's new samples only:
  name → N×H×W×C float32 with N the round's largest count; row ``j`` of a pixel is its ``j``-th
  new sample and rows past its count are zero.
* ``reference=True`` renders the reference stream (color, diffuse, specular only), never the noisy
  inputs' random numbers.

Notes:
    No Python loop runs over pixels: a round is one kernel launch per band of rows (more only past
    :data:`~denoisebench.generator.render.frame.MAX_PATHS_PER_PASS` paths) whose lanes loop over
    their pixel's range of sample indices. A lane of a pixel with fewer samples idles while the
    pixel with the most samples of its vector finishes, so very uneven maps cost somewhat more per
    sample than uniform ones: measured on a 128 px cornell frame, four rounds of counts drawn
    uniformly from 0-8 took 1.1-1.4x the time of four uniform rounds of 4 (same total; 2 busy
    cores). Rounds are replayed with ``dr.freeze`` like frames (uneven maps record once more).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from denoisebench.generator.render.frame import FrameStream


class RenderClock:
    """``perf_counter`` seconds minus Dr.Jit's kernel compilation so far: render time as a warm renderer pays it.

    Notes:
        Dr.Jit's kernel history (``JitFlag.KernelHistory``, switched on here) reports the LLVM
        compile time of every launch that missed the kernel cache; each call drains it and adds
        those times to :attr:`compile_seconds`, which it subtracts. Launches appear in the history
        once they ran, so read the clock after evaluating.
    """

    def __init__(self):
        import drjit as dr

        dr.set_flag(dr.JitFlag.KernelHistory, True)
        dr.kernel_history()  # drains (and so clears) the history of earlier launches
        self.compile_seconds = 0.0

    def __call__(self) -> float:
        import drjit as dr

        compile_ms = sum(
            float(entry.get("backend_time", 0.0)) for entry in dr.kernel_history() if not entry.get("cache_hit")
        )
        self.compile_seconds += compile_ms / 1000.0
        return time.perf_counter() - self.compile_seconds


@dataclass
class RoundBuffers:
    """What a round returns (module docstring, "Conventions").

    ``buffers``: accumulated per-pixel means, ``"color"``, ``"diffuse"``, ``"specular"`` and the
    plan's features (H×W×C float32), plus ``"<name>_var"`` (variance of the mean; inf where a pixel
    has no sample). ``counts``: H×W int32 samples per pixel so far. ``seconds``: render seconds of
    the last round. ``samples``: per-sample data of the last round when asked.
    """

    buffers: dict[str, np.ndarray]
    counts: np.ndarray
    seconds: float
    samples: dict[str, np.ndarray] | None = None


class ProgressiveFrame(FrameStream):
    """One frame rendered in rounds of per-pixel sample counts (module docstring).

    Built like its :class:`~denoisebench.generator.render.frame.FrameStream`: ``scene`` is a loaded
    Mitsuba scene, ``camera``/``frame``/``plan`` as for
    :func:`~denoisebench.generator.render.frame.render_frame`, ``width``/``height``/``seed`` by
    keyword (a sampler judged against a dataset should use a seed disjoint from the dataset's own),
    ``reference`` for the reference stream and ``keep_samples`` for per-sample data (default: the
    plan's ``per_sample``). Samplers call :meth:`render_round`; :attr:`counts` is what they got.
    """

    def render_round(self, counts: np.ndarray) -> RoundBuffers:
        """Trace ``counts`` (H×W ints >= 0) *additional* samples per pixel; return the accumulated buffers.

        Raises ``ValueError`` for a map of another shape, non-integers or negative counts.
        """
        counts = np.asarray(counts)
        if counts.shape != (self.height, self.width):
            raise ValueError(f"counts must be {self.height}x{self.width} (got shape {counts.shape})")
        if counts.dtype == bool or not np.issubdtype(counts.dtype, np.integer):
            raise ValueError(f"counts must be integers (got {counts.dtype})")
        if counts.size and counts.min() < 0:
            raise ValueError("counts must be >= 0")
        clock = RenderClock()
        started = clock()
        samples = self.advance(counts)
        buffers = self.buffers()
        return RoundBuffers(buffers=buffers, counts=self.counts, seconds=clock() - started, samples=samples)
