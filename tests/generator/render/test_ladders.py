"""Nested spp ladders: every rung a prefix of one progressive sample stream per pixel.

Peers and invariants: a rung against a plain render at its spp with the same seed (the same
bytes, through the renderer and through ``generate-dataset``'s EXR files), against the
reference stream (each rung unbiased: means over independent seeds), and the ladder's error
against a high-spp reference falling as 1/spp on a diffuse scene (log-log slope). Images are
16-24 px; the kernels compile once per module.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from scipy import stats

from denoisebench.cli import main
from denoisebench.dataset import layout, open_dataset
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render.frame import render_frame, render_ladder
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family

SIZE = 16
BLOCK = 4


@pytest.fixture(scope="module")
def family_scene(mi, tmp_path_factory):
    cache = {}

    def get(name: str, size: int = SIZE):
        if (name, size) not in cache:
            out = tmp_path_factory.mktemp(f"{name}_{size}")
            translated = translate_usd(get_family(name).author(out, seed=0, frames=2, width=size, height=size))
            cache[name, size] = (translated, build_mitsuba_scene(translated))
        return cache[name, size]

    return get


def test_a_rung_is_the_plain_render_at_its_spp(family_scene):
    """Rung 4 of 1,2,4,8 and a plain 4-spp render: the same bytes, buffers and per-sample data."""
    translated, scene = family_scene("depth_of_field")  # thin lens: lens random numbers too
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    kw = dict(width=SIZE, height=SIZE, seed=3)
    ladder = render_ladder(scene, translated.camera, 1, plan, rungs=(8, 1, 4, 2, 4), **kw)
    assert [r.spp for r in ladder] == [1, 2, 4, 8]
    plain = render_frame(scene, translated.camera, 1, plan, spp=4, **kw)
    rung = ladder[2]
    assert rung.buffers.keys() == plain.buffers.keys()
    for name in plain.buffers:
        assert np.array_equal(rung.buffers[name], plain.buffers[name]), name
    for name in plain.samples:
        assert np.array_equal(rung.samples[name], plain.samples[name]), name
        assert np.array_equal(ladder[-1].samples[name][:4], plain.samples[name]), name  # a prefix
    # Each rung is the mean of its samples, with its own variance of the mean.
    for rung in ladder:
        values = rung.samples["color"].astype(np.float64)
        assert values.shape[0] == rung.spp
        assert np.allclose(values.mean(0), rung.buffers["color"], rtol=1e-5, atol=1e-5)
        if rung.spp > 1:
            var = values.var(0, ddof=1) / rung.spp
            assert np.allclose(var, rung.buffers["color_var"], rtol=1e-3, atol=1e-6)
    # Rungs are correlated (shared samples), but they are not one image.
    assert not np.array_equal(ladder[0].buffers["color"], ladder[1].buffers["color"])
    assert [r.seconds for r in ladder] == sorted(r.seconds for r in ladder)  # time to reach each rung


def test_every_rung_is_unbiased(family_scene):
    """Over 24 seeds the mean of each rung agrees with a 2048-spp reference-stream render (block z-tests)."""
    translated, scene = family_scene("cornell")
    plan = make_render_plan(translated.effects)
    kw = dict(width=SIZE, height=SIZE)
    rungs = (1, 2, 4, 8)
    seeds = 24
    images = np.stack(
        [
            np.stack(
                [
                    r.buffers["color"]
                    for r in render_ladder(scene, translated.camera, 1, plan, rungs=rungs, seed=s, **kw)
                ]
            )
            for s in range(seeds)
        ]
    ).astype(np.float64)  # seeds × rungs × H × W × 3
    truth = render_frame(scene, translated.camera, 1, plan, spp=2048, seed=99, reference=True, **kw)

    def blocks(a):
        *lead, h, w, c = a.shape
        return a.reshape(*lead, h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean(axis=(-4, -2))

    truth_blocks = blocks(truth.buffers["color"].astype(np.float64))
    truth_var = blocks(truth.buffers["color_var"].astype(np.float64)) / BLOCK**2
    for k, spp in enumerate(rungs):
        ours = blocks(images[:, k])
        z = (ours.mean(0) - truth_blocks) / np.sqrt(ours.var(0, ddof=1) / seeds + truth_var + 1e-20)
        z = z.ravel()
        assert np.abs(z).max() < 4.5, (spp, np.abs(z).max())
        # z² over 48 block-channels: chi-square with 48 degrees of freedom (t-ish tails: loose bound)
        assert stats.chi2.sf(np.sum(z**2), z.size) > 1e-4, (spp, np.sum(z**2))


def test_ladder_error_falls_as_one_over_spp_on_a_diffuse_scene(family_scene):
    """MSE against a reference, less the reference's own floor, has log-log slope about -1 over 1..64 spp."""
    translated, scene = family_scene("cornell", 24)
    plan = make_render_plan(translated.effects)
    kw = dict(width=24, height=24)
    rungs = (1, 2, 4, 8, 16, 32, 64)
    truth = render_frame(scene, translated.camera, 1, plan, spp=1024, seed=7, reference=True, **kw)
    ref = truth.buffers["color"].astype(np.float64)
    floor = truth.buffers["color_var"].astype(np.float64).mean()
    errors = np.zeros(len(rungs))
    for seed in range(2):
        ladder = render_ladder(scene, translated.camera, 1, plan, rungs=rungs, seed=seed, **kw)
        errors += [np.mean((r.buffers["color"] - ref) ** 2) - floor for r in ladder]
    errors /= 2
    assert (errors > 0).all(), errors
    slope = np.polyfit(np.log(rungs), np.log(errors), 1)[0]
    assert -1.2 < slope < -0.8, (slope, errors)


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_generate_dataset_rung_equals_plain_render_and_independent_rungs_are_recorded(mi, tmp_path):
    base = ["--families", "cornell", "--frames", "1", "--width", "16", "--height", "12", "--ref-error", "0"]
    base += ["--ref-spp", "8", "--seed", "4", "--quiet"]

    def generate(name, *extra):
        out = tmp_path / name
        assert main(["generate", "--out", str(out), *base, *extra]) == 0
        return out, json.loads((out / layout.MANIFEST_NAME).read_text())

    ladder, ladder_manifest = generate("ladder", "--spp", "1,2,4")
    plain, plain_manifest = generate("plain", "--spp", "4")
    independent, independent_manifest = generate("independent", "--spp", "1,2,4", "--independent-rungs")
    assert ladder_manifest["config"]["rungs"] == "nested" and plain_manifest["config"]["rungs"] == "nested"
    assert independent_manifest["config"]["rungs"] == "independent"
    (scene,) = open_dataset(ladder).scenes
    rung4 = layout.noisy_path(scene, 4, 0)
    assert _sha(ladder / rung4) == _sha(plain / rung4)  # the same EXR bytes
    assert _sha(ladder / rung4) != _sha(independent / rung4)
    frames = [open_dataset(independent).frame(scene, spp, 0).color for spp in (1, 2, 4)]
    nested = [open_dataset(ladder).frame(scene, spp, 0).color for spp in (1, 2, 4)]
    # Independent rungs share no samples: rung 1's error is uncorrelated with rung 4's error.
    lit = nested[2] > 0
    err = [f - open_dataset(ladder).frame(scene, 4, 0).reference for f in (*frames, *nested)]
    assert abs(stats.spearmanr(err[0][lit], err[2][lit]).statistic) < 0.3
    assert stats.spearmanr(err[3][lit], err[5][lit]).statistic > 0.3  # nested: rung 1 is part of rung 4
    # Each rung's seconds is the time the progressive render took to reach it.
    renders = open_dataset(ladder).scene(scene).record["renders"]
    seconds = [renders[layout.spp_key(s)][layout.frame_key(0)]["seconds"] for s in (1, 2, 4)]
    assert seconds == sorted(seconds)

    # Resume: a frame whose rungs are incomplete renders again and gets the bytes of an uninterrupted run.
    before = {s: _sha(ladder / layout.noisy_path(scene, s, 0)) for s in (1, 2, 4)}
    (ladder / layout.noisy_path(scene, 2, 0)).unlink()
    assert main(["generate", "--out", str(ladder), *base, "--spp", "1,2,4"]) == 0
    assert {s: _sha(ladder / layout.noisy_path(scene, s, 0)) for s in (1, 2, 4)} == before


def test_frozen_ladder_passes_replay_what_a_fresh_trace_computes(monkeypatch, family_scene):
    """Continuation passes (the lanes' moments as inputs) replayed by dr.freeze: the bits of tracing afresh."""
    from denoisebench.generator.render import passes as render_passes

    translated, scene = family_scene("motion_blur")  # per-ray poses and time
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    kw = dict(width=SIZE, height=SIZE, rungs=(1, 3, 4))
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", True)
    frozen = [render_ladder(scene, translated.camera, 1, plan, seed=s, **kw) for s in (1, 2)]  # 2: a replay
    continuing = [c for c in render_passes._COMPILED.values() if c.frozen is not None]
    assert continuing and all(c.frozen.n_recordings == 1 for c in continuing)
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", False)
    traced = render_ladder(scene, translated.camera, 1, plan, seed=2, **kw)
    for a, b in zip(frozen[1], traced):
        for name in b.buffers:
            assert np.array_equal(a.buffers[name], b.buffers[name]), (b.spp, name)
        for name in b.samples:
            assert np.array_equal(a.samples[name], b.samples[name]), (b.spp, name)
    assert not np.array_equal(frozen[0][-1].buffers["color"], frozen[1][-1].buffers["color"])


def test_buffers_read_finished_rounds_while_a_launched_round_traces(family_scene):
    """launch() queues a round; until finish(), buffers() and counts are those of the rounds before; prefix_buffers(k)
    while lanes hold one sample each. All against plain renders, bit for bit."""
    from denoisebench.generator.render.frame import FrameStream

    translated, scene = family_scene("cornell")
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    kw = dict(width=SIZE, height=SIZE, seed=6)
    stream = FrameStream(scene, translated.camera, 1, plan, **kw)
    stream.advance(2)
    # Lanes hold one sample each (64 lanes per pixel at 16 px): the first sample's buffers without tracing anew.
    assert stream.lanes_per_pixel > 5
    first = stream.prefix_buffers(1)
    with pytest.raises(ValueError):
        stream.prefix_buffers(3)  # more than the stream has
    stream.launch(3)
    with pytest.raises(RuntimeError):
        stream.launch(1)  # one round in flight at a time
    during = stream.buffers()
    assert (stream.counts == 2).all()
    new = stream.finish()
    after = stream.buffers()
    plain2 = render_frame(scene, translated.camera, 1, plan, spp=2, **kw)
    plain5 = render_frame(scene, translated.camera, 1, plan, spp=5, **kw)
    plain1 = render_frame(scene, translated.camera, 1, plan, spp=1, **kw)
    for name in plain2.buffers:
        assert np.array_equal(first[name], plain1.buffers[name]), name
        assert np.array_equal(during[name], plain2.buffers[name]), name
        assert np.array_equal(after[name], plain5.buffers[name]), name
    for name in plain5.samples:
        assert np.array_equal(new[name], plain5.samples[name][2:]), name  # the round's samples: 3..5
    with pytest.raises(RuntimeError):
        stream.finish()


def test_rounds_a_ladder_traces(monkeypatch, family_scene):
    """A plain render is one round; rungs below the lanes per pixel share the first round; the others get one each."""
    from denoisebench.generator.render.frame import FrameStream

    translated, scene = family_scene("cornell")
    plan = make_render_plan(translated.effects)
    launched = []
    launch = FrameStream.launch
    monkeypatch.setattr(FrameStream, "launch", lambda self, counts: launched.append(counts) or launch(self, counts))
    kw = dict(width=SIZE, height=SIZE, seed=2)
    lanes = FrameStream(scene, translated.camera, 1, plan, **kw).lanes_per_pixel  # 64 at 16x16
    render_frame(scene, translated.camera, 1, plan, spp=3, **kw)
    assert launched == [3]
    launched.clear()
    render_ladder(scene, translated.camera, 1, plan, rungs=(1, 2, 4, lanes + 6, lanes + 8), **kw)
    assert launched == [lanes, 6, 2]
