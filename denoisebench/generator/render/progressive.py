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
* **Placed rounds** (for multidimensional samplers such as ``mdas``): besides count rounds,
  :meth:`ProgressiveFrame.render_placed` traces one sample at each position the caller gives, film
  ``x, y`` plus lens ``u, v`` and shutter ``t`` where the plan has them
  (:attr:`ProgressiveFrame.placement_dimensions`); :mod:`~denoisebench.generator.render.placed`
  has the conventions. The round's samples come back in request order in ``RoundBuffers.placed``
  (name → N×C: color, diffuse, specular, the features, ``pixel``/``lens``/``time``), and they are
  pooled into the pixels' buffers and counts. Count rounds never read placed state: a frame
  rendered with count rounds only has the same bytes whether or not placed rounds exist.

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

import threading
import time
import weakref
from dataclasses import dataclass

import numpy as np

from denoisebench.generator.render.frame import FrameStream, stream_key
from denoisebench.generator.render.placed import PLACED_STREAM, PlacedMoments, check_positions, trace_placed

#: Live :class:`RenderClock` objects; Dr.Jit's kernel history is on while there is one.
_LIVE_CLOCKS = 0
_LIVE_LOCK = threading.Lock()


def _release_clock() -> None:
    """A clock was collected: the last one switches the kernel history off and drops what it holds."""
    global _LIVE_CLOCKS
    import drjit as dr

    with _LIVE_LOCK:
        _LIVE_CLOCKS -= 1
        if _LIVE_CLOCKS == 0:
            dr.set_flag(dr.JitFlag.KernelHistory, False)
            dr.kernel_history()


class RenderClock:
    """``perf_counter`` seconds minus Dr.Jit's kernel compilation so far: render time as a warm renderer pays it.

    Notes:
        Dr.Jit's kernel history (``JitFlag.KernelHistory``, switched on here) reports the LLVM
        compile time of every launch that missed the kernel cache; each call drains it and adds
        those times to :attr:`compile_seconds`, which it subtracts. Launches appear in the history
        once they ran, so read the clock after evaluating.

        The history keeps every launch's kernel source (IR) until it is drained, cache hits
        included, so it is on only while a clock lives: when the last one is collected it is
        switched off and emptied. Left on, every later launch of the process (renders that read no
        clock) would keep its IR: gigabytes over a long process (a test run), and a copy of them
        all in Python when the next clock drains it.
    """

    def __init__(self):
        global _LIVE_CLOCKS
        import drjit as dr

        with _LIVE_LOCK:
            _LIVE_CLOCKS += 1
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            dr.kernel_history()  # drains (and so clears) the history of earlier launches
        weakref.finalize(self, _release_clock).atexit = False  # never call into Dr.Jit while it shuts down
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
    the last round. ``samples``: per-sample data of the last round when asked. ``placed``: a placed
    round's samples in request order (name → N×C), None after a count round.
    """

    buffers: dict[str, np.ndarray]
    counts: np.ndarray
    seconds: float
    samples: dict[str, np.ndarray] | None = None
    placed: dict[str, np.ndarray] | None = None


class ProgressiveFrame(FrameStream):
    """One frame rendered in rounds of per-pixel sample counts (module docstring).

    Built like its :class:`~denoisebench.generator.render.frame.FrameStream`: ``scene`` is a loaded
    Mitsuba scene, ``camera``/``frame``/``plan`` as for
    :func:`~denoisebench.generator.render.frame.render_frame`, ``width``/``height``/``seed`` by
    keyword (a sampler judged against a dataset should use a seed disjoint from the dataset's own),
    ``reference`` for the reference stream and ``keep_samples`` for per-sample data (default: the
    plan's ``per_sample``). Samplers call :meth:`render_round`; :attr:`counts` is what they got.
    """

    def __init__(self, scene, camera, frame: int, plan, *, seed: int, reference: bool = False, **options):
        super().__init__(scene, camera, frame, plan, seed=seed, reference=reference, **options)
        self._placed = None  # PlacedMoments once a placed round ran
        self._placed_key = stream_key(seed, frame, PLACED_STREAM + (1 if reference else 0))

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

    @property
    def placement_dimensions(self) -> tuple[str, ...]:
        """What a placed round takes beyond the film position: ``"lens"`` (thin lens), ``"time"`` (time sampling)."""
        return tuple(
            name for name, on in (("lens", self._switches.thin_lens), ("time", self._switches.time_sampling)) if on
        )

    @property
    def counts(self) -> np.ndarray:
        """H×W int32: samples per pixel so far, count and placed rounds together."""
        placed = self._placed
        return self._counts.astype(np.int32) if placed is None else (self._counts + placed.counts()).astype(np.int32)

    def buffers(self) -> dict[str, np.ndarray]:
        """The count rounds' buffers with the placed samples pooled in (the same bytes when there are none)."""
        out = super().buffers()
        placed = self._placed
        return out if placed is None or not placed.total else placed.merge(out, self._counts)

    def render_placed(self, film, lens=None, time=None) -> RoundBuffers:
        """Trace one sample at each position (module docstring, "Placed rounds"); the accumulated buffers.

        ``film`` N×2 (pixels), ``lens`` N×2 and ``time`` N (unit interval), each given exactly when it
        is one of :attr:`placement_dimensions`. Raises ``ValueError`` (one line) for anything else.
        """
        film, lens, time = check_positions(
            film, lens, time, width=self.width, height=self.height, dimensions=self.placement_dimensions
        )
        if self._placed is None:
            self._placed = PlacedMoments(self.width, self.height, self.stat_channels)
        names = dict(self.stat_channels)
        names["pixel"] = 2
        names.update({name: 2 if name == "lens" else 1 for name in self.placement_dimensions})
        clock = RenderClock()
        started = clock()
        values = trace_placed(
            self.scene,
            self._opts,
            self._switches,
            self._values,
            self._placed_key,
            film,
            lens,
            time,
            self._placed.total,
            names,
        )
        self._placed.add(film, values)
        buffers = self.buffers()
        return RoundBuffers(buffers=buffers, counts=self.counts, seconds=clock() - started, placed=values)
