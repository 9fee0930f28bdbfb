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

The memory estimate (:func:`frame_memory_bytes`) is the peak of one frame in flight: float64
mean and M2 accumulators for every buffer channel (:data:`ACCUMULATOR_BYTES_PER_PIXEL`), the
render pass's path state (at most ``MAX_PATHS_PER_PASS`` paths of :data:`PATH_BYTES`) and, with
per-sample data, S×H×W float32 values of every per-sample channel
(:data:`SAMPLE_BYTES_PER_SAMPLE`). It is a lower bound of what rendering needs, so a refusal is
certain to be right; it is compared with ``MemAvailable`` (``/proc/meminfo``; physical memory
where that cannot be read) times the number of frames rendered at once.
"""

from __future__ import annotations

import os

from denoisebench.errors import UserInputError

MAX_SIDE = 16384
MAX_PIXELS = 1 << 26
MAX_SPP = 1 << 20
MAX_REF_SPP = 1 << 24
MAX_SPP_COUNTS = 32
MAX_FRAMES = 10_000
MAX_SCENES = 10_000

#: float64 mean + M2 of ~26 buffer channels (color, diffuse, specular, albedo, normal, depth,
#: position, roughness, motion) and a few counters.
ACCUMULATOR_BYTES_PER_PIXEL = 26 * 2 * 8 + 16
#: float32 per-sample channels (buffers + random parameters + second-hit features), per sample.
SAMPLE_BYTES_PER_SAMPLE = 40 * 4
#: Dr.Jit state of one path in a render pass (rays, throughput, moments), a conservative figure.
PATH_BYTES = 64
#: Paths per render pass (the feature renderer's MAX_PATHS_PER_PASS).
MAX_PATHS_PER_PASS = 1 << 22


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
    """Lower bound of the peak memory of rendering one frame (module docstring)."""
    pixels = width * height
    paths = min(pixels * max(max(spp), ref_spp), MAX_PATHS_PER_PASS)
    total = pixels * ACCUMULATOR_BYTES_PER_PIXEL + paths * PATH_BYTES
    if samples:
        total += pixels * max(spp) * SAMPLE_BYTES_PER_SAMPLE
    return total


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
    from denoisebench.dataset.errors import DatasetError

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
