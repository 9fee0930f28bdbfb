"""The TranslatedScene contract: typed, frozen records that survive pickling (Ray ships them)."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from denoisebench.generator.contract.scene_parts import AreaEmitter, MeshShape, ShutterMotion
from denoisebench.generator.usd.translate import translate_stage
from tests.support.motion_helpers import FRAMES, moving_box_stage


@pytest.fixture(scope="module")
def translated(tmp_path_factory):
    return translate_stage(moving_box_stage(tmp_path_factory.mktemp("box")))


def test_records_are_typed_and_frozen(translated):
    assert translated.shapes and all(isinstance(s, MeshShape) for s in translated.shapes)
    (box,) = [s for s in translated.shapes if s.shutter_motion is not None]
    assert isinstance(box.shutter_motion, ShutterMotion) and box.frame_positions.shape[0] == FRAMES
    (lamp,) = [s for s in translated.shapes if s.emitter is not None]
    assert isinstance(lamp.emitter, AreaEmitter) and lamp.light == "RectLight" and lamp.bsdf is None
    with pytest.raises(dataclasses.FrozenInstanceError):
        box.bsdf = "other"
    assert translated.mitsuba_xml is None and translated.transport_origin == ""
    assert translated.summary()["shapes"] == {"mesh": len(translated.shapes)}


def test_a_translated_scene_survives_pickling(translated):
    copy = pickle.loads(pickle.dumps(translated))
    assert (copy.moving, copy.shutter_moving) == (True, True)
    assert [type(s) for s in copy.shapes] == [type(s) for s in translated.shapes]
    for ours, theirs in zip(copy.shapes, translated.shapes):
        assert ours.name == theirs.name and ours.bsdf == theirs.bsdf
        np.testing.assert_array_equal(ours.positions, theirs.positions)
        if theirs.shutter_motion is not None:
            np.testing.assert_array_equal(ours.shutter_motion.to_world, theirs.shutter_motion.to_world)
    assert copy.bsdfs.keys() == translated.bsdfs.keys() and copy.summary() == translated.summary()
