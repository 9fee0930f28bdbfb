"""Upper bounds on what a dataset may ask for, and a memory estimate checked before allocation.

Both sides are untrusted input: the command line of ``generate-dataset`` (``--spp 1000000000000``
once planned 10⁹ render passes and was killed by the kernel at 24 GB; ``--frames 100000000``
ran 300 s at 1.8 GB before writing anything) and the manifest a benchmark reads (a forged
``frames`` or ``width`` must not make the harness loop or allocate for ever). Every bound is far
above what a denoising dataset needs:

=======================  ====================  ===========================================
bound                    value                 applies to
=======================  ====================  ===========================================
:data:`MAX_SIDE`         16384 pixels          width, height
:data:`MAX_PIXELS`       2²⁶ (8192×8192)       width × height
:data:`MAX_SPP`          2²⁰ (1 048 576)       each noisy spp
:data:`MAX_REF_SPP`      2²⁴ (16 777 216)      reference spp (the cap of adaptive references)
:data:`MAX_SPP_COUNTS`   32                    how many noisy spp values
:data:`MAX_FRAMES`       10 000                frames per scene
:data:`MAX_SCENES`       10 000                scenes per family (and scenes in a manifest)
=======================  ====================  ===========================================

The memory estimate (:func:`frame_memory_bytes`) is the peak of one frame in flight, counted from
what the renderer allocates (render/frame.py ``FrameStream`` and ``render_ladder``, then the
reference while the noisy rungs wait to be written):

* held until the frame is written: every rung's buffers (H×W float32 means and variances of
  :data:`NOISY_CHANNELS`) and, with per-sample data, the top rung's S×H×W samples
  (:data:`SAMPLE_BYTES_PER_SAMPLE` per sample and pixel; the rungs' samples are views of it);
* the noisy stream while it renders: the lanes' float32 mean and M2 of every channel (one lane
  per pixel, more on small images: ``TARGET_LANES``), in and out of a pass; the buffers the running
  round's last pass writes (the next rung traces while a rung is handed out; the host reads the
  device's buffers without a copy, so a held rung is that memory); with per-sample data the largest round's host arrays
  and two passes' device arrays;
* then the reference stream (:data:`REFERENCE_CHANNELS`) and its buffers, in place of the noisy one.

Dr.Jit rounds every allocation up to a power of two, and each channel of the lanes' moments is
its own array, so device arrays are counted that way. Left out: the scene, the interpreter and
libraries, kernels' registers, an adaptive reference's extra rounds and the EXR writer's
buffers; tests/generator/render/test_memory_estimate.py measures a small frame's peaks (``tracemalloc`` and Dr.Jit's
allocation watermark) at 1-2x the estimate. It is compared with ``MemAvailable``
(``/proc/meminfo``; physical memory where that cannot be read) times the number of frames
rendered at once.
"""

from __future__ import annotations

import os

from denoisebench.dataset.errors import DatasetError
from denoisebench.errors import UserInputError

MAX_SIDE = 16384
MAX_PIXELS = 1 << 26
MAX_SPP = 1 << 20
MAX_REF_SPP = 1 << 24
MAX_SPP_COUNTS = 32
MAX_FRAMES = 10_000
MAX_SCENES = 10_000

#: Channels of the noisy stream's moments and buffers: color, diffuse, specular (3 each) and every
#: feature (albedo 3, normal 3, depth 1, position 3, roughness 1, motion 2), as render/frame.py renders them.
NOISY_CHANNELS = 22
#: Channels of the reference stream: color, diffuse, specular.
REFERENCE_CHANNELS = 9
#: float32 per-sample channels every per-sample plan holds: the 8 buffers (20 channels) and the
#: pixel offset (2); bounces, thin lens and motion blur add up to 13 more.
SAMPLE_CHANNELS = 22
SAMPLE_BYTES_PER_SAMPLE = SAMPLE_CHANNELS * 4
#: Paths per render pass and lanes per pass aimed at (the feature renderer's MAX_PATHS_PER_PASS and
#: TARGET_LANES; tests/generator/render/test_memory_estimate.py checks they agree).
MAX_PATHS_PER_PASS = 1 << 22
TARGET_LANES = 1 << 14


def _device(nbytes: int) -> int:
    """Bytes Dr.Jit allocates for an array of ``nbytes``: the next power of two."""
    return 1 << max(0, int(nbytes) - 1).bit_length() if nbytes > 0 else 0


def _bands(width: int, height: int) -> tuple[list[tuple[int, int]], int]:
    """``([(pixels, lanes per pixel) per band of rows], samples per pixel per pass)`` as the renderer splits a frame."""
    rows = max(1, min(height, MAX_PATHS_PER_PASS // width))
    bands = [min(rows, height - row0) * width for row0 in range(0, height, rows)]
    return [(b, max(1, -(-TARGET_LANES // b))) for b in bands], max(1, MAX_PATHS_PER_PASS // (rows * width))


def _stream_bytes(width: int, height: int, channels: int) -> int:
    """A stream's moments while it renders (module docstring): device lanes' moments and the running round's buffers."""
    bands, _ = _bands(width, height)
    lanes = sum(_device(pixels * groups * 4) * 2 * channels for pixels, groups in bands)  # every band's lanes
    largest = max(_device(pixels * groups * 4) * 2 * channels for pixels, groups in bands)  # a pass's new ones
    packed = sum(_device(pixels * 2 * channels * 4) for pixels, _ in bands)
    return lanes + largest + packed


def _rounds(width: int, height: int, rungs: list[int]) -> list[int]:
    """Sample counts after each round of ``render_ladder``: rungs below the lanes per pixel share the first."""
    bands, _ = _bands(width, height)
    first = min(min(groups for _, groups in bands), rungs[-1])
    head = {k for k in rungs if k < first}
    return sorted({first, *rungs} - head) if head else rungs


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB"


def check_size(width: int, height: int, what: str = "--width/--height") -> None:
    if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
        raise UserInputError(f"{what} must be 1..{MAX_SIDE} pixels (got {width}x{height})")
    if width * height > MAX_PIXELS:
        raise UserInputError(f"{what} {width}x{height} is over {MAX_PIXELS} pixels per frame")


def check_counts(*, scenes: int, frames: int, spp, ref_spp: int, option_prefix: str = "--") -> None:
    """UserInputError (one line) for a count outside its documented bound."""
    spp = list(spp)
    if not 1 <= frames <= MAX_FRAMES:
        raise UserInputError(f"{option_prefix}frames must be 1..{MAX_FRAMES} (got {frames})")
    if not 1 <= scenes <= MAX_SCENES:
        raise UserInputError(f"{option_prefix}scenes must be 1..{MAX_SCENES} (got {scenes})")
    if len(spp) > MAX_SPP_COUNTS:
        raise UserInputError(f"{option_prefix}spp takes at most {MAX_SPP_COUNTS} values (got {len(spp)})")
    if spp and max(spp) > MAX_SPP:
        raise UserInputError(f"{option_prefix}spp at most {MAX_SPP} samples per pixel (got {max(spp)})")
    if ref_spp > MAX_REF_SPP:
        raise UserInputError(f"{option_prefix}ref-spp at most {MAX_REF_SPP} samples per pixel (got {ref_spp})")


def frame_memory_bytes(width: int, height: int, spp, ref_spp: int, samples: bool) -> int:
    """Peak memory of rendering one frame, as the renderer allocates it (module docstring)."""
    pixels = width * height
    rungs = sorted({int(k) for k in spp})
    held = len(rungs) * pixels * 2 * NOISY_CHANNELS * 4
    noisy = _stream_bytes(width, height, NOISY_CHANNELS) if rungs else 0
    if samples and rungs:
        held += pixels * rungs[-1] * SAMPLE_BYTES_PER_SAMPLE
        rounds = _rounds(width, height, rungs)
        largest = max(b - a for a, b in zip([0, *rounds], rounds))
        bands, chunk = _bands(width, height)
        per_pass = _device(min(largest, chunk) * max(p for p, _ in bands) * SAMPLE_BYTES_PER_SAMPLE)
        noisy += pixels * largest * SAMPLE_BYTES_PER_SAMPLE + 2 * per_pass
    reference = 0
    if ref_spp:
        reference = _stream_bytes(width, height, REFERENCE_CHANNELS) + pixels * 2 * REFERENCE_CHANNELS * 4
    return held + max(noisy, reference)


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (MemAvailable), or physical memory, or None."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(width: int, height: int, spp, ref_spp: int, samples: bool, *, in_flight: int = 1) -> int:
    """UserInputError when the estimate for ``in_flight`` frames exceeds the available memory."""
    need = frame_memory_bytes(width, height, spp, ref_spp, samples) * max(1, in_flight)
    have = available_memory()
    if have is not None and need > have:
        detail = f" with --samples at {max(spp)} spp" if samples else ""
        raise UserInputError(
            f"{width}x{height}{detail} needs at least {_gib(need)} of memory per frame in flight "
            f"(x{in_flight}), this machine has {_gib(have)} available: lower --width/--height"
            + (", --spp or drop --samples" if samples else "")
        )
    return need


def check_generate(*, width: int, height: int, scenes: int, frames: int, spp, ref_spp: int, samples: bool) -> None:
    """Every bound and the memory estimate of a generate request, before anything is allocated."""
    check_size(width, height)
    check_counts(scenes=scenes, frames=frames, spp=spp, ref_spp=ref_spp)
    check_memory(width, height, spp, ref_spp, samples)


def check_scene_record(scene: str, record: dict) -> None:
    """A manifest's scene record within the bounds (a forged one is refused before it is read)."""
    try:
        width, height, frames = int(record["width"]), int(record["height"]), int(record["frames"])
        spp = [int(s) for s in record["spp"]]
    except (KeyError, TypeError, ValueError) as error:
        raise DatasetError(f"scene {scene!r}: malformed manifest record ({type(error).__name__}: {error})") from None
    try:
        check_size(width, height, f"scene {scene!r} size")
        check_counts(
            scenes=1, frames=frames, spp=spp, ref_spp=int(record.get("ref_spp") or 0), option_prefix=f"scene {scene!r} "
        )
    except UserInputError as error:
        raise DatasetError(f"manifest out of bounds: {error}") from None
