"""Frozen render passes replay exactly what a fresh trace computes.

The feature renderer records each pass configuration once with ``dr.freeze`` and replays its kernels
for later frames; the camera pose, lens, time, seed and rows must be inputs of the recording, never
constants baked into it. Peer: the same frame traced afresh (``FREEZE_PASSES`` off), bit for bit,
for frames rendered *after* the recording one, and after other configurations ran in between.
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render import passes as render_passes
from denoisebench.generator.render.frame import load_scene, render_frame
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.mitsuba_runtime import load_mitsuba
from denoisebench.scenes import get_family

SIZE = 16


pytestmark = pytest.mark.skipif(
    not load_mitsuba().variant().startswith("llvm"), reason="needs the LLVM variant (libLLVM >= 16)"
)


def _assert_same(a, b, frame) -> None:
    assert a.buffers.keys() == b.buffers.keys()
    for name in a.buffers:
        assert np.array_equal(a.buffers[name], b.buffers[name]), (frame, name)
    assert (a.samples is None) == (b.samples is None)
    for name in a.samples or {}:
        assert np.array_equal(a.samples[name], b.samples[name]), (frame, name)


# motion_blur: per-ray poses and time; depth_of_field: thin lens; glass_env: delta chains, environment.
@pytest.mark.parametrize("family", ["motion_blur", "depth_of_field", "glass_env"])
def test_replayed_frames_equal_fresh_traces(monkeypatch, tmp_path, family):
    translated = translate_usd(get_family(family).author(tmp_path, seed=0, frames=4, width=SIZE, height=SIZE))
    scene = build_mitsuba_scene(translated)
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    # Frame 0 has no previous frame (another configuration); frame 1 records, frames 2 and 3 replay
    # with other poses, times and seeds, and the reference configuration runs in between.
    frames = [0, 1, 2, 3]
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", True)
    frozen = []
    for f in frames:
        frozen.append(render_frame(scene, translated.camera, f, plan, width=SIZE, height=SIZE, spp=2, seed=3))
        render_frame(scene, translated.camera, f, plan, width=SIZE, height=SIZE, spp=4, seed=3, reference=True)
    frozen_ref = render_frame(scene, translated.camera, 3, plan, width=SIZE, height=SIZE, spp=4, seed=3, reference=True)
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", False)
    for f, out in zip(frames, frozen):
        _assert_same(out, render_frame(scene, translated.camera, f, plan, width=SIZE, height=SIZE, spp=2, seed=3), f)
    fresh_ref = render_frame(scene, translated.camera, 3, plan, width=SIZE, height=SIZE, spp=4, seed=3, reference=True)
    _assert_same(frozen_ref, fresh_ref, "reference")
    # The frames really differ (the camera moves), so equal bytes are not one replayed frame.
    assert not np.array_equal(frozen[2].buffers["color"], frozen[3].buffers["color"])


def test_sizes_seeds_and_scenes_change_between_replays(monkeypatch):
    box = load_mitsuba().cornell_box()
    del box["sensor"]
    scenes = [load_scene(box), load_scene(box)]  # equal content, distinct objects
    pose = np.eye(4)
    pose[2, 3] = 3.9
    camera = CameraTrack(poses=np.stack([pose, pose, pose]), fov_x_deg=39.3)
    plan = make_render_plan(["area_lights", "indirect"])
    calls = [
        (scenes[0], dict(width=SIZE, height=SIZE, spp=3, seed=1)),
        (scenes[0], dict(width=SIZE, height=SIZE, spp=3, seed=2)),  # replay, other seed
        (scenes[0], dict(width=SIZE + 5, height=SIZE - 3, spp=3, seed=2)),  # other (odd) size
        (scenes[0], dict(width=SIZE, height=SIZE, spp=5, seed=2)),  # other spp: other lanes per pixel
        (scenes[1], dict(width=SIZE, height=SIZE, spp=3, seed=2)),  # other scene object
        (scenes[0], dict(width=SIZE, height=SIZE, spp=3, seed=2, max_paths_per_pass=SIZE * 5)),  # row bands
    ]
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", True)
    frozen = [render_frame(scene, camera, 1, plan, **kw) for scene, kw in calls[:2]]
    # The second call replayed the first one's recording: no fallback to tracing, no re-recording.
    (compiled,) = render_passes._COMPILED.values()
    assert compiled.frozen is not None and compiled.frozen.n_recordings == 1
    frozen += [render_frame(scene, camera, 1, plan, **kw) for scene, kw in calls[2:]]
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", False)
    for k, ((scene, kw), out) in enumerate(zip(calls, frozen)):
        _assert_same(out, render_frame(scene, camera, 1, plan, **kw), k)
    assert not np.array_equal(frozen[0].buffers["color"], frozen[1].buffers["color"])  # seeds do matter


@pytest.mark.slow
def test_motion_blur_reference_rounds_record_each_pass_once(monkeypatch, tmp_path, capfd):
    """An adaptive reference's rounds (fresh seeds) and later frames replay the recordings.

    Regression: the camera's arrays were NumPy buffers mapped by Dr.Jit, whose alignment (part of a
    frozen function's input layout) varied from one array to the next, so a motion-blurred scene
    (per-ray pose tables, rebuilt every pass) recorded a new variant of nearly every pass, and Dr.Jit
    printed "The frozen function has been recorded N times" from the third on. Each configuration
    (noisy frame 0 / later frames, reference frame 0 / later frames) must be recorded exactly once.
    """
    from denoisebench.generator.render.reference import MIN_ROUNDS, render_adaptive, round_seed

    translated = translate_usd(get_family("motion_blur").author(tmp_path, seed=0, frames=3, width=SIZE, height=SIZE))
    scene = build_mitsuba_scene(translated)
    plan = make_render_plan(translated.effects, RenderOptions(), stage_max_depth=translated.max_depth)
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", True)
    kw = dict(width=SIZE, height=SIZE)
    for frame in (0, 1, 2):
        render_frame(scene, translated.camera, frame, plan, spp=2, seed=3, **kw)

        def render_round(k, round_spp, frame=frame):
            out = render_frame(
                scene, translated.camera, frame, plan, spp=round_spp, seed=round_seed(3, frame, k), reference=True, **kw
            )
            return out.buffers, out.seconds, 0.0

        # cap 128: rounds of 2 spp; a target every floor meets stops after MIN_ROUNDS rounds
        assert render_adaptive(render_round, 128, 1e9).record["rounds"] == MIN_ROUNDS
    counts = {}
    for config, compiled in render_passes._COMPILED.items():
        assert compiled.frozen is not None, config  # no fallback to plain tracing
        counts[(config.opts.features, config.switches.has_previous)] = compiled.frozen.n_recordings
    assert counts == {(True, False): 1, (True, True): 1, (False, False): 1, (False, True): 1}
    assert "frozen function has been recorded" not in capfd.readouterr().err


def test_moving_shapes_replay_equals_fresh_traces(monkeypatch, tmp_path):
    """Object motion blur within the shutter (render/motion.py) on frozen passes: a ShutterMotionScene
    is a Dr.Jit PyTree, so its layout scenes and pose tables are inputs of the recording. Frames 1 and
    2 of one scene object (other camera times, other seeds) and reference rounds replay; every one
    equals a fresh trace bit for bit, and the replays really replayed (no fallback to tracing)."""
    from denoisebench.generator.render.motion import ShutterMotionScene
    from denoisebench.generator.usd.translate import translate_stage
    from tests.support.motion_helpers import moving_box_stage

    translated = translate_stage(moving_box_stage(tmp_path, "stretch"))
    scene = build_mitsuba_scene(translated, frame=1)
    assert isinstance(scene, ShutterMotionScene)
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=True))
    calls = [dict(frame=f, spp=2, seed=s, reference=r) for f, s, r in ((1, 3, False), (2, 4, False), (1, 5, False))]
    calls += [dict(frame=f, spp=4, seed=s, reference=True) for f, s in ((1, 1), (1, 2), (2, 3), (1, 4))]
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", True)
    frozen = []
    for kw in calls:
        kw = dict(kw)
        frozen.append(render_frame(scene, translated.camera, kw.pop("frame"), plan, width=SIZE, height=SIZE, **kw))
    recorded = [c.frozen for c in render_passes._COMPILED.values()]
    assert recorded and all(f is not None for f in recorded)  # recorded, not traced
    # Dr.Jit 1.5 records a function over several mi.Scene inputs twice (its third call), then replays.
    assert all(f.n_recordings <= 2 for f in recorded), [f.n_recordings for f in recorded]
    monkeypatch.setattr(render_passes, "FREEZE_PASSES", False)
    for k, (kw, out) in enumerate(zip(calls, frozen)):
        kw = dict(kw)
        fresh = render_frame(scene, translated.camera, kw.pop("frame"), plan, width=SIZE, height=SIZE, **kw)
        _assert_same(out, fresh, k)
    assert not np.array_equal(frozen[0].buffers["color"], frozen[2].buffers["color"])  # seeds do matter
