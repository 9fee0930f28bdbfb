"""Per-pixel sample counts (ProgressiveFrame): rounds that continue each pixel's own stream.

Peers: plain renders at uniform spp with the same seed (a pixel with k samples after any rounds
has exactly the buffers of a k-spp render, bit for bit), the reference stream (statistics over
seeds for an uneven map), and the round's per-sample data against the plain render's. Images are
16 px, a few samples.
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render.frame import render_frame
from denoisebench.generator.render.progressive import ProgressiveFrame, RenderClock, RoundBuffers
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family

SIZE = 16


@pytest.fixture(scope="module")
def cornell(mi, tmp_path_factory):
    out = tmp_path_factory.mktemp("cornell")
    translated = translate_usd(get_family("cornell").author(out, seed=0, frames=2, width=SIZE, height=SIZE))
    return translated, build_mitsuba_scene(translated)


def _frame(cornell, seed=3, **kw):
    translated, scene = cornell
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=kw.pop("per_sample", False)))
    return ProgressiveFrame(scene, translated.camera, 1, plan, width=SIZE, height=SIZE, seed=seed, **kw), plan


def _plain(cornell, plan, spp, seed=3, reference=False):
    translated, scene = cornell
    return render_frame(
        scene, translated.camera, 1, plan, width=SIZE, height=SIZE, spp=spp, seed=seed, reference=reference
    )


def test_uniform_rounds_equal_a_plain_render(cornell):
    """A uniform map of 2 then of 3: the bytes of a plain 5-spp render (and 2 of a plain 2-spp one)."""
    frame, plan = _frame(cornell)
    first = frame.render_round(np.full((SIZE, SIZE), 2))
    assert isinstance(first, RoundBuffers) and first.counts.dtype == np.int32 and (first.counts == 2).all()
    assert first.seconds > 0 and first.samples is None
    plain2 = _plain(cornell, plan, 2)
    for name in plain2.buffers:
        assert np.array_equal(first.buffers[name], plain2.buffers[name]), name
    second = frame.render_round(np.full((SIZE, SIZE), 3))
    plain5 = _plain(cornell, plan, 5)
    assert second.buffers.keys() == plain5.buffers.keys()
    for name in plain5.buffers:
        assert np.array_equal(second.buffers[name], plain5.buffers[name]), name
    # The reference stream too.
    reference, _ = _frame(cornell, reference=True)
    out = reference.render_round(np.full((SIZE, SIZE), 4))
    assert set(out.buffers) == {"color", "diffuse", "specular", "color_var", "diffuse_var", "specular_var"}
    assert np.array_equal(out.buffers["color"], _plain(cornell, plan, 4, reference=True).buffers["color"])


def test_uneven_rounds_give_each_pixel_its_own_first_samples(cornell):
    """After two rounds of random counts (0-3 each), a pixel with k samples holds a k-spp render's values."""
    frame, plan = _frame(cornell)
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, 4, (2, SIZE, SIZE))
    frame.render_round(a)
    out = frame.render_round(b)
    total = a + b
    assert np.array_equal(out.counts, total)
    plains = {k: _plain(cornell, plan, int(k)) for k in np.unique(total) if k > 0}
    for k, plain in plains.items():
        here = total == k
        for name in plain.buffers:
            assert np.array_equal(out.buffers[name][here], plain.buffers[name][here]), (k, name)
    empty = total == 0
    assert empty.any() and not out.buffers["color"][empty].any()
    assert np.isinf(out.buffers["color_var"][empty]).all()  # no sample: variance unknown (inf)
    assert np.isfinite(out.buffers["color_var"][~empty]).all()
    assert (out.buffers["color_var"][total == 1] == 0).all()  # one sample: 0, as in 1-spp files


def test_round_samples_continue_each_pixel_stream(cornell):
    frame, plan = _frame(cornell, per_sample=True, keep_samples=True)
    counts = np.zeros((SIZE, SIZE), np.int64)
    counts[:, SIZE // 2 :] = 2  # left half none, right half 2
    frame.render_round(np.ones((SIZE, SIZE), np.int64))
    out = frame.render_round(counts)
    plain = _plain(cornell, plan, 3)
    for name, values in out.samples.items():
        assert values.shape[:3] == (2, SIZE, SIZE), name
        assert np.array_equal(values[:, :, SIZE // 2 :], plain.samples[name][1:3, :, SIZE // 2 :]), name
        assert not values[:, :, : SIZE // 2].any(), name  # rows past a pixel's count are zero


def test_an_uneven_map_is_unbiased(cornell):
    """Over 24 seeds, an image whose pixels got 1 or 6 samples averages to the reference (z-tests)."""
    translated, scene = cornell
    counts = np.where((np.arange(SIZE)[:, None] + np.arange(SIZE)) % 3 == 0, 6, 1)
    images = []
    for seed in range(24):
        frame, plan = _frame(cornell, seed=seed)
        images.append(frame.render_round(counts).buffers["color"].astype(np.float64))
    images = np.stack(images)
    truth = _plain(cornell, plan, 2048, seed=99, reference=True)
    for k in (1, 6):
        here = counts == k
        ours = images[:, here].mean(axis=1)  # seeds × 3: the mean over those pixels
        ref = truth.buffers["color"][here].astype(np.float64).mean(0)
        ref_var = truth.buffers["color_var"][here].astype(np.float64).sum(0) / here.sum() ** 2
        z = (ours.mean(0) - ref) / np.sqrt(ours.var(0, ddof=1) / len(ours) + ref_var)
        assert np.abs(z).max() < 4.0, (k, z)


@pytest.mark.parametrize(
    "counts, message",
    [
        (np.ones((SIZE, SIZE + 1), np.int64), "must be 16x16"),
        (-np.ones((SIZE, SIZE), np.int64), ">= 0"),
        (np.ones((SIZE, SIZE)), "integers"),
    ],
)
def test_bad_count_maps_are_refused(cornell, counts, message):
    frame, _ = _frame(cornell)
    with pytest.raises(ValueError, match=message):
        frame.render_round(counts)
    assert not frame.counts.any()


def test_the_kernel_history_is_on_only_while_a_clock_lives(cornell):
    """Dr.Jit's kernel history keeps every launch's IR until drained: a round that is done must leave it off and
    empty, or every later render of the process piles up its kernels' source."""
    import drjit as dr

    frame, _ = _frame(cornell)
    frame.render_round(np.full((SIZE, SIZE), 2))
    assert not dr.flag(dr.JitFlag.KernelHistory)
    frame.render_round(np.full((SIZE, SIZE), 2))  # a round of its own: its clock drains what it records
    first, second = RenderClock(), RenderClock()
    assert dr.flag(dr.JitFlag.KernelHistory)
    del first
    assert dr.flag(dr.JitFlag.KernelHistory)  # the other clock still reads it
    dr.eval(dr.arange(dr.llvm.Float, 7) * 3.0)
    assert second() > 0.0 and second.compile_seconds >= 0.0
    del second
    assert not dr.flag(dr.JitFlag.KernelHistory)
    _plain(cornell, make_render_plan(cornell[0].effects, RenderOptions()), 2)
    dr.eval(dr.arange(dr.llvm.Float, 9) * 5.0)
    assert dr.kernel_history() == []
