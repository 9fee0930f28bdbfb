"""The buffers the pass kernels write (render/moments.py ``pixel_buffers``) against NumPy's formula.

Peer: the host assembly the renderer used before the kernels wrote the buffers themselves, i.e. a
buffer's mean is the pixel's merged mean and its variance of the mean ``np.maximum(M2, 0) *
np.float32(1 / ((n - 1) n))`` (``n`` in float64), ``inf`` for a pixel without samples. The device
result must be the same bits (NaN, negative and infinite M2 included), through a frame of several
bands and rounds of per-pixel counts; and the arrays handed out without a copy must stay what they
were when later rounds render. Images are 24x16 with one lane per pixel (``target_lanes=1``), so
the lanes' moments are the pixels' moments.
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render.frame import FrameStream, render_frame, render_ladder
from denoisebench.generator.render.moments import pixel_buffers, variance_scale
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family

WIDTH, HEIGHT = 24, 16


def numpy_variance(m2: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """The host formula: float32 ``max(M2, 0) * scale``, scale from float64 counts, inf where unsampled."""
    n = counts.astype(np.float64)
    with np.errstate(divide="ignore"):
        scale = np.where(counts > 1, 1.0 / ((n - 1) * n), 0.0).astype(np.float32)
    var = np.maximum(m2, np.float32(0.0)) * scale.reshape(scale.shape + (1,) * (m2.ndim - scale.ndim))
    var[counts == 0] = np.inf
    return var


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_variance_scale_is_numpys_float64_formula_rounded_once(mi):
    counts = np.array([0, 1, 2, 3, 7, 16, 1000, 4097, 1 << 20, (1 << 26) - 1], np.uint32)
    got = np.asarray(variance_scale(mi, mi.UInt32(counts)))
    n = counts.astype(np.float64)
    with np.errstate(divide="ignore"):
        want = np.where(counts > 1, 1.0 / ((n - 1) * n), 0.0).astype(np.float32)
    assert same_bits(got, want)


def test_pixel_buffers_are_the_numpy_formula_bit_for_bit(mi):
    """Synthetic moments with the awkward values: negative, NaN and inf M2; 0, 1 and many samples. (Not -0.0:
    NumPy's maximum leaves its sign to the platform, and the renderer's M2 is never -0.0.)"""
    rng = np.random.default_rng(5)
    pixels = 64
    mean = rng.normal(size=(pixels, 3)).astype(np.float32)
    m2 = rng.normal(size=(pixels, 3)).astype(np.float32)  # about half negative: rounding in Welford's update
    m2[3] = [0.0, np.nan, np.inf]
    m2[4] = [np.nan, -np.inf, 0.0]
    depth_mean = rng.normal(size=pixels).astype(np.float32)
    depth_m2 = np.abs(rng.normal(size=pixels)).astype(np.float32)
    counts = rng.integers(0, 40, pixels).astype(np.uint32)
    counts[:3] = [0, 1, 2]
    counts[3:5] = [5, 1]
    moments = {
        "color": (mi.Color3f(mean.T), mi.Color3f(m2.T)),
        "depth": (mi.Float(depth_mean), mi.Float(depth_m2)),
    }
    out = pixel_buffers(mi, moments, {"color": 3, "depth": 1}, 1, mi.UInt32(counts))
    assert same_bits(np.asarray(out["color"][0]).reshape(pixels, 3), mean)
    assert same_bits(np.asarray(out["color"][1]).reshape(pixels, 3), numpy_variance(m2, counts))
    assert same_bits(np.asarray(out["depth"][0]), depth_mean)
    assert same_bits(np.asarray(out["depth"][1]), numpy_variance(depth_m2, counts))


@pytest.fixture(scope="module")
def cornell(mi, tmp_path_factory):
    translated = translate_usd(
        get_family("cornell").author(tmp_path_factory.mktemp("cornell"), seed=0, frames=2, width=WIDTH, height=HEIGHT)
    )
    plan = make_render_plan(translated.effects, RenderOptions(max_depth=4))
    return translated.camera, build_mitsuba_scene(translated), plan


def test_frame_buffers_are_the_lanes_moments_through_bands_and_rounds(cornell):
    """Three bands of rows, rounds of per-pixel counts (a band without samples at first): every buffer is
    the NumPy formula of the lanes' moments, and unsampled pixels read mean 0, variance inf."""
    camera, scene, plan = cornell
    stream = FrameStream(
        scene, camera, 1, plan, width=WIDTH, height=HEIGHT, seed=2, target_lanes=1, max_paths_per_pass=WIDTH * 6
    )
    assert len(stream._bands) == 3 and stream.lanes_per_pixel == 1
    rng = np.random.default_rng(1)
    rounds = [rng.integers(0, 4, (HEIGHT, WIDTH)) for _ in range(3)] + [np.full((HEIGHT, WIDTH), 2)]
    rounds[0][:6] = 0  # the first band has no samples after the first round
    for counts in rounds:
        stream.advance(counts)
        out = stream.buffers()
        total = stream.counts
        for name, channels in stream.stat_channels.items():
            mean = np.concatenate([np.asarray(dr_mean_m2(state, name, 0)) for state in stream._state if state])
            m2 = np.concatenate([np.asarray(dr_mean_m2(state, name, 1)) for state in stream._state if state])
            sampled = np.concatenate(
                [np.full(b * WIDTH, s is not None) for (_, b), s in zip(stream._bands, stream._state)]
            )
            want_mean = np.zeros((HEIGHT * WIDTH, channels), np.float32)
            want_m2 = np.zeros((HEIGHT * WIDTH, channels), np.float32)
            want_mean[sampled], want_m2[sampled] = mean.reshape(-1, channels), m2.reshape(-1, channels)
            shape = (HEIGHT, WIDTH, channels)
            assert same_bits(out[name], want_mean.reshape(shape)), name
            assert same_bits(out[f"{name}_var"], numpy_variance(want_m2.reshape(shape), total)), name
        assert np.isinf(out["color_var"][total == 0]).all() and (out["color"][total == 0] == 0).all()
        assert np.isfinite(out["color_var"][total > 0]).all()


def dr_mean_m2(state: dict, name: str, part: int) -> np.ndarray:
    """A band's lanes' mean (part 0) or M2 (part 1) of ``name`` as lanes × channels."""
    value = np.asarray(state[name][part])
    return value.T if value.ndim == 2 else value


def test_zero_copy_rungs_keep_their_bytes_and_buffers_are_the_callers(cornell):
    """A ladder hands each rung the arrays its last pass wrote: later rungs must not overwrite them (each
    equals a plain render at its spp); FrameStream.buffers() returns arrays the caller may write into."""
    camera, scene, plan = cornell
    kw = dict(width=WIDTH, height=HEIGHT, seed=9, target_lanes=1)
    ladder = render_ladder(scene, camera, 1, plan, rungs=(1, 2, 3), **kw)
    for rung in ladder:
        plain = render_frame(scene, camera, 1, plan, spp=rung.spp, **kw)
        for name, value in plain.buffers.items():
            assert same_bits(rung.buffers[name], value), (rung.spp, name)
    stream = FrameStream(scene, camera, 1, plan, width=WIDTH, height=HEIGHT, seed=9, target_lanes=1)
    stream.advance(2)
    first = stream.buffers()
    kept = first["color"].copy()
    first["color"][:] = -1.0
    assert same_bits(stream.buffers()["color"], kept)


def test_one_count_for_all_pixels_gives_the_bytes_of_a_per_pixel_map(cornell):
    """Rounds given as one int (0-d arithmetic while every pixel has the same count) and the same rounds as
    H×W maps: the same counts and buffers after each round, also once a per-pixel round breaks uniformity."""
    camera, scene, plan = cornell
    kw = dict(width=WIDTH, height=HEIGHT, seed=4, max_paths_per_pass=WIDTH * 6)
    scalar, mapped = (FrameStream(scene, camera, 1, plan, **kw) for _ in range(2))
    uneven = np.arange(HEIGHT * WIDTH).reshape(HEIGHT, WIDTH) % 3
    for counts in (2, 1, uneven, 3):
        scalar.advance(counts)
        mapped.advance(np.broadcast_to(counts, (HEIGHT, WIDTH)).copy())
        assert np.array_equal(scalar.counts, mapped.counts)
        a, b = scalar.buffers(), mapped.buffers()
        assert a.keys() == b.keys()
        for name in a:
            assert same_bits(a[name], b[name]), (counts if np.ndim(counts) == 0 else "map", name)
