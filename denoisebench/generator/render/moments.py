"""Sample streams and per-pixel moments: the loop that runs a tracer over a pixel's samples.

:func:`sample_stream` gives every (frame key, pixel, sample) its own PCG32 stream, so a sample's random
numbers never depend on the lane, the pass or the sample count (nested spp ladders, per-pixel counts).
:func:`render_moments` traces a lane's samples in one Dr.Jit loop (the surface tracer, or the volumetric
one for scenes with media) and keeps running Welford moments of the buffers asked for, optionally
scattering per-sample values; :func:`pixel_buffers` merges a pixel's lanes in a fixed order
(:func:`merge_lanes`) and writes every buffer's mean and variance of the mean as the host reads it.

Pitfall: the merge order is fixed (group order, one kernel) so the sums are the same bits on every
run and thread count; scatter-adds from shared lanes would not be.
"""

from __future__ import annotations

import functools
import importlib

from denoisebench.generator.render.camera import DrCamera
from denoisebench.generator.render.integrator import trace
from denoisebench.generator.render.tracing import KernelOptions


def channel_type(mi, channels: int):
    return {1: mi.Float, 2: mi.Vector2f, 3: mi.Color3f}[channels]


@functools.cache
def _sample_stream_type(pcg_type, point2_type):
    """The :class:`SampleStream` class of one Dr.Jit variant (its ``DRJIT_STRUCT`` names the variant's PCG32)."""

    class SampleStream:
        """The random numbers of one sample per lane: a PCG32 stream with Mitsuba's sampler interface.

        ``trace`` (and the loops that carry it) only call :meth:`next_1d` and :meth:`next_2d`;
        ``DRJIT_STRUCT`` makes it a Dr.Jit PyTree, so that it can be loop state.
        """

        DRJIT_STRUCT = {"rng": pcg_type}

        def __init__(self, rng=None):
            self.rng = pcg_type() if rng is None else rng

        def next_1d(self):
            return self.rng.next_float32()

        def next_2d(self):
            x = self.rng.next_float32()
            return point2_type(x, self.rng.next_float32())

    return SampleStream


def sample_stream(mi, key, pixel_index, sample_index):
    """The random stream of sample ``sample_index`` of pixel ``pixel_index`` (UInt32 per lane).

    ``key`` is a pair of UInt32 (the frame's stream key: a hash of seed, frame and stream). The
    PCG32 state and sequence come from two rounds of TEA (Zafar et al. 2010, the scrambler Mitsuba's
    ``independent`` sampler seeds with): ``(h0, h1) = TEA(pixel, key0)``, then
    ``(state, seq) = TEA(h0 + sample, h1 ^ key1)``.

    Notes
    -----
    A sample's random numbers depend on nothing but (key, pixel, sample): not on the lane that
    traces it, the pass it falls in, the other samples of the pass or how many samples a pixel
    gets. That is what makes a k-spp render the prefix of any longer one (nested spp ladders)
    and lets per-pixel sample counts continue each pixel's own stream. For a fixed key the map
    from (pixel, sample) to the TEA input is one to one for samples below 2^32, and TEA is a
    permutation, so no two samples of a frame share a stream.
    """
    h0, h1 = mi.sample_tea_32(pixel_index, key[0])
    state, seq = mi.sample_tea_32(h0 + sample_index, h1 ^ key[1])
    rng = mi.PCG32()
    rng.seed(mi.UInt64(state), mi.UInt64(seq))  # not the constructor: it adds arange(size) to both
    return _sample_stream_type(mi.PCG32, mi.Point2f)(rng)


def render_moments(
    mi,
    scene,
    streams,
    camera: DrCamera,
    opts: KernelOptions,
    pixel_x,
    pixel_y,
    first,
    end,
    step,
    start: dict,
    names: dict,
    sample_targets: dict | None = None,
    sample_slot=None,
):
    """Each lane traces samples ``first, first + step, ... < end`` of pixel ``(pixel_x, pixel_y)`` in a
    loop, continuing running per-lane moments (Welford: mean and sum of squared deviations) of the
    buffers in ``names`` (name → channels): one kernel yields per-pixel statistics without storing samples.

    ``streams(s)`` is the :func:`sample_stream` of sample index ``s`` (UInt32 per lane). ``start``
    holds the lane's moments so far (name → (mean, m2)); the lane's samples are ``s ≡ first (mod
    step)``, so sample ``s`` is its ``s // step + 1``-th and the Welford weight needs no counter: a
    lane that continues over several calls gives the same bits as one call over all its samples.

    ``sample_targets`` (name → (flat Float array, channels)) also receives per-sample values: sample
    ``s`` of a lane is written to row ``sample_slot(s)`` (row-major, channels innermost).
    Returns ``{name: (mean, m2)}`` as Dr.Jit arrays (one entry per lane).
    """
    import drjit as dr

    mean = {k: start[k][0] for k in names}
    m2 = {k: start[k][1] for k in names}
    s = mi.UInt32(first)
    end = mi.UInt32(end)

    def cond(s, mean, m2):
        return s < end

    tracer = trace
    if opts.media:  # participating media: the volumetric tracer (a scene without media never imports it)
        from denoisebench.generator.render.volpath import trace as tracer

    def body(s, mean, m2):
        out = tracer(mi, scene, streams(s), camera, opts, pixel_x, pixel_y)
        inv_n = dr.rcp(mi.Float(s // step + 1))
        new_mean, new_m2 = {}, {}
        for k, c in names.items():
            value = channel_type(mi, c)(out[k])
            delta = value - mean[k]
            new_mean[k] = dr.fma(delta, inv_n, mean[k])
            new_m2[k] = dr.fma(delta, value - new_mean[k], m2[k])
        if sample_targets:
            slot = sample_slot(s)
            for k, (target, channels) in sample_targets.items():
                value = out[k]
                for c in range(channels):
                    dr.scatter(target, value if channels == 1 else value[c], slot * channels + c)
        return s + step, new_mean, new_m2

    # Dr.Jit's loop optimisation records a loop twice whenever a state variable is loop-invariant,
    # and the path loop's sample stream always carries one (its PCG32 stream increment); nested in
    # the sample loop, the path loop was recorded four times per frame. Python tracing is a fixed
    # cost per frame (~20 ms, a sixth of a 64x64 16-spp frame), so record once: the invariants stay
    # plain loop variables, which costs nothing measurable and gives the same bits.
    with dr.scoped_set_flag(dr.JitFlag.OptimizeLoops, False):
        s, mean, m2 = dr.while_loop(state=(s, mean, m2), cond=cond, body=body, label="denoisebench samples per pixel")
    return {k: (mean[k], m2[k]) for k in names}


def merge_lanes(mi, moments: dict, groups: int, total) -> dict:
    """Per-pixel moments of :func:`render_moments`' per-lane ones: name → (mean, M2), one entry per pixel.

    A pixel owns ``groups`` consecutive lanes (lane = pixel * groups + group); group ``g`` holds the
    pixel's samples ``s ≡ g (mod groups)`` below ``total`` (UInt32 per pixel: samples so far), i.e.
    ``total // groups + (g < total % groups)`` of them. Lanes merge by Chan et al.'s rule
    generalised to K groups: ``mean = Σ n_k mean_k / n`` and ``M2 = Σ (M2_k + n_k (mean_k - mean)²)``;
    a pixel without samples gets 0 for both. With one lane per pixel nothing is merged and the
    moments are returned as they are.

    Notes
    -----
    Each pixel gathers its lanes in a loop, in group order, so the sums are the same bits on every
    run and thread count (scatter-adds from lanes that two threads share would add in either order).
    """
    import drjit as dr

    if groups == 1:
        return moments
    lanes = dr.width(next(iter(moments.values()))[0])
    pixels = lanes // groups
    pixel = dr.arange(mi.UInt32, pixels)
    # Sizes as opaque values, so that every image size shares one compiled kernel.
    groups_o = dr.opaque(mi.UInt32, groups)
    first = pixel * groups_o
    total = mi.UInt32(total)
    base = total // groups_o
    rem = total - base * groups_o
    inv_total = dr.select(total > 0, dr.rcp(mi.Float(total)), 0.0)

    def lane_weight(g):
        return mi.Float(base + dr.select(g < rem, mi.UInt32(1), mi.UInt32(0)))

    def cond(g, acc):
        return g < groups_o

    def mean_body(g, acc):
        w = lane_weight(g) * inv_total
        lane = first + g
        return g + 1, {k: dr.fma(dr.gather(type(m), m, lane), w, acc[k]) for k, (m, _) in moments.items()}

    zeros = {k: dr.zeros(type(m), pixels) for k, (m, _) in moments.items()}
    _, means = dr.while_loop((mi.UInt32(0), zeros), cond, mean_body, label="denoisebench lane means")

    def m2_body(g, acc):
        w = lane_weight(g)
        lane = first + g
        new = {}
        for k, (m, m2) in moments.items():
            d = dr.gather(type(m), m, lane) - means[k]
            new[k] = acc[k] + dr.fma(w, dr.square(d), dr.gather(type(m2), m2, lane))
        return g + 1, new

    _, m2s = dr.while_loop((mi.UInt32(0), zeros), cond, m2_body, label="denoisebench lane M2")
    return {k: (means[k], m2s[k]) for k in moments}


def variance_scale(mi, total):
    """``1 / ((n - 1) n)`` as float32 per pixel (``n = total``, UInt32), 0 where ``n <= 1``.

    Computed in float64 and rounded once to float32, as NumPy computes ``1 / ((n - 1) * n)`` from
    float64 counts: the same bits (the product is exact for ``n < 2^26``; the division is IEEE).
    """
    import drjit as dr

    n = mi.Float64(total)
    return dr.select(total > 1, mi.Float(1.0 / ((n - 1.0) * n)), 0.0)


def pixel_buffers(mi, moments: dict, names: dict, groups: int, total) -> dict:
    """The buffers of :func:`render_moments`' per-lane moments: name → (mean, variance of the mean).

    Each is a flat Float of the band's pixels, row-major with channels innermost (an H×W×C image
    as NumPy reads it), so the host reads every buffer as it is, without a copy. ``total`` is
    UInt32 per pixel, the samples so far (:func:`merge_lanes`). The variance of the mean is
    ``max(M2, 0) * variance_scale(total)`` in float32, with ``np.maximum``'s NaN rule (a NaN M2 stays
    NaN; Dr.Jit's own maximum would return 0), and ``inf`` for a pixel without samples (its mean is
    0). (A -0.0 M2 would read +0.0; Welford's sums start at +0.0 and never reach -0.0.)

    Notes
    -----
    One kernel merges the lanes and writes every buffer (with one lane per pixel it is the tracing
    kernel itself). A buffer of several channels is one scatter of a ``C``-wide array, which writes
    whole pixels (``pixel * C + channel``).
    """
    import drjit as dr

    merged = merge_lanes(mi, moments, groups, total)
    pixels = dr.width(next(iter(merged.values()))[0])
    pixel = dr.arange(mi.UInt32, pixels)
    total = mi.UInt32(total)
    scale = variance_scale(mi, total)
    empty = total == 0
    out = {}
    for k, c in names.items():
        mean, m2 = merged[k]
        var = dr.select(empty, dr.inf, dr.select(m2 <= 0, 0.0, m2) * scale)
        pair = []
        for value in (mean, var):
            target = dr.empty(mi.Float, pixels * c)
            if c == 1:
                dr.scatter(target, value, pixel)
            else:
                row_type = getattr(importlib.import_module(type(value).__module__), "ArrayXf")
                dr.scatter(target, row_type(*(value[j] for j in range(c))), pixel)
            pair.append(target)
        out[k] = tuple(pair)
    return out
