"""Render one frame's buffers (DESIGN.md, "Buffers") in one pass with our own Dr.Jit path tracer.

:func:`render_frame` is what the dataset writer calls. It generates camera rays itself
(:mod:`~denoisebench.generator.render.camera`: box pixel filter, pinhole or thin lens, camera motion
blur) and traces them with :mod:`~denoisebench.generator.render.integrator`, an unbiased estimator
of the image Mitsuba's ``path`` integrator renders at the same ``max_depth``, which also yields the
diffuse/specular split and every feature. One kernel per pass computes all of it: each lane loops over
samples of its pixel keeping running (Welford) moments, and when a small image gives a pixel several
lanes their moments are merged on the device; the same kernel writes every buffer's mean and variance
in the layout the host reads, so only finished per-pixel buffers (and per-sample data, when asked)
reach the host, without a copy.

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
* Seeds and sample order: sample ``s`` of pixel ``p`` draws its random numbers from its own PCG32
  stream, seeded from ``(key, p, s)`` (:func:`~denoisebench.generator.render.moments.sample_stream`)
  where the key is a 64-bit hash (BLAKE2b) of ``(seed, frame, stream)`` (:func:`stream_key`; stream 0
  for noisy, 1 for reference renders). A pixel's samples are therefore one progressive stream:
  a k-spp render is the mean of the first k samples of any longer render with the same seed, and
  frames and the reference never share random numbers (DESIGN.md, "Spp ladders are nested").
* Moments are carried, not merged: each lane keeps running (Welford) moments of its own samples
  across passes, so where a render is split (passes, rungs, rounds) never changes the bits: a
  plain k-spp render, rung k of a ladder (:func:`render_ladder`) and k uniform samples requested
  through :class:`FrameStream` in any number of rounds are the same bytes.
* Each pass configuration (kernel options, camera switches, buffers, band and sample sizes) is
  recorded once per scene with ``dr.freeze`` and replayed for later frames, whose camera and seed
  are the recording's inputs: a replay launches the kernels a fresh trace would, so bytes do not
  depend on it (:mod:`~denoisebench.generator.render.passes`, whose ``FREEZE_PASSES`` turns it off;
  tests/generator/render/test_frozen.py compares the two).
* Passes hold at most :data:`MAX_PATHS_PER_PASS` paths: a frame is split into bands of rows and
  chunks of samples.
* Lanes per pixel (``groups``: lane ``g`` takes the samples ``s ≡ g`` mod groups) depend on the image
  size and ``target_lanes`` only, never on spp or the core count; they decide the float rounding
  of the means (the order of the sums), not the random numbers.
"""

from __future__ import annotations

import hashlib
import struct
import time as _time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from denoisebench.dataset.frame import BUFFER_CHANNELS
from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.render_plan import RenderPlan
from denoisebench.generator.render.camera import camera_setup, camera_switches, camera_values
from denoisebench.generator.render.media import scene_has_media
from denoisebench.generator.render.passes import (
    MergeConfig,
    PassConfig,
    compiled_pass,
    device_copy,
    lane_groups,
    merge_pass,
)
from denoisebench.generator.render.tracing import (
    NULL_SKIPS,
    KernelOptions,
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

#: Channels of each per-sample buffer, in output order: the dataset's buffers but motion (per pixel, not sampled).
SAMPLE_BUFFERS = {name: count for name, count in BUFFER_CHANNELS.items() if name != "motion"}
RANDOM_PARAMETER_CHANNELS = {"pixel": 2, "lens": 2, "time": 1, "medium": 1}
#: Per-sample channels of paths that bounce (render_integrator's ``second_hit``): the first vertex's
#: light-sample and bounce-direction random numbers, and the bounce ray's hit point and normal.
SECOND_HIT_CHANNELS = {"light": 2, "bounce": 2, "position2": 3, "normal2": 3}
FEATURES = ("albedo", "normal", "depth", "position", "roughness", "motion")
FEATURE_CHANNELS = {name: BUFFER_CHANNELS[name] for name in FEATURES}

NOISY_STREAM = 0
REFERENCE_STREAM = 1


@dataclass
class RenderedFrame:
    """The buffers of one frame (see the module docstring for their conventions)."""

    buffers: dict[str, np.ndarray]
    samples: dict[str, np.ndarray] | None
    seconds: float
    spp: int


def load_scene(mitsuba_dict: dict):
    """Load a Mitsuba scene from an ``mi.load_dict`` dictionary (no sensor needed: rays are ours)."""
    mi = load_mitsuba()
    return mi.load_dict(mitsuba_dict)


def stream_key(seed: int, frame: int, stream: int) -> tuple[int, int]:
    """The 64-bit key (two 32-bit words) of one frame's sample streams: a hash of what decorrelates renders."""
    data = struct.pack("<qqq", int(seed), int(frame), int(stream))
    digest = hashlib.blake2b(data, digest_size=8).digest()
    return int.from_bytes(digest[:4], "little"), int.from_bytes(digest[4:], "little")


class FrameStream:
    """The progressive sample stream of one frame: per-pixel sample counts that grow round by round.

    :meth:`advance` traces more samples per pixel (each pixel continues its own stream where it
    stopped); :meth:`buffers` gives the means and variances of the mean of all samples so far.
    :func:`render_frame`, :func:`render_ladder` and
    :class:`~denoisebench.generator.render.progressive.ProgressiveFrame` are built on it, so they
    share its bits: a pixel's value depends only on its sample count, never on the rounds.

    Notes:
        Per-lane moments stay on the device between rounds (one entry per lane and channel, all
        bands at once): about ``pixels × groups × 2 × channels × 4`` bytes, e.g. 0.2 GB for a
        1920×1080 frame with every feature. The last pass of a round also writes every buffer
        (means and variances of the mean, H×W×C float32, as much again), which the host wraps as
        NumPy arrays without a copy.
    """

    def __init__(
        self,
        scene,
        camera: CameraTrack,
        frame: int,
        plan: RenderPlan,
        *,
        width: int,
        height: int,
        seed: int,
        reference: bool = False,
        keep_samples: bool | None = None,
        max_paths_per_pass: int = MAX_PATHS_PER_PASS,
        target_lanes: int = TARGET_LANES,
        _jitter: bool = True,
    ):
        mi = load_mitsuba()

        self.scene, self.width, self.height = scene, int(width), int(height)
        if self.width < 1 or self.height < 1:
            raise ValueError(f"image size must be positive (got {width}x{height})")
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
            media=scene_has_media(scene),
            follow_delta_albedo="albedo" in features and scene_has_delta_only_bsdf(mi, scene),
            jitter=_jitter,
        )
        if keep_samples is None:
            keep_samples = bool(plan.per_sample)
        keep_samples = keep_samples and not reference
        if keep_samples and opts.features and opts.bounces:
            opts = replace(opts, second_hit=True)  # RPF's bounce random numbers and second-hit features
        self.zero_motion = "motion" in features and not want_motion
        stat_channels = {"color": 3, "diffuse": 3, "specular": 3}
        for name in features:
            if name != "motion" or want_motion:
                stat_channels[name] = FEATURE_CHANNELS[name]
        sample_channels = {}
        if keep_samples:
            sample_channels = {k: c for k, c in SAMPLE_BUFFERS.items() if k in stat_channels}
            # light/bounce (listed by the plan when paths bounce) come with the second-hit channels below
            sample_channels.update(
                {
                    k: RANDOM_PARAMETER_CHANNELS[k]
                    for k in plan.random_parameters
                    if k in RANDOM_PARAMETER_CHANNELS and (k != "medium" or opts.media)  # the volumetric tracer's
                }
            )
            if opts.second_hit:
                sample_channels.update(SECOND_HIT_CHANNELS)
        self.stat_channels, self.sample_channels = stat_channels, sample_channels
        self.keep_samples = bool(sample_channels)
        self._opts, self._switches = opts, camera_switches(setup)
        self._values = camera_values(mi, setup)
        stream = REFERENCE_STREAM if reference else NOISY_STREAM
        self._key = stream_key(seed, frame, stream)
        rows = max(1, min(height, max_paths_per_pass // width))
        self._bands = [(row0, min(rows, height - row0)) for row0 in range(0, height, rows)]
        self._chunk = max(1, max_paths_per_pass // (rows * width))  # samples per pixel per pass
        self._groups = [lane_groups(band, width, target_lanes) for _, band in self._bands]
        self._state: list = [None] * len(self._bands)
        self._counts = np.zeros((height, width), np.int64)
        self._uniform: int | None = 0  # the count every pixel has, while rounds are one count for all (else None)
        self._round = None  # the launched round's (add, samples, pending, last), until finish()
        self._prefixes: dict = {}  # total → merged device buffers queued with the first round (queue_prefixes)
        self._band_buffers: list = [None] * len(self._bands)  # per band: name → (mean, var) host views, or None

    @property
    def counts(self) -> np.ndarray:
        """H×W int32: samples per pixel so far (those of finished rounds: what :meth:`buffers` reads)."""
        return self._counts.astype(np.int32)

    def advance(self, counts) -> dict[str, np.ndarray] | None:
        """Trace ``counts`` (H×W ints >= 0, or one int for every pixel) more samples per pixel.

        Returns this round's per-sample data when kept (name → N×H×W×C float32, N the largest count
        of the round; row ``j`` of pixel ``p`` is its ``j``-th new sample, zeros where ``j >=
        counts[p]``), else ``None``. The same as :meth:`launch` then :meth:`finish`.
        """
        self.launch(counts)
        return self.finish()

    def launch(self, counts) -> None:
        """Queue the passes of a round of ``counts`` more samples per pixel (:meth:`advance`); :meth:`finish` ends it.

        Dr.Jit runs the queued kernels while Python goes on, so the host can assemble the previous
        round's buffers (:meth:`buffers` reads finished rounds only) while this one traces: that is
        how :func:`render_ladder` hides a rung's host work behind the next rung's samples. One round
        at a time. Without per-sample data nothing waits for the kernels here; with it, a pass's
        samples are copied out once the next pass is queued (so at most two passes' samples are on
        the device).
        """
        mi = load_mitsuba()

        if self._round is not None:
            raise RuntimeError("finish() the launched round before launching another")
        self._prefixes = {}
        add = np.asarray(counts)
        np.broadcast_shapes(add.shape, (self.height, self.width))  # raises for another shape
        if not np.issubdtype(add.dtype, np.integer) or (add < 0).any():
            raise ValueError("per-pixel sample counts must be integers >= 0")
        # One count for all pixels of a stream whose pixels all have the same count: the arithmetic
        # below runs on 0-d arrays, not on H×W ones (tens of ms per round at 1 MP).
        flat = add.ndim == 0 and self._uniform is not None
        add = add.astype(np.int64) if flat else np.broadcast_to(add, (self.height, self.width)).astype(np.int64)
        most_after = self._uniform + int(add) if flat else int((self._counts + add).max(initial=0))
        if most_after >= 1 << 31:
            raise ValueError("at most 2^31 - 1 samples per pixel")
        rows_most = int(add.max(initial=0))
        samples = None
        if self.keep_samples:
            samples = {
                k: np.zeros((rows_most, self.height, self.width, c), np.float32)
                for k, c in self.sample_channels.items()
            }
        pending = []  # (rows, offset, count, targets): per-sample data still on the device
        last = {}  # band index → the buffers (device arrays) of the band's last pass: all samples so far
        for index, ((row0, band), groups) in enumerate(zip(self._bands, self._groups)):
            rows = slice(row0, row0 + band)
            before = np.asarray(self._uniform, np.int64) if flat else self._counts[rows]
            extra = add if flat else add[rows]
            most = int(extra.max(initial=0))
            for offset in range(0, most, self._chunk):
                starts = before + np.minimum(extra, offset)
                ends = before + np.minimum(extra, offset + self._chunk)
                count = int((ends - starts).max()) if self.keep_samples else 0
                uniform = bool((starts == starts.flat[0]).all() and (ends == ends.flat[0]).all())
                scalars = [*self._key, row0, int(starts.flat[0]), int(ends.flat[0])]
                params = device_copy(mi, mi.UInt32, np.asarray(scalars, np.uint32))
                ranges = (
                    ()
                    if uniform
                    else tuple(device_copy(mi, mi.UInt32, a.astype(np.uint32).ravel()) for a in (starts, ends))
                )
                config = PassConfig(
                    self._opts,
                    self._switches,
                    tuple(self.stat_channels.items()),
                    tuple(self.sample_channels.items()),
                    band,
                    self.width,
                    count,
                    groups,
                    uniform,
                    self._state[index] is None,
                )
                state, buffers, targets = compiled_pass(self.scene, config)(
                    self.scene,
                    params,
                    ranges,
                    self._state[index],
                    self._values,
                    config,
                )
                self._state[index] = state
                last[index] = buffers
                if targets is not None:
                    if pending:
                        self._copy_samples(samples, *pending.pop())
                    pending.append((rows, offset, count, targets))
        self._round = (add, samples, pending, last)

    def finish(self) -> dict[str, np.ndarray] | None:
        """Wait for the launched round, take its buffers to the host (views, no copy); return its per-sample data.

        What :meth:`advance` returns; afterwards :attr:`counts` and :meth:`buffers` include the round.
        """
        if self._round is None:
            raise RuntimeError("no launched round to finish")
        add, samples, pending, last = self._round
        self._round = None
        for index, buffers in last.items():
            self._band_buffers[index] = self._host_views(buffers, self._bands[index][1])
        for entry in pending:
            self._copy_samples(samples, *entry)
        if add.ndim == 0 and self._uniform is not None:
            self._uniform += int(add)
            self._counts = np.broadcast_to(np.int64(self._uniform), (self.height, self.width))  # read-only
        else:
            self._uniform = None
            self._counts = self._counts + add
        return samples

    def _copy_samples(self, samples: dict, rows: slice, offset: int, count: int, targets: dict) -> None:
        """One pass's per-sample data (``targets``, on the device) into the round's host arrays."""
        band = rows.stop - rows.start
        for name, chans in self.sample_channels.items():
            values = np.asarray(targets[name]).reshape(count, band, self.width, chans)
            samples[name][offset : offset + count, rows] = values

    def buffers(self, copy: bool = True) -> dict[str, np.ndarray]:
        """Means and variances of the mean of every sample of the finished rounds (module docstring's conventions).

        A pixel without samples has mean 0 and variance ``inf``; one with a single sample has
        variance 0 (unknown, but finite, as in a 1-spp render).

        ``copy=False`` returns the stream's own arrays where the frame is one band (views of the
        device memory the pass wrote): no copy, but they are shared with every later call until
        the next round, so a caller that writes into one changes what the stream returns next.
        :func:`render_ladder` takes its rungs that way (each rung's arrays are fresh: a later round
        writes new ones).

        Notes:
            The pass kernels write each buffer's mean and variance (``max(M2, 0) / ((n - 1) n)``)
            in H×W×C order (:func:`~denoisebench.generator.render.moments.pixel_buffers`); the host
            only joins bands of rows (frames above ``max_paths_per_pass`` pixels) and fills bands
            that have no samples yet.
        """
        return self._collect(self._band_buffers, self._counts, copy)

    @property
    def lanes_per_pixel(self) -> int:
        """Lanes every pixel has at least (``groups``): a fresh stream of up to this many samples holds one per lane."""
        return min(self._groups)

    def queue_prefixes(self, totals) -> None:
        """Queue :meth:`prefix_buffers`' merges for ``totals`` on the launched round, so that its finish waits for them too.

        Only for a fresh stream's first round (launched, not finished) of ``n <= lanes_per_pixel``
        samples for every pixel, and totals ``1..n``; raises ``ValueError`` otherwise.
        """
        if self._round is None or self._counts.any():
            raise ValueError("queue_prefixes() needs the launched first round of a fresh stream")
        self._prefixes = {int(k): self._merge(int(k), self._round[0]) for k in totals}

    def prefix_buffers(self, total: int) -> dict[str, np.ndarray]:
        """The buffers of every pixel's first ``total`` samples, while each lane holds at most one sample.

        That is, after one finished round of ``n <= lanes_per_pixel`` samples for every pixel from a
        fresh stream, and ``1 <= total <= n``: the bytes :meth:`buffers` gives after a round of
        ``total`` (:func:`merge_pass`), from the lanes already traced. :func:`render_ladder` takes
        its rungs below ``lanes_per_pixel`` this way: on small images a pixel's few samples occupy
        a few of its lanes while the others idle in the same SIMD vectors, so one pass of ``n``
        costs about what a pass of 1 costs. Merges queued with the round (:meth:`queue_prefixes`)
        are only taken (once: a second call merges anew); others run now. The arrays are the
        caller's own. Raises ``ValueError`` otherwise.
        """
        if self._round is not None:
            raise ValueError("prefix_buffers() reads a finished round: finish() first")
        merged = self._prefixes.pop(int(total), None) or self._merge(int(total), self._counts)
        views = [self._host_views(buffers, band) for (_, band), buffers in zip(self._bands, merged)]
        return self._collect(views, np.full_like(self._counts, total), False)  # fresh arrays: nobody else holds them

    def _merge(self, total: int, counts: np.ndarray) -> list:
        """Queue the merges of every band's lanes as ``total`` samples (:func:`merge_pass`): device buffers per band."""
        mi = load_mitsuba()

        n = int(counts.flat[0])
        if (counts != n).any() or not 1 <= total <= n <= self.lanes_per_pixel:
            raise ValueError(
                f"prefix_buffers({total}) needs a uniform round of {total}..{self.lanes_per_pixel} samples"
            )
        params = device_copy(mi, mi.UInt32, np.asarray([total, 0], np.uint32))  # two: one element is a literal
        merged = []
        for index, ((_, band), groups) in enumerate(zip(self._bands, self._groups)):
            config = MergeConfig(tuple(self.stat_channels.items()), band, self.width, groups)
            merged.append(compiled_pass(self.scene, config, merge_pass)(self.scene, params, self._state[index], config))
        return merged

    def _host_views(self, buffers: dict, band: int) -> dict:
        """A band's device buffers (name → (mean, var), flat) as H×W×C NumPy views of the same memory (waits for them)."""
        shape = {name: (band, self.width, c) for name, c in self.stat_channels.items()}
        return {name: tuple(np.asarray(a).reshape(shape[name]) for a in pair) for name, pair in buffers.items()}

    def _collect(self, bands: list, counts: np.ndarray, copy: bool) -> dict[str, np.ndarray]:
        """The frame's buffers from each band's host views (None: a band without samples yet) (:meth:`buffers`)."""
        out = {}
        for name, c in self.stat_channels.items():
            for part, key in enumerate((name, f"{name}_var")):
                pieces = [
                    views[name][part] if views is not None else self._unsampled(band, c, part)
                    for (_, band), views in zip(self._bands, bands)
                ]
                if len(pieces) > 1:
                    out[key] = np.concatenate(pieces)
                else:
                    out[key] = np.array(pieces[0]) if copy and bands[0] is not None else pieces[0]
        if self.zero_motion:
            out["motion"] = np.zeros((self.height, self.width, 2), np.float32)
            out["motion_var"] = np.where(counts[..., None] == 0, np.inf, 0.0).astype(np.float32) * np.ones(
                2, np.float32
            )
        return out

    def _unsampled(self, band: int, channels: int, part: int) -> np.ndarray:
        """A band's mean (part 0: zeros) or variance (part 1: ``inf``) before any of its pixels has a sample."""
        return np.full((band, self.width, channels), np.inf if part else 0.0, np.float32)


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
    clock: Callable[[], float] = _time.perf_counter,
    _jitter: bool = True,
) -> RenderedFrame:
    """Render ``frame`` of ``camera`` with ``spp`` samples per pixel; see the module docstring.

    ``target_lanes`` overrides how many lanes one launch aims for (:data:`TARGET_LANES`); it
    changes the float rounding of the means, not the random numbers or the estimator. ``clock``
    measures ``seconds`` (e.g. one that leaves out kernel compilation).

    ``_jitter=False`` puts every sample at its pixel center (tests compare features with Mitsuba's
    ``aov`` integrator that way); it is not meant for datasets.
    """
    (out,) = render_ladder(
        scene,
        camera,
        frame,
        plan,
        width=width,
        height=height,
        rungs=(spp,),
        seed=seed,
        reference=reference,
        max_paths_per_pass=max_paths_per_pass,
        target_lanes=target_lanes,
        clock=clock,
        _jitter=_jitter,
    )
    return out


def render_ladder(
    scene,
    camera: CameraTrack,
    frame: int,
    plan: RenderPlan,
    *,
    width: int,
    height: int,
    rungs,
    seed: int,
    reference: bool = False,
    max_paths_per_pass: int = MAX_PATHS_PER_PASS,
    target_lanes: int = TARGET_LANES,
    clock: Callable[[], float] = _time.perf_counter,
    _jitter: bool = True,
) -> list[RenderedFrame]:
    """Render one progressive stream per pixel and return its rungs (ascending spp, duplicates dropped).

    Rung ``k`` is the mean of each pixel's first ``k`` samples, with its own ``_var`` buffers and,
    when the plan keeps them, the first ``k`` samples (views of one array of the top rung's
    samples). It is the same bytes as ``render_frame(..., spp=k)`` with the same seed. A rung's
    ``seconds`` is the time (by ``clock``) from the call until that rung's buffers were ready, so the
    top rung's seconds is what the whole ladder cost.

    Notes:
        The passes are split at rung boundaries (each rung is a snapshot of the carried moments),
        so a ladder ``1, 2, 4, ..., 64`` traces what a plain 64-spp render traces plus one launch
        and one write of every buffer per rung (by the rung's last pass, on the device: the host
        only wraps the arrays). The next rung's passes are queued before a rung is handed out
        (:meth:`FrameStream.launch`). On small images,
        whose pixels have several lanes, the rungs below the lanes per pixel all come from the
        first round (:meth:`FrameStream.prefix_buffers`): traced one by one, each would cost a
        pass of mostly idle lanes. bench/ladder_cost.py measures the difference against the top
        rung alone; a rung's ``seconds`` then is the time the shared round and its own merge took.
    """
    started = clock()
    rungs = sorted({int(k) for k in rungs})
    if not rungs or rungs[0] < 1:
        raise ValueError(f"spp must be >= 1 (got {rungs})")
    stream = FrameStream(
        scene,
        camera,
        frame,
        plan,
        width=width,
        height=height,
        seed=seed,
        reference=reference,
        max_paths_per_pass=max_paths_per_pass,
        target_lanes=target_lanes,
        _jitter=_jitter,
    )
    top = None
    if stream.keep_samples:
        top = {k: np.zeros((rungs[-1], height, width, c), np.float32) for k, c in stream.sample_channels.items()}
    # Rungs below the lanes per pixel come from one round of `first` samples (FrameStream.prefix_buffers).
    first = min(stream.lanes_per_pixel, rungs[-1])
    head = [k for k in rungs if k < first]
    rounds = sorted({first, *rungs} - set(head)) if head else rungs
    out, done = [], 0

    def emit(spp, buffers):
        samples = None if top is None else {name: values[:spp] for name, values in top.items()}
        out.append(RenderedFrame(buffers=buffers, samples=samples, seconds=clock() - started, spp=spp))

    stream.launch(rounds[0])
    if head:
        stream.queue_prefixes(head)
    for index, spp in enumerate(rounds):
        new = stream.finish()
        if top is not None:
            for name, values in new.items():
                top[name][done:spp] = values
        done = spp
        if index == 0:
            for k in head:
                emit(k, stream.prefix_buffers(k))
        if index + 1 < len(rounds):
            stream.launch(rounds[index + 1] - spp)  # traces while the host assembles this rung
        if spp in rungs:
            emit(spp, stream.buffers(copy=False))  # this round's own arrays: the next round writes new ones
    return out
