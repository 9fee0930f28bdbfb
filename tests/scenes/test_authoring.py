"""SceneBuilder's constructor: the output folder, then every other argument by name."""

from __future__ import annotations

import pytest

from denoisebench.scenes.authoring import SceneBuilder


def test_scene_builder_takes_everything_after_the_folder_by_name(tmp_path):
    with pytest.raises(TypeError):
        SceneBuilder(tmp_path, "test", 0, 1, ("area_lights",))
    builder = SceneBuilder(tmp_path, family="test", seed=3, frames=2, effects=("area_lights",), up_axis="Z")
    assert (builder.family, builder.seed, builder.frames, builder.up_axis) == ("test", 3, 2, "Z")
    assert builder.stage.GetEndTimeCode() == 1
