"""Render one frame's buffers (DESIGN.md, "Buffers") in one pass with our own Dr.Jit path tracer.

:func:`render_frame` is what the dataset writer calls. It generates camera rays itself
(:mod:`~denoisebench.generator.render.camera`: box pixel filter, pinhole or thin lens, camera motion
blur) and traces them with :mod:`~denoisebench.generator.render.integrator`, an unbiased estimator
of the image Mitsuba's ``path`` integrator renders at the same ``max_depth``, which also yields the
diffuse/specular split and every feature. One kernel per pass computes all of it: each lane loops over
samples of its pixel keeping running (Welford) moments, and when a small image gives a pixel several
lanes their moments are merged on the device, so only per-pixel values (and per-sample data, when
asked) reach the host.

Conventions:

* Buffers are H×W×C float32: color, diffuse, specular, albedo, normal, depth (1), position,
  roughness (1), motion (2), and ``<name>_var`` for each: the variance of the per-pixel *mean*,
  i.e. the unbiased sample variance divided by spp (0 when spp is 1: unknown, but finite).
* Feature means are averages over the pixel's samples (anti-aliased), like color.
* Per-sample data (``plan.per_sample`` and not ``reference``) is S×H×W×C per buffer, plus the
  random parameters that exist in the plan, as the uniform numbers that drove them: ``pixel`` (the
  sub-pixel offset in [0,1)²), ``lens`` (the square sample in [0,1)² mapped to the disk; thin lens
  only), ``time`` (the shutter fraction in [0,1); motion blur only). When paths bounce (max_depth
  not 1) it also holds :data:`SECOND_HIT_CHANNELS` for RPF: ``light`` and ``bounce`` (the first
  vertex's light-sample and bounce-direction random numbers in [0,1)²) and ``position2``/``normal2``
  (where the first bounce lands; 0 on a miss). Images are the same bytes with or without them.
* ``reference=True``: color, diffuse and specular with their variances only (no features), from an
  independent random stream.
* Seeds: each pass seeds Mitsuba's ``independent`` sampler with a 32-bit hash (BLAKE2b) of
  ``(seed, frame, spp, stream, pass)`` where stream is 0 for noisy and 1 for reference renders, so
  frames, sample counts and the reference never share random numbers, and the same arguments give
  bit-identical buffers.
* Each pass configuration (kernel options, camera switches, buffers, band and sample sizes) is
  recorded once per scene with ``dr.freeze`` and replayed for later frames, whose camera and seed
  are the recording's inputs: a replay launches the kernels a fresh trace would, so bytes do not
  depend on it (:data:`FREEZE_PASSES` turns it off; tests/test_render_frozen.py compares the two).
* Passes hold at most :data:`MAX_PATHS_PER_PASS` paths: a frame is split into bands of rows and
  chunks of samples, whose statistics are merged exactly (Chan et al.'s pairwise update).
* Random numbers depend on the pass layout (:data:`MAX_PATHS_PER_PASS`, ``target_lanes``), which
  is fixed, never derived from the core count (vector width may still change float rounding).
"""

from __future__ import annotations

import hashlib
import struct
import time as _time
from dataclasses import dataclass, replace

import numpy as np

from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.render_plan import RenderPlan
from denoisebench.generator.render.camera import CameraSwitches, DrCamera, camera_setup, camera_switches, camera_values
from denoisebench.generator.render.integrator import (
    NULL_SKIPS,
    KernelOptions,
    moment_layout,
    pixel_moments,
    render_moments,
    scene_has_delta_only_bsdf,
    scene_has_null_bsdf,
    scene_has_object_motion,
)
from denoisebench.mitsuba_runtime import load_mitsuba

#: Most paths traced by one kernel launch (bounds per-sample memory and the length of one launch).
MAX_PATHS_PER_PASS = 1 << 22
#: Lanes per launch to aim for: each lane loops over several samples of its pixel, keeping running
#: moments, and a pixel gets several lanes only when the image is small (so that every core has
#: work). Fewer, longer lanes mean less output and merging: on 2 cores, 64×64 at 16 spp took ~15%
#: less CPU time with 16K lanes than with 64K (bench/render_throughput.py). A constant, not a
#: function of the core count: lanes decide which random numbers a sample gets, and a frame must
#: be the same bytes on every machine.
TARGET_LANES = 1 << 14

#: Channels of each per-sample buffer, in output order.
SAMPLE_BUFFERS = {
    "color": 3,
    "diffuse": 3,
    "specular": 3,
    "albedo": 3,
    "normal": 3,
    "depth": 1,
    "position": 3,
    "roughness": 1,
}
RANDOM_PARAMETER_CHANNELS = {"pixel": 2, "lens": 2, "time": 1}
#: Per-sample channels of paths that bounce (render_integrator's ``second_hit``): the first vertex's
#: light-sample and bounce-direction random numbers, and the bounce ray's hit point and normal.
SECOND_HIT_CHANNELS = {"light": 2, "bounce": 2, "position2": 3, "normal2": 3}
FEATURES = ("albedo", "normal", "depth", "position", "roughness", "motion")
FEATURE_CHANNELS = {"albedo": 3, "normal": 3, "depth": 1, "position": 3, "roughness": 1, "motion": 2}

NOISY_STREAM = 0
REFERENCE_STREAM = 1


@dataclass(frozen=True)
class _PassConfig:
    """Everything that shapes one pass's kernels (hashable); the numbers that vary per frame are not here."""

    opts: KernelOptions
    switches: CameraSwitches
    stat_channels: tuple  # (name, channels) of the per-pixel statistics, in output order
    sample_channels: tuple  # (name, channels) of per-sample data, () without
    band: int  # rows of the pass
    width: int
    count: int  # samples per pixel in the pass
    groups: int  # lanes per pixel


def _render_pass(scene, seed, row0, camera_values: dict, config: _PassConfig):
    """Trace one pass: ``config.count`` samples of every pixel of rows ``row0 .. row0 + band``.

    Returns ``(packed, targets)``: the per-pixel moments packed as :func:`moment_layout` says, and
    the per-sample arrays (name → flat Float, sample-major) or ``None``. Dr.Jit arrays, evaluated.
    """
    mi = load_mitsuba()
    import drjit as dr

    band, width, count, groups = config.band, config.width, config.count, config.groups
    stat_channels = dict(config.stat_channels)
    pixels = band * width
    base, rem = divmod(count, groups)
    lanes = pixels * groups
    cam = DrCamera(mi, config.switches, camera_values)
    sampler = mi.load_dict({"type": "independent", "sample_count": 1})
    sampler.seed(seed, lanes)
    # Pixel-major lanes (lane = pixel * groups + group): a pixel's lanes are one contiguous block.
    # Sizes enter as opaque values: as literals, every image size and spp would compile anew.
    groups_o, pixels_o, width_o = (dr.opaque(mi.UInt32, v) for v in (groups, pixels, width))
    lane = dr.arange(mi.UInt32, lanes)
    pixel = lane // groups_o
    group = lane - pixel * groups_o
    px = pixel % width_o
    py = pixel // width_o + row0
    lane_count = dr.opaque(mi.UInt32, base) + dr.select(group < dr.opaque(mi.UInt32, rem), mi.UInt32(1), mi.UInt32(0))
    targets = None
    if config.sample_channels:
        targets = {k: (dr.zeros(mi.Float, count * pixels * c), c) for k, c in config.sample_channels}
    moments_dr = render_moments(
        mi,
        scene,
        sampler,
        cam,
        config.opts,
        px,
        py,
        lane_count,
        stat_channels,
        targets,
        lambda s: (group + s * groups_o) * pixels_o + pixel,  # sample index within the pass, then pixel
    )
    if groups > 1:
        dr.eval(moments_dr, targets)  # one kernel traces everything; the merge gathers from its results
    packed, _ = pixel_moments(mi, moments_dr, stat_channels, groups, base, rem, count)
    targets = None if targets is None else {k: target for k, (target, _) in targets.items()}
    # One lane per pixel: tracing and packing are a single kernel. Several: the merge kernel.
    dr.eval(packed, targets)
    return packed, targets


#: Record passes with ``dr.freeze`` and replay them (False: trace every pass afresh; same bits).
FREEZE_PASSES = True
#: Passes compiled with ``dr.freeze`` for the most recent scene, one per :class:`_PassConfig`, oldest first.
_COMPILED: dict = {}
_COMPILED_SCENE: list = [None]  # the scene they were recorded with (a strong reference: see below)
#: Most pass configurations kept compiled at once (each holds its recorded kernels).
MAX_COMPILED_PASSES = 8


def _compiled_pass(scene, config: _PassConfig):
    """The frozen (``dr.freeze``) :func:`_render_pass` for ``scene`` and ``config``.

    Notes:
        Tracing the Python integrator costs ~10-20 ms per pass and assembling its ~6000-op
        kernel a few more, which on a 64x64 16-spp frame was a sixth of the time; a frozen function
        records the kernel launches once and replays them for later frames, whose camera and seed
        arrive as Dr.Jit inputs. A replay launches the very kernels a fresh trace would (the tests
        compare the two bit for bit).

        One frozen function per configuration: a single one that alternated between two (noisy and
        reference frames) re-recorded on every call. Image sizes are in the configuration because
        sizes taken with ``dr.width`` inside become constants of the recording.

        Recordings are only reused for the scene object they were made with (its BSDF and shape
        code is inlined in the kernels): a different scene drops them all. The module keeps that
        scene alive, so that no new scene can ever reuse its ``id``; one scene at most.
    """
    import drjit as dr

    if not FREEZE_PASSES:
        return _render_pass
    if _COMPILED_SCENE[0] is not scene:
        _COMPILED.clear()
        _COMPILED_SCENE[0] = scene
    function = _COMPILED.pop(config, None)
    if function is None:
        function = _FreezeOrTrace(dr.freeze(_render_pass, warn_after=2))
        while len(_COMPILED) >= MAX_COMPILED_PASSES:
            _COMPILED.pop(next(iter(_COMPILED)))
    _COMPILED[config] = function  # most recently used last
    return function


class _FreezeOrTrace:
    """A frozen pass that falls back to plain tracing where Dr.Jit refuses to record it.

    Notes:
        Dr.Jit validates a recording: a virtual call whose instances are not among the function's
        inputs aborts it. That happens when the scene has no instance of a domain (a scene without
        emitters) while other live scenes have some: the call is then over *their* instances. The
        pass is traced normally instead (same kernels, same bits), for good for this configuration.
    """

    def __init__(self, frozen):
        self.frozen = frozen

    def __call__(self, *args):
        if self.frozen is not None:
            try:
                return self.frozen(*args)
            except RuntimeError as error:
                if "frozen function" not in str(error):
                    raise
                self.frozen = None
        return _render_pass(*args)


@dataclass
class RenderedFrame:
    """The buffers of one frame (see the module docstring for their conventions)."""

    buffers: dict[str, np.ndarray]
    samples: dict[str, np.ndarray] | None
    seconds: float
    spp: int


def load_scene(scene_dict: dict):
    """Load a Mitsuba scene from a dict (no sensor needed: rays are ours)."""
    mi = load_mitsuba()
    return mi.load_dict(scene_dict)


def derive_seed(seed: int, frame: int, spp: int, stream: int, pass_index: int = 0) -> int:
    """32-bit sampler seed for one pass: a hash of everything that must decorrelate renders."""
    data = struct.pack("<qqqqq", int(seed), int(frame), int(spp), int(stream), int(pass_index))
    return int.from_bytes(hashlib.blake2b(data, digest_size=4).digest(), "little")


class _Moments:
    """Per-pixel mean and sum of squared deviations of one buffer (float64), merged pass by pass."""

    def __init__(self, height: int, width: int, channels: int):
        self.mean = np.zeros((height, width, channels))
        self.m2 = np.zeros((height, width, channels))

    def add(self, rows: slice, before: int, count: int, mean_b: np.ndarray, m2_b: np.ndarray) -> None:
        """Merge ``count`` new samples per pixel of ``rows`` (their mean and M2) into ``before`` ones."""
        if before == 0:
            self.mean[rows] = mean_b
            self.m2[rows] = m2_b
        else:
            total = before + count
            delta = mean_b - self.mean[rows]
            self.mean[rows] += delta * (count / total)
            self.m2[rows] += m2_b + np.square(delta) * (before * count / total)

    def finish(self, spp: int):
        mean = self.mean.astype(np.float32)
        if spp > 1:
            var = (np.maximum(self.m2, 0.0) / ((spp - 1) * spp)).astype(np.float32)
        else:
            var = np.zeros_like(mean)
        return mean, var


def _plan_passes(height: int, width: int, spp: int, max_paths: int):
    """(row0, rows, sample0, samples) of every pass, rows outermost."""
    rows = max(1, min(height, max_paths // width))
    chunk = max(1, min(spp, max_paths // (rows * width)))
    passes = []
    for row0 in range(0, height, rows):
        band = min(rows, height - row0)
        for s0 in range(0, spp, chunk):
            passes.append((row0, band, s0, min(chunk, spp - s0)))
    return passes


def render_frame(
    scene,
    camera: CameraTrack,
    frame: int,
    plan: RenderPlan,
    *,
    width: int,
    height: int,
    spp: int,
    seed: int,
    reference: bool = False,
    max_paths_per_pass: int = MAX_PATHS_PER_PASS,
    target_lanes: int = TARGET_LANES,
    _jitter: bool = True,
) -> RenderedFrame:
    """Render ``frame`` of ``camera`` with ``spp`` samples per pixel; see the module docstring.

    ``target_lanes`` overrides how many lanes one launch aims for (:data:`TARGET_LANES`); it
    changes which random numbers each sample gets, not the estimator.

    ``_jitter=False`` puts every sample at its pixel center (tests compare features with Mitsuba's
    ``aov`` integrator that way); it is not meant for datasets.
    """
    start = _time.perf_counter()
    if spp < 1:
        raise ValueError(f"spp must be >= 1 (got {spp})")
    mi = load_mitsuba()
    import drjit as dr

    setup = camera_setup(camera, frame, plan, width, height)
    features = () if reference else tuple(f for f in FEATURES if f in plan.features)
    want_motion = "motion" in features and setup.has_previous
    opts = KernelOptions(
        max_depth=int(plan.max_depth),
        rr_depth=int(plan.rr_depth),
        lobe_split=bool(plan.lobe_split),
        features=bool(features),
        motion=want_motion,
        object_motion=want_motion and scene_has_object_motion(scene),
        null_skips=NULL_SKIPS if scene_has_null_bsdf(mi, scene) else 0,
        follow_delta_albedo="albedo" in features and scene_has_delta_only_bsdf(mi, scene),
        jitter=_jitter,
    )
    stream = REFERENCE_STREAM if reference else NOISY_STREAM
    keep_samples = plan.per_sample and not reference
    if keep_samples and opts.features and opts.bounces:
        opts = replace(opts, second_hit=True)  # RPF's bounce random numbers and second-hit features

    stat_channels = {"color": 3, "diffuse": 3, "specular": 3}
    for name in features:
        if name != "motion" or want_motion:
            stat_channels[name] = FEATURE_CHANNELS[name]
    moments = {name: _Moments(height, width, c) for name, c in stat_channels.items()}
    sample_channels = {}
    if keep_samples:
        sample_channels = {k: c for k, c in SAMPLE_BUFFERS.items() if k in stat_channels}
        # light/bounce (listed by the plan when paths bounce) come with the second-hit channels below
        sample_channels.update(
            {k: RANDOM_PARAMETER_CHANNELS[k] for k in plan.random_parameters if k in RANDOM_PARAMETER_CHANNELS}
        )
        if opts.second_hit:
            sample_channels.update(SECOND_HIT_CHANNELS)
        samples = {k: np.zeros((spp, height, width, c), np.float32) for k, c in sample_channels.items()}
    else:
        samples = None

    switches = camera_switches(setup)
    values = camera_values(mi, setup)
    layout = moment_layout(stat_channels)
    passes = _plan_passes(height, width, spp, max_paths_per_pass)
    for index, (row0, band, s0, count) in enumerate(passes):
        groups = max(1, min(count, -(-target_lanes // (band * width))))  # lanes per pixel (each loops over samples)
        config = _PassConfig(
            opts, switches, tuple(stat_channels.items()), tuple(sample_channels.items()), band, width, count, groups
        )
        seed_dr = dr.opaque(mi.UInt32, derive_seed(seed, frame, spp, stream, index))
        packed, targets = _compiled_pass(scene, config)(scene, seed_dr, dr.opaque(mi.UInt32, row0), values, config)
        host = np.asarray(packed, dtype=np.float32).reshape(band, width, layout["stride"])  # one copy
        rows = slice(row0, row0 + band)
        for name, chans in stat_channels.items():
            mean_at, m2_at = layout[name]
            moments[name].add(rows, s0, count, host[..., mean_at : mean_at + chans], host[..., m2_at : m2_at + chans])
        if samples is not None:
            for name, chans in sample_channels.items():
                samples[name][s0 : s0 + count, rows] = np.asarray(targets[name]).reshape(count, band, width, chans)
        del packed, targets

    buffers = {}
    for name, m in moments.items():
        mean, var = m.finish(spp)
        buffers[name] = mean
        buffers[f"{name}_var"] = var
    if "motion" in features and not want_motion:
        buffers["motion"] = np.zeros((height, width, 2), np.float32)
        buffers["motion_var"] = np.zeros((height, width, 2), np.float32)
    return RenderedFrame(buffers=buffers, samples=samples, seconds=_time.perf_counter() - start, spp=spp)
