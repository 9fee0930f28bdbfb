"""One pass of the feature renderer: the kernels that trace a band of rows and write its per-pixel buffers.

:func:`render_pass` traces samples ``start[p] .. end[p]`` of every pixel of a band, continuing each
lane's running moments (:mod:`~denoisebench.generator.render.moments`), and writes the pixels' buffers
(means and variances of the mean, as the host reads them); :func:`merge_pass` writes a fresh stream's
lanes as a smaller sample count (the rungs of a ladder below the lanes per pixel). Both are shaped by a hashable configuration (:class:`PassConfig`,
:class:`MergeConfig`); everything that varies per frame (stream key, rows, sample ranges, camera)
arrives as Dr.Jit inputs, so :func:`compiled_pass` records each configuration once per scene with
``dr.freeze`` and replays it for later frames (:data:`FREEZE_PASSES` off: every pass traced afresh, the
same bits). :class:`~denoisebench.generator.render.frame.FrameStream` and the placed rounds
(:mod:`~denoisebench.generator.render.placed`) run their passes through this cache.

Pitfalls: inputs must be fresh Dr.Jit allocations (:func:`device_copy`): inputs mapping NumPy memory
made replays record anew at random; sizes read with ``dr.width`` inside a pass would become constants
of the recording, hence the sizes in the configurations; recordings hold one scene's code inlined,
so another scene drops them all.
"""

from __future__ import annotations

import gc
from dataclasses import dataclass

import numpy as np

from denoisebench.generator.render.camera import CameraSwitches, DrCamera
from denoisebench.generator.render.moments import channel_type, pixel_buffers, render_moments, sample_stream
from denoisebench.generator.render.tracing import KernelOptions
from denoisebench.mitsuba_runtime import load_mitsuba


@dataclass(frozen=True)
class PassConfig:
    """Everything that shapes one pass's kernels (hashable); the numbers that vary per frame are not here."""

    opts: KernelOptions
    switches: CameraSwitches
    stat_channels: tuple  # (name, channels) of the per-pixel statistics, in output order
    sample_channels: tuple  # (name, channels) of per-sample data, () without
    band: int  # rows of the pass
    width: int
    count: int  # most samples a pixel gets in the pass: rows of the per-sample arrays (0 without them)
    groups: int  # lanes per pixel
    uniform: bool  # every pixel's sample range is the same: its range is in params, not per-pixel arrays
    fresh: bool  # the first pass of a stream: moments start at zero (made inside, not an input)


def render_pass(scene, params, ranges: tuple, state, camera_values: dict, config: PassConfig):
    """Trace samples ``start[p] .. end[p]`` of every pixel ``p`` of rows ``row0 .. row0 + band``.

    ``params`` is a UInt32 array ``[key0, key1, row0, start, end]`` (the frame's stream key, the
    band's first row and, when ``config.uniform``, every pixel's sample range); otherwise ``ranges``
    is ``(starts, ends)``, UInt32 per pixel of the band (row-major). ``state`` holds the lanes'
    moments so far (name → (mean, m2), one entry per lane; ``None`` when ``config.fresh``: the first
    pass starts from zeros made inside, so that single-pass renders have no state inputs at all).
    Returns ``(state, buffers, targets)``: the lanes' moments after the pass, the band's buffers of
    all samples so far (:func:`~denoisebench.generator.render.moments.pixel_buffers`: name → (mean,
    variance of the mean), H×W×C row-major), and the per-sample arrays (name → flat Float, row
    ``(s - starts[p]) * pixels + p``) or ``None``. Dr.Jit arrays, evaluated.
    """
    mi = load_mitsuba()
    import drjit as dr

    band, width, groups = config.band, config.width, config.groups
    stat_channels = dict(config.stat_channels)
    pixels = band * width
    lanes = pixels * groups
    cam = DrCamera(mi, config.switches, camera_values)
    # Pixel-major lanes (lane = pixel * groups + group): a pixel's lanes are one contiguous block.
    # Sizes enter as opaque values: as literals, every image size and spp would compile anew.
    groups_o, pixels_o, width_o = (dr.opaque(mi.UInt32, v) for v in (groups, pixels, width))
    # Scalars come in one array read at fixed positions: separate opaque scalars of equal value may
    # share a variable in one call and not in the next, and a frozen function's input layout
    # includes such aliasing (seen as recordings anew on every few replays).
    key0, key1, row0, start, end = (dr.gather(mi.UInt32, params, k) for k in range(5))
    if config.fresh:
        state = {
            k: (dr.zeros(channel_type(mi, c), lanes), dr.zeros(channel_type(mi, c), lanes))
            for k, c in stat_channels.items()
        }
    lane = dr.arange(mi.UInt32, lanes)
    pixel = lane // groups_o
    group = lane - pixel * groups_o
    px = pixel % width_o
    py = pixel // width_o + row0
    if not config.uniform:
        start, end = (dr.gather(mi.UInt32, r, pixel) for r in ranges)
    first = start + (group + groups_o - start % groups_o) % groups_o  # the lane's first sample >= start
    image_pixel = py * width_o + px  # bands cover whole rows: the pixel's index in the image
    targets = None
    if config.sample_channels:
        targets = {k: (dr.zeros(mi.Float, config.count * pixels * c), c) for k, c in config.sample_channels}
    state = render_moments(
        mi,
        scene,
        lambda s: sample_stream(mi, (key0, key1), image_pixel, s),
        cam,
        config.opts,
        px,
        py,
        first,
        end,
        groups_o,
        state,
        stat_channels,
        targets,
        lambda s: (s - start) * pixels_o + pixel,  # the pixel's sample within the pass, then pixel
    )
    if groups > 1:
        dr.eval(state, targets)  # one kernel traces everything; the merge gathers from its results
    samples_so_far = end if config.uniform else ranges[1]  # per pixel (the lanes' `end` is per lane)
    buffers = pixel_buffers(mi, state, stat_channels, groups, samples_so_far)
    targets = None if targets is None else {k: target for k, (target, _) in targets.items()}
    # One lane per pixel: tracing and writing the buffers are a single kernel. Several: the merge kernel.
    dr.eval(state, buffers, targets)
    return state, buffers, targets


@dataclass(frozen=True)
class MergeConfig:
    """What shapes a :func:`merge_pass` (hashable)."""

    stat_channels: tuple
    band: int
    width: int
    groups: int


def merge_pass(scene, params, state, config: MergeConfig):
    """The buffers of ``state`` (a band's lanes) counted as ``params[0]`` samples per pixel (:func:`render_pass`'s).

    Right where every lane holds at most one sample (a fresh stream of at most ``groups`` samples):
    lane ``g`` then holds sample ``g`` and the merge weighs lanes ``g >= params[0]`` by 0, so the
    result is the bits a stream of ``params[0]`` samples writes (:meth:`FrameStream.prefix_buffers`).
    ``scene`` is unused (the compiled-pass cache is per scene).
    """
    mi = load_mitsuba()
    import drjit as dr

    total = dr.gather(mi.UInt32, params, 0)
    buffers = pixel_buffers(mi, state, dict(config.stat_channels), config.groups, total)
    dr.eval(buffers)
    return buffers


#: Record passes with ``dr.freeze`` and replay them (False: trace every pass afresh; same bits).
FREEZE_PASSES = True


#: Passes compiled with ``dr.freeze`` for the most recent scene, one per :class:`PassConfig`, oldest first.
_COMPILED: dict = {}


_COMPILED_SCENE: list = [None]  # the scene they were recorded with (a strong reference: see below)


#: Most pass configurations kept compiled at once (each holds its recorded kernels).
MAX_COMPILED_PASSES = 8


def compiled_pass(scene, config, function=render_pass):
    """The frozen (``dr.freeze``) ``function`` (:func:`render_pass`, or :func:`merge_pass` for a
    :class:`MergeConfig`) for ``scene`` and ``config``.

    Notes:
        Tracing the Python integrator costs ~10-20 ms per pass and assembling its ~6000-op
        kernel a few more, which on a 64x64 16-spp frame was a sixth of the time; a frozen function
        records the kernel launches once and replays them for later frames, whose camera and seed
        arrive as Dr.Jit inputs. A replay launches the very kernels a fresh trace would (the tests
        compare the two bit for bit).

        One frozen function per configuration: a single one that alternated between two (noisy and
        reference frames) re-recorded on every call. Every input array is a fresh Dr.Jit allocation
        (:func:`device_copy`): inputs that map NumPy memory made replays record anew at random. Image sizes are in the configuration because
        sizes taken with ``dr.width`` inside become constants of the recording.

        Recordings are only reused for the scene object they were made with (its BSDF and shape
        code is inlined in the kernels): a different scene drops them all. The module keeps that
        scene alive, so that no new scene can ever reuse its ``id``; one scene at most.
    """
    import drjit as dr

    if not FREEZE_PASSES:
        return function
    if _COMPILED_SCENE[0] is not scene:
        _COMPILED.clear()
        _COMPILED_SCENE[0] = scene
    compiled = _COMPILED.pop(config, None)
    if compiled is None:
        compiled = _FreezeOrTrace(dr.freeze(function, warn_after=2), function)
        while len(_COMPILED) >= MAX_COMPILED_PASSES:
            _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[config] = compiled  # most recently used last
    return compiled


def forget_scene() -> None:
    """Drop the compiled passes and the scene they hold alive (:func:`compiled_pass`'s Notes).

    For a process that is done with a scene and renders another through something else (e.g.
    Mitsuba's own integrators, as bench/render_throughput.py does): a live scene's shapes and BSDFs
    stay among the instances every Dr.Jit virtual call dispatches over.
    """
    _COMPILED.clear()
    _COMPILED_SCENE[0] = None


class _FreezeOrTrace:
    """A frozen pass that falls back to plain tracing where Dr.Jit refuses to record it.

    Notes:
        Dr.Jit validates a recording: a virtual call whose instances are not among the function's
        inputs aborts it. That happens when the scene has no instance of a domain (a scene without
        emitters) while other live scenes have some: the call is then over *their* instances. The
        pass is traced normally instead (same kernels, same bits), for good for this configuration.
    """

    def __init__(self, frozen, function=render_pass):
        self.frozen, self.function = frozen, function

    def __call__(self, *args):
        if self.frozen is not None:
            # Python's cyclic collector must not free Dr.Jit objects left by an earlier mi.load_file or
            # mi.render while a pass records: Dr.Jit aborts the process then (seen with Mitsuba XML
            # scenes loaded in the same process). No collection runs during the call; none is lost.
            enabled = gc.isenabled()
            gc.disable()
            try:
                return self.frozen(*args)
            except RuntimeError as error:
                if "frozen function" not in str(error):
                    raise
                self.frozen = None
            finally:
                if enabled:
                    gc.enable()
        return self.function(*args)


def lane_groups(band: int, width: int, target_lanes: int) -> int:
    """Lanes per pixel for a band: enough lanes to keep every core busy on small images (never spp-dependent)."""
    return max(1, -(-target_lanes // (band * width)))


def device_copy(mi, kind, values: np.ndarray):
    """``values`` (1-D) as an evaluated Dr.Jit array of ``kind`` in memory Dr.Jit allocated, distinct from every other.

    Notes:
        ``kind(numpy_array)`` maps the NumPy buffer, and a frozen function's input layout includes
        whether each buffer is aligned (render/camera.py ``_float_array``): mapped inputs made
        replays record anew, at random (NumPy's alignment varies). Adding an opaque zero runs a
        kernel that writes a fresh Dr.Jit array (fast for large arrays, unlike going through a
        list); a gather by ``arange`` did not do it (Dr.Jit returned the mapped array itself).
        A few values (a pass's scalars) go through a list: a copy without a kernel launch, which
        in a ladder's pipelined rounds also queued behind the running pass.
    """
    import drjit as dr

    if 1 < values.size <= 16:  # a pass's few scalars: copied from a list, without a kernel (one element: a literal)
        copy = kind(values.tolist())
    else:
        mapped = kind(values)
        copy = mapped + dr.opaque(kind, 0)  # a kernel writes a fresh array (an opaque 0 is not folded away)
    dr.eval(copy)
    return copy
