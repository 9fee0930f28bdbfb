"""The render plan is a pure function of effects and options: each effect present and absent."""

from __future__ import annotations

import json

import pytest

from denoisebench.generator.render_plan import (
    DEFAULT_INDIRECT_DEPTH,
    DELTA_CHAIN_DEPTH,
    DIRECT_ONLY_DEPTH,
    RenderOptions,
    RenderPlan,
    make_render_plan,
)
from denoisebench.scenes.effects import EFFECTS


def test_nothing_special_is_the_cheapest_plan():
    plan = make_render_plan([])
    assert plan.camera_model == "pinhole"
    assert not plan.time_sampling
    assert plan.max_depth == DIRECT_ONLY_DEPTH
    assert plan.random_parameters == ("pixel",)
    assert not plan.lobe_split
    assert plan.pixel_filter == "box"


@pytest.mark.parametrize("effect", EFFECTS)
def test_each_effect_present_and_absent(effect):
    others = [e for e in EFFECTS if e != effect]
    with_effect, without = make_render_plan(EFFECTS), make_render_plan(others)
    if effect == "depth_of_field":
        assert (with_effect.camera_model, without.camera_model) == ("thin_lens", "pinhole")
        assert "lens" in with_effect.random_parameters and "lens" not in without.random_parameters
    elif effect == "motion_blur":
        assert with_effect.time_sampling and not without.time_sampling
        assert "time" in with_effect.random_parameters and "time" not in without.random_parameters
    elif effect == "indirect":
        assert with_effect.max_depth == DEFAULT_INDIRECT_DEPTH
        assert without.max_depth == DELTA_CHAIN_DEPTH  # specular/transmission still present
        assert make_render_plan(["indirect"]).max_depth == DEFAULT_INDIRECT_DEPTH
        assert make_render_plan(["glossy"]).max_depth == DIRECT_ONLY_DEPTH
    elif effect in ("specular", "transmission"):
        assert make_render_plan([effect]).max_depth == DELTA_CHAIN_DEPTH
        assert make_render_plan([effect]).lobe_split
    elif effect == "glossy":
        assert make_render_plan([effect]).lobe_split and not make_render_plan(["textures"]).lobe_split
    else:  # textures, area_lights, environment change what is rendered, not how
        import dataclasses

        assert make_render_plan([effect]) == dataclasses.replace(make_render_plan([]), effects=(effect,))
    assert with_effect.effects == EFFECTS and effect not in without.effects


def test_options_cannot_change_a_scene_without_the_effect():
    plain = make_render_plan(["area_lights"])
    tweaked = make_render_plan(["area_lights"], RenderOptions(aperture_scale=3.0, shutter_scale=0.0))
    assert plain == tweaked
    lens = make_render_plan(["depth_of_field"], RenderOptions(aperture_scale=3.0))
    assert lens.aperture_scale == 3.0
    shutter = make_render_plan(["motion_blur"], RenderOptions(shutter_scale=0.5))
    assert shutter.shutter_scale == 0.5


def test_user_depth_and_per_sample_options():
    plan = make_render_plan(["indirect"], RenderOptions(max_depth=3, per_sample=True))
    assert plan.max_depth == 3 and plan.per_sample
    assert any("set by the user" in note for note in plan.notes)
    with pytest.raises(ValueError, match="max_depth"):
        RenderOptions(max_depth=0)
    with pytest.raises(ValueError, match="aperture_scale"):
        RenderOptions(aperture_scale=-1)


def test_pure_and_order_independent():
    a = make_render_plan(["motion_blur", "glossy", "depth_of_field"])
    b = make_render_plan(["depth_of_field", "glossy", "motion_blur", "glossy"])
    assert a == b and a.to_json() == b.to_json()


def test_json_round_trip():
    plan = make_render_plan(EFFECTS, RenderOptions(per_sample=True))
    data = json.loads(plan.to_json())
    assert data["random_parameters"] == ["pixel", "lens", "time"]
    assert RenderPlan.from_dict(data) == plan


def test_unknown_effect_is_named():
    with pytest.raises(ValueError, match="unknown effect.*caustics"):
        make_render_plan(["glossy", "caustics"])
