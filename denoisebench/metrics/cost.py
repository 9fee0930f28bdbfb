"""What a call costs: wall seconds, seconds per megapixel, peak memory; total time of a result.

Notes
-----
* ``measure_call`` times one call with ``time.perf_counter`` and, unless ``trace_memory=False``,
  records the peak of Python-visible allocations during the call with ``tracemalloc`` (numpy
  buffers included). Memory that native libraries allocate themselves (FLIP's C++ images, a torch
  CPU allocator, OpenMP stacks) is **not** seen: ``peak_bytes`` is a lower bound for those.
  Tracing slows allocation-heavy *Python* code; numpy-bound calls are barely affected. Use
  ``trace_memory=False`` for timings that must not carry that overhead.
* If tracemalloc was already tracing, it is left running and the peak is measured from the
  current traced size (``tracemalloc.reset_peak``).
* Total cost of a denoised frame (docs/architecture.md): render seconds at the input spp + denoise seconds,
  ``total_seconds(render_seconds_per_spp, spp, denoise_seconds)``.
"""

from __future__ import annotations

import math
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "CallCost",
    "measure_call",
    "megapixels",
    "seconds_per_megapixel",
    "total_seconds",
    "CostSummary",
    "summarize_costs",
]


@dataclass(frozen=True)
class CallCost:
    """Wall seconds and traced peak bytes of one call, and what it returned."""

    seconds: float
    peak_bytes: int
    result: Any = field(default=None, repr=False, compare=False)


def measure_call(fn: Callable, *args, trace_memory: bool = True, **kwargs) -> CallCost:
    """Call ``fn(*args, **kwargs)`` once; return its wall seconds and peak traced memory.

    ``peak_bytes`` is 0 when ``trace_memory`` is False. Exceptions from ``fn`` propagate (tracing
    is stopped first when this function started it).
    """
    started_tracing = False
    baseline = 0
    if trace_memory:
        if tracemalloc.is_tracing():
            tracemalloc.reset_peak()
            baseline = tracemalloc.get_traced_memory()[0]
        else:
            tracemalloc.start()
            started_tracing = True
    try:
        t0 = time.perf_counter()
        result = fn(*args, **kwargs)
        seconds = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1] - baseline if trace_memory else 0
    finally:
        if started_tracing:
            tracemalloc.stop()
    return CallCost(seconds=seconds, peak_bytes=max(int(peak), 0), result=result)


def megapixels(shape_or_pixels) -> float:
    """Megapixels of an H×W(×C) shape, an (H, W) pair, or a pixel count."""
    if isinstance(shape_or_pixels, (int, float)):
        pixels = float(shape_or_pixels)
    else:
        dims = tuple(shape_or_pixels)
        if len(dims) < 2:
            raise ValueError(f"need an (H, W, ...) shape or a pixel count, got {shape_or_pixels!r}")
        pixels = float(dims[0]) * float(dims[1])
    if not (math.isfinite(pixels) and pixels > 0):
        raise ValueError(f"pixel count must be finite and positive, got {pixels}")
    return pixels / 1e6


def seconds_per_megapixel(seconds: float, shape_or_pixels) -> float:
    """``seconds`` per megapixel of an image of the given shape (or pixel count)."""
    return float(seconds) / megapixels(shape_or_pixels)


def total_seconds(render_seconds_per_spp: float, spp: float, denoise_seconds: float) -> float:
    """Time of a denoised frame: render seconds at the input spp plus denoise seconds."""
    values = (render_seconds_per_spp, spp, denoise_seconds)
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise ValueError(f"times and spp must be finite and ≥ 0, got {values}")
    return render_seconds_per_spp * spp + denoise_seconds


@dataclass(frozen=True)
class CostSummary:
    """Per-frame and per-megapixel seconds of a run of frames, and the largest traced peak."""

    frames: int
    seconds_per_frame: float
    seconds_per_megapixel: float
    peak_bytes: int


def summarize_costs(costs: list[CallCost], shape) -> CostSummary:
    """Mean seconds per frame and per megapixel over ``costs`` (one per frame of ``shape``)."""
    if not costs:
        raise ValueError("no calls to summarize")
    mean = sum(c.seconds for c in costs) / len(costs)
    return CostSummary(
        frames=len(costs),
        seconds_per_frame=mean,
        seconds_per_megapixel=seconds_per_megapixel(mean, shape),
        peak_bytes=max(c.peak_bytes for c in costs),
    )
