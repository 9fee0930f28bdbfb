"""Render one frame's buffers (DESIGN.md, "Buffers") in one pass with our own Dr.Jit path tracer.

:func:`render_frame` is what the dataset writer calls. It generates camera rays itself
(:mod:`~denoisebench.generator.render_camera`: box pixel filter, pinhole or thin lens, camera motion
blur) and traces them with :mod:`~denoisebench.generator.render_integrator`, an unbiased estimator
of the image Mitsuba's ``path`` integrator renders at the same ``max_depth``, which also yields the
diffuse/specular split and every feature. One kernel per pass computes all of it; per-pixel means
and variances are reduced on the host from the per-sample values.

Conventions:

* Buffers are H×W×C float32: color, diffuse, specular, albedo, normal, depth (1), position,
  roughness (1), motion (2), and ``<name>_var`` for each: the variance of the per-pixel *mean*,
  i.e. the unbiased sample variance divided by spp (0 when spp is 1: unknown, but finite).
* Feature means are averages over the pixel's samples (anti-aliased), like color.
* Per-sample data (``plan.per_sample`` and not ``reference``) is S×H×W×C per buffer, plus the
  random parameters that exist in the plan, as the uniform numbers that drove them: ``pixel`` (the
  sub-pixel offset in [0,1)²), ``lens`` (the square sample in [0,1)² mapped to the disk; thin lens
  only), ``time`` (the shutter fraction in [0,1); motion blur only).
* ``reference=True``: color, diffuse and specular with their variances only (no features), from an
  independent random stream.
* Seeds: each pass seeds Mitsuba's ``independent`` sampler with a 32-bit hash (BLAKE2b) of
  ``(seed, frame, spp, stream, pass)`` where stream is 0 for noisy and 1 for reference renders, so
  frames, sample counts and the reference never share random numbers, and the same arguments give
  bit-identical buffers.
* Passes hold at most :data:`MAX_PATHS_PER_PASS` paths: a frame is split into bands of rows and
  chunks of samples, whose statistics are merged exactly (Chan et al.'s pairwise update).
"""

from __future__ import annotations

import hashlib
import struct
import time as _time
from dataclasses import dataclass

import numpy as np

from denoisebench.generator.camera_track import CameraTrack
from denoisebench.generator.render_camera import DrCamera, camera_setup
from denoisebench.generator.render_integrator import KernelOptions, scene_has_delta_only_bsdf, trace
from denoisebench.generator.render_plan import RenderPlan
from denoisebench.mitsuba_runtime import load_mitsuba

#: Most paths traced by one kernel launch (bounds memory: ~100 bytes of output per path).
MAX_PATHS_PER_PASS = 1 << 22

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
FEATURES = ("albedo", "normal", "depth", "position", "roughness", "motion")
FEATURE_CHANNELS = {"albedo": 3, "normal": 3, "depth": 1, "position": 3, "roughness": 1, "motion": 2}

NOISY_STREAM = 0
REFERENCE_STREAM = 1


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


def _channels(value, count: int, n: int) -> list[np.ndarray]:
    """Per-channel 1-D numpy arrays (length ``n``) of a Dr.Jit value with ``count`` channels."""
    parts = [value] if count == 1 else [value[c] for c in range(count)]
    return [np.broadcast_to(np.asarray(p, dtype=np.float32).reshape(-1), (n,)) for p in parts]


class _Moments:
    """Per-pixel mean and sum of squared deviations of one buffer (float64), merged pass by pass."""

    def __init__(self, height: int, width: int, channels: int):
        self.mean = np.zeros((height, width, channels))
        self.m2 = np.zeros((height, width, channels))

    def add(self, rows: slice, chans: list[np.ndarray], before: int, count: int, band: int, width: int) -> None:
        """Merge ``count`` new samples per pixel of ``rows`` into the ``before`` already there."""
        for c, values in enumerate(chans):
            x = values.reshape(count, band, width)
            mean_b = x.mean(axis=0, dtype=np.float64)
            m2_b = np.square(x - mean_b.astype(np.float32), dtype=np.float64).sum(axis=0) if count > 1 else 0.0
            if before == 0:
                self.mean[rows, :, c] = mean_b
                self.m2[rows, :, c] = m2_b
            else:
                total = before + count
                delta = mean_b - self.mean[rows, :, c]
                self.mean[rows, :, c] += delta * (count / total)
                self.m2[rows, :, c] += m2_b + np.square(delta) * (before * count / total)

    def finish(self, spp: int):
        mean = self.mean.astype(np.float32)
        if spp > 1:
            var = (self.m2 / ((spp - 1) * spp)).astype(np.float32)
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
    _jitter: bool = True,
) -> RenderedFrame:
    """Render ``frame`` of ``camera`` with ``spp`` samples per pixel; see the module docstring.

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
        follow_delta_albedo="albedo" in features and scene_has_delta_only_bsdf(mi, scene),
        jitter=_jitter,
    )
    cam = DrCamera(mi, setup)
    stream = REFERENCE_STREAM if reference else NOISY_STREAM
    keep_samples = plan.per_sample and not reference

    stat_channels = {"color": 3, "diffuse": 3, "specular": 3}
    for name in features:
        if name != "motion" or want_motion:
            stat_channels[name] = FEATURE_CHANNELS[name]
    moments = {name: _Moments(height, width, c) for name, c in stat_channels.items()}
    sample_channels = {}
    if keep_samples:
        sample_channels = {k: c for k, c in SAMPLE_BUFFERS.items() if k in stat_channels}
        sample_channels.update({k: RANDOM_PARAMETER_CHANNELS[k] for k in plan.random_parameters})
        samples = {k: np.zeros((spp, height, width, c), np.float32) for k, c in sample_channels.items()}
    else:
        samples = None

    sampler = mi.load_dict({"type": "independent", "sample_count": 1})
    passes = _plan_passes(height, width, spp, max_paths_per_pass)
    for index, (row0, band, s0, count) in enumerate(passes):
        n = band * width * count
        sampler.seed(derive_seed(seed, frame, spp, stream, index), n)
        lane = dr.arange(mi.UInt32, n)
        per_sample = band * width
        pixel = lane % per_sample
        px = pixel % width
        py = pixel // width + dr.opaque(mi.UInt32, row0)
        out = trace(mi, scene, sampler, cam, opts, px, py)
        wanted = {k: out[k] for k in dict.fromkeys([*stat_channels, *sample_channels])}
        dr.eval(wanted)
        rows = slice(row0, row0 + band)
        for name, chans in stat_channels.items():
            moments[name].add(rows, _channels(wanted[name], chans, n), s0, count, band, width)
        if samples is not None:
            for name, chans in sample_channels.items():
                values = _channels(wanted[name], chans, n)
                samples[name][s0 : s0 + count, rows] = np.stack(values, axis=-1).reshape(count, band, width, chans)
        del out, wanted

    buffers = {}
    for name, m in moments.items():
        mean, var = m.finish(spp)
        buffers[name] = mean
        buffers[f"{name}_var"] = var
    if "motion" in features and not want_motion:
        buffers["motion"] = np.zeros((height, width, 2), np.float32)
        buffers["motion_var"] = np.zeros((height, width, 2), np.float32)
    return RenderedFrame(buffers=buffers, samples=samples, seconds=_time.perf_counter() - start, spp=spp)

