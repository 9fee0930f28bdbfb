"""Frame jobs build a scene with object motion blur once per sequence, and that changes no byte.

:func:`~denoisebench.generator.frame_jobs.scene_varies_by_frame` decides whether a scene is rebuilt
per frame: with shapes moving within the shutter (posed at each ray's time, in their object space)
one Mitsuba scene serves every frame. The peer is the rule it replaced (rebuild for every frame of
any moving scene): every rung and reference layer of every frame must be the same bytes.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from denoisebench.generator import frame_jobs
from denoisebench.generator.frame_jobs import FrameJob, render_job, scene_varies_by_frame
from denoisebench.generator.usd.translate import translate_stage
from tests.support.motion_helpers import FRAMES, moving_box_stage

SIZE = 16


def _render_sequence(usd_path) -> tuple[list, list]:
    """Every frame's buffers (rungs 1, 2 and a 16-spp reference) and the scene object each frame rendered with."""
    frame_jobs._CACHE.clear()
    buffers, scenes = [], []
    for frame in range(FRAMES):
        result = render_job(FrameJob("s", frame, "reuse", str(usd_path), (1, 2), 16, SIZE, SIZE, 7))
        buffers.append([r.buffers for r in result.noisy] + [result.reference.buffers])
        scenes.append(next(iter(frame_jobs._CACHE.values())).scene_at(frame))
    frame_jobs._CACHE.clear()
    return buffers, scenes


def test_blurred_sequence_reuses_one_scene_with_the_bytes_of_per_frame_builds(tmp_path, monkeypatch):
    stage = moving_box_stage(tmp_path)
    usd_path = tmp_path / "scene.usda"
    stage.GetRootLayer().Export(str(usd_path))
    reused, scenes = _render_sequence(usd_path)
    assert all(s is scenes[0] for s in scenes)
    monkeypatch.setattr(frame_jobs, "scene_varies_by_frame", lambda translated: translated.moving)  # the old rule
    rebuilt, scenes = _render_sequence(usd_path)
    assert len({id(s) for s in scenes}) == FRAMES
    for frame, (ours, theirs) in enumerate(zip(reused, rebuilt)):
        for k, (a, b) in enumerate(zip(ours, theirs)):
            assert a.keys() == b.keys()
            for name in a:
                assert a[name].tobytes() == b[name].tobytes(), (frame, k, name)
    assert not np.array_equal(reused[0][-1]["color"], reused[2][-1]["color"])  # the box does move


def test_scenes_that_move_between_frames_only_are_still_built_per_frame(tmp_path):
    blurred = translate_stage(moving_box_stage(tmp_path / "blur"))
    closed = translate_stage(moving_box_stage(tmp_path / "closed", shutter=(0.0, 0.0)))  # moves between frames only
    emitter = translate_stage(moving_box_stage(tmp_path / "emitter", emissive=True))  # moving emitters keep frame poses
    assert blurred.shutter_moving and not scene_varies_by_frame(blurred)
    assert closed.moving and not closed.shutter_moving and scene_varies_by_frame(closed)
    assert emitter.moving and scene_varies_by_frame(emitter)
    # Blurred movers plus a shape that moves between frames only (here the moving emitter's record).
    lamp = [s for s in emitter.shapes if s.frame_positions is not None]
    assert lamp and lamp[0].shutter_motion is None
    mixed = dataclasses.replace(blurred, shapes=blurred.shapes + tuple(lamp))
    assert mixed.shutter_moving and scene_varies_by_frame(mixed)
    static = translate_stage(moving_box_stage(tmp_path / "static"))
    static.shapes = tuple(
        dataclasses.replace(s, frame_positions=None, frame_normals=None, shutter_motion=None) for s in static.shapes
    )
    assert not static.moving and not scene_varies_by_frame(static)
