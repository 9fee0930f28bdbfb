"""Samples at positions the caller chooses: film position, lens point and shutter time.

The progressive frame's count rounds (:mod:`~denoisebench.generator.render.progressive`) let a sampler
choose *how many* samples each pixel gets; where they land inside the pixel, on the lens and in the
shutter is the renderer's random stream. A multidimensional sampler (``mdas``: Hachisuka et al.
2008) chooses those positions itself. :func:`trace_placed` traces one sample per given position:

* ``film``: N×2 film positions in pixels, ``x`` in ``[0, W)`` (left to right), ``y`` in ``[0, H)``
  (top to bottom); the sample belongs to pixel ``(floor(y), floor(x))`` and its sub-pixel offset is
  the fractional part (the renderer's box filter, camera.py's film convention).
* ``lens``: N×2 points of the unit square, mapped to the aperture disk as the renderer maps its own
  lens numbers (``square_to_uniform_disk_concentric``); only where the plan has a thin lens.
* ``time``: N shutter fractions in ``[0, 1)``, mapped to a ray time as the renderer maps its own
  (camera.py ``sample_time``); only where the plan samples time.

Everything else a path draws (light samples, BSDF samples, roulette) comes from a PCG32 stream of
its own: sample ``i`` of the frame's placed samples (counted over all placed rounds) draws from
:func:`~denoisebench.generator.render.moments.sample_stream` with the frame's *placed* key
(:data:`PLACED_STREAM`), pixel index ``i`` and sample index 0, so no placed sample shares random
numbers with another or with the count rounds' samples.

Unbiasedness: a placed sample's value is an unbiased estimate of the pixel integrand (radiance, and
each feature) *at its position*, whatever the position; the positions are the caller's business.
Uniform positions give pixel means with the count rounds' expectation (tests/sampling/test_mdas.py checks
both against the reference stream).

Notes
-----
* The positions replace the first uniform numbers ``trace`` draws, in its documented order
  (sub-pixel offset, then time with time sampling, then lens with a thin lens): :class:`_PlacedStream`
  hands those out first and then continues with its PCG32 stream. Each sample reports the numbers
  it used (``pixel``, ``lens``, ``time``), and the tests hold them equal to the request, so a change
  of that order cannot go unnoticed.
* Placed passes are ``dr.freeze``-recorded per configuration and replayed, like the count passes
  (:func:`trace_placed`'s Notes).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from denoisebench.generator.render.camera import DrCamera
from denoisebench.generator.render.integrator import trace
from denoisebench.generator.render.moments import sample_stream
from denoisebench.mitsuba_runtime import load_mitsuba

#: Stream tag of placed samples in :func:`~denoisebench.generator.render.frame.stream_key` (noisy 0, reference 1;
#: placed samples of a reference frame use 3).
PLACED_STREAM = 2
#: Record placed passes with ``dr.freeze`` and replay them (False: trace every round afresh; same bits).
FREEZE_PLACED = True
#: Most placed samples traced by one kernel launch.
MAX_PLACED_PER_PASS = 1 << 20


@functools.cache
def _placed_type(pcg_type, point2_type):
    """The stream class of one Dr.Jit variant: queued values first, then PCG32 (a ``DRJIT_STRUCT``)."""

    class _PlacedStream:
        """Hands out ``queue`` (Dr.Jit arrays) on the first draws, then the PCG32 ``rng``'s numbers.

        The queue is no loop state: a copy Dr.Jit rebuilds inside a loop starts with an empty one,
        which is right because the camera's draws (the queued ones) all come before any loop.
        """

        DRJIT_STRUCT = {"rng": pcg_type}

        def __init__(self, rng=None, queue=()):
            self.rng = pcg_type() if rng is None else rng
            self.queue = list(queue)

        def next_1d(self):
            if self.queue:
                return self.queue.pop(0)
            return self.rng.next_float32()

        def next_2d(self):
            if self.queue:
                return self.queue.pop(0)
            x = self.rng.next_float32()
            return point2_type(x, self.rng.next_float32())

    return _PlacedStream


def check_positions(film, lens, time, *, width: int, height: int, dimensions: tuple[str, ...]):
    """The request as float64 arrays ``(film N×2, lens N×2 or None, time N or None)``; ValueError (one line) if malformed.

    ``dimensions`` are the placement dimensions the frame has (``"lens"``, ``"time"``): each must be
    given exactly when it is one of them.
    """
    film = np.asarray(film, dtype=np.float64)
    if film.ndim != 2 or film.shape[1] != 2 or film.shape[0] < 1:
        raise ValueError(f"film positions must be an N×2 array with N >= 1 (got shape {film.shape})")
    n = film.shape[0]
    if not np.isfinite(film).all() or (film < 0).any() or (film[:, 0] >= width).any() or (film[:, 1] >= height).any():
        raise ValueError(f"film positions must lie in [0, {width}) × [0, {height})")
    out = [film]
    for name, value, channels in (("lens", lens, 2), ("time", time, 1)):
        if name not in dimensions:
            if value is not None:
                raise ValueError(f"this frame's plan has no {name} dimension: pass {name}=None")
            out.append(None)
            continue
        if value is None:
            raise ValueError(f"this frame's plan samples {name}: give {name} positions")
        value = np.asarray(value, dtype=np.float64).reshape(n, -1) if np.size(value) == n * channels else None
        if value is None or value.shape[1] != channels:
            raise ValueError(f"{name} positions must be N×{channels} for N = {n} film positions")
        if not np.isfinite(value).all() or (value < 0).any() or (value >= 1).any():
            raise ValueError(f"{name} positions must lie in [0, 1)")
        out.append(value if channels == 2 else value[:, 0])
    return tuple(out)


@dataclass(frozen=True)
class _PlacedConfig:
    """What shapes a placed pass's kernels (hashable): kernel options, camera switches, output channels."""

    opts: object
    switches: object
    names: tuple  # (name, channels) in output order


def _placed_pass(scene, inputs: dict, camera_values: dict, config: _PlacedConfig):
    """Trace one sample per lane at the positions in ``inputs`` (device arrays); name → Dr.Jit array, evaluated.

    ``inputs``: ``px``, ``py`` (UInt32 pixel), ``ox``, ``oy`` (Float sub-pixel offset), ``time``
    (Float, with time sampling), ``lu``, ``lv`` (Float lens square, with a thin lens), ``ordinal``
    (UInt32: the sample's index among the frame's placed samples) and ``key`` (UInt32 pair). Sizes
    come from the inputs only, so one recording serves every round size.
    """
    mi = load_mitsuba()
    import drjit as dr

    cam = DrCamera(mi, config.switches, camera_values)
    queue = [mi.Point2f(inputs["ox"], inputs["oy"])]
    if config.switches.time_sampling:
        queue.append(mi.Float(inputs["time"]))
    if config.switches.thin_lens:
        queue.append(mi.Point2f(inputs["lu"], inputs["lv"]))
    key = (dr.gather(mi.UInt32, inputs["key"], 0), dr.gather(mi.UInt32, inputs["key"], 1))
    rng = sample_stream(mi, key, inputs["ordinal"], inputs["ordinal"] * 0).rng
    stream = _placed_type(mi.PCG32, mi.Point2f)(rng, queue)
    values_out = trace(mi, scene, stream, cam, config.opts, inputs["px"], inputs["py"])
    picked = {name: values_out[name] for name, _ in config.names if name in values_out}
    dr.eval(picked)
    return picked


def trace_placed(
    scene, opts, switches, values, key, film, lens, time, first: int, names: dict
) -> dict[str, np.ndarray]:
    """Trace one sample at each position (module docstring); name → N×C float32 for ``names`` (name → channels).

    ``opts``/``switches``/``values`` are a :class:`~denoisebench.generator.render.frame.FrameStream`'s
    kernel options and camera; ``key`` the placed stream's key; ``first`` the frame's count of placed
    samples before these (their random streams continue from there). ``names`` may include the
    random parameters ``pixel``, ``lens``, ``time``.

    Notes:
        The pass is recorded with ``dr.freeze`` like the count rounds' passes
        (:func:`~denoisebench.generator.render.passes.compiled_pass`, the same per-scene cache) and
        replayed for later rounds: measured on a 32 px depth-of-field frame, 0.3 s per traced round of
        2048 samples against a few hundredths replayed. :data:`FREEZE_PLACED` False traces every round
        (the same bits: tests/sampling/test_mdas.py compares them).
    """
    mi = load_mitsuba()
    from denoisebench.generator.render.passes import compiled_pass, device_copy

    config = _PlacedConfig(replace(opts, jitter=True), switches, tuple(names.items()))  # the offset is queued
    n = film.shape[0]
    out = {name: np.zeros((n, c), np.float32) for name, c in names.items()}
    key_array = device_copy(mi, mi.UInt32, np.asarray([key[0], key[1], 0], np.uint32))
    for lo in range(0, n, MAX_PLACED_PER_PASS):
        hi = min(n, lo + MAX_PLACED_PER_PASS)
        cell = np.floor(film[lo:hi])
        offset = film[lo:hi] - cell
        host = {
            "px": (mi.UInt32, cell[:, 0].astype(np.uint32)),
            "py": (mi.UInt32, cell[:, 1].astype(np.uint32)),
            "ox": (mi.Float, offset[:, 0].astype(np.float32)),
            "oy": (mi.Float, offset[:, 1].astype(np.float32)),
            "ordinal": (mi.UInt32, np.arange(first + lo, first + hi, dtype=np.uint32)),
        }
        if switches.time_sampling:
            host["time"] = (mi.Float, time[lo:hi].astype(np.float32))
        if switches.thin_lens:
            host["lu"] = (mi.Float, lens[lo:hi, 0].astype(np.float32))
            host["lv"] = (mi.Float, lens[lo:hi, 1].astype(np.float32))
        inputs = {name: device_copy(mi, kind, np.ascontiguousarray(array)) for name, (kind, array) in host.items()}
        inputs["key"] = key_array
        function = compiled_pass(scene, config, _placed_pass) if FREEZE_PLACED else _placed_pass
        picked = function(scene, inputs, values, config)
        for name, value in picked.items():
            array = np.asarray(value, dtype=np.float32)  # (N,) or (C, N)
            out[name][lo:hi] = array[:, None] if array.ndim == 1 else array.reshape(names[name], -1).T
    return out


class PlacedMoments:
    """Per-pixel count, sum and sum of squares (float64) of the placed samples of one frame, per channel."""

    def __init__(self, width: int, height: int, channels: dict):
        self.width, self.height, self.channels = int(width), int(height), dict(channels)
        pixels = self.width * self.height
        self.n = np.zeros(pixels, np.int64)
        self.sums = {name: np.zeros((pixels, c)) for name, c in self.channels.items()}
        self.squares = {name: np.zeros((pixels, c)) for name, c in self.channels.items()}

    @property
    def total(self) -> int:
        return int(self.n.sum())

    def counts(self) -> np.ndarray:
        return self.n.reshape(self.height, self.width)

    def add(self, film: np.ndarray, values: dict) -> np.ndarray:
        """Add samples at ``film`` (N×2) with ``values`` (name → N×C); the H×W map of what was added."""
        pixel = np.floor(film[:, 1]).astype(np.int64) * self.width + np.floor(film[:, 0]).astype(np.int64)
        size = self.width * self.height
        added = np.bincount(pixel, minlength=size)
        self.n += added
        for name in self.channels:
            value = values[name].astype(np.float64)
            for c in range(value.shape[1]):
                self.sums[name][:, c] += np.bincount(pixel, value[:, c], minlength=size)
                self.squares[name][:, c] += np.bincount(pixel, value[:, c] ** 2, minlength=size)
        return added.reshape(self.height, self.width)

    def merge(self, buffers: dict, stream_counts: np.ndarray) -> dict:
        """``buffers`` (a FrameStream's, from ``stream_counts`` samples per pixel) with the placed samples pooled in.

        Means and variances of the mean of all of a pixel's samples (Chan et al.'s pairwise rule);
        the stream's M2 is recovered from its variance of the mean, ``var · (n - 1) · n``.
        """
        n1 = stream_counts.astype(np.float64).reshape(-1, 1)
        n2 = self.n.astype(np.float64).reshape(-1, 1)
        n = n1 + n2
        out = dict(buffers)
        with np.errstate(divide="ignore", invalid="ignore"):
            for name, c in self.channels.items():
                if name not in buffers:
                    continue
                mean1 = buffers[name].reshape(-1, c).astype(np.float64)
                var1 = np.where(n1 > 1, buffers[f"{name}_var"].reshape(-1, c).astype(np.float64), 0.0)
                m2_1 = var1 * np.maximum(n1 - 1, 0) * n1
                mean2 = np.where(n2 > 0, self.sums[name] / np.maximum(n2, 1), 0.0)
                m2_2 = np.maximum(self.squares[name] - n2 * mean2**2, 0.0)
                delta = mean2 - mean1
                mean = np.where(n > 0, mean1 + delta * n2 / np.maximum(n, 1), 0.0)
                m2 = m2_1 + m2_2 + delta**2 * n1 * n2 / np.maximum(n, 1)
                var = np.where(n > 1, m2 / np.maximum((n - 1) * n, 1), np.where(n > 0, 0.0, np.inf))
                shape = (self.height, self.width, c)
                out[name] = mean.reshape(shape).astype(np.float32)
                out[f"{name}_var"] = var.reshape(shape).astype(np.float32)
        if "motion" in out and "motion" not in self.channels:  # zero motion (first frame): finite where sampled
            seen = (n > 0).reshape(self.height, self.width, 1)
            out["motion_var"] = np.where(seen, 0.0, np.inf).astype(np.float32) * np.ones(2, np.float32)
        return out
