"""The render plan is a pure function of effects and options: each effect present and absent."""

from __future__ import annotations

import json

import pytest

from denoisebench.generator.contract.render_plan import (
    DEFAULT_RR_DEPTH,
    UNBOUNDED_DEPTH,
    RenderOptions,
    RenderPlan,
    make_render_plan,
)
from denoisebench.scenes.effects import EFFECTS


def test_nothing_special_is_the_cheapest_plan():
    plan = make_render_plan([])
    assert plan.camera_model == "pinhole"
    assert not plan.time_sampling
    assert plan.max_depth == UNBOUNDED_DEPTH and plan.rr_depth == DEFAULT_RR_DEPTH == 5  # Mitsuba path's defaults
    assert plan.max_depth_source == "default" and not plan.transport_restricted
    # full transport bounces: the first vertex's random numbers and the second hit are per-sample channels
    assert plan.random_parameters == ("pixel", "light", "bounce")
    assert plan.sample_features == ("position2", "normal2")
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
    elif effect in ("specular", "transmission"):
        assert make_render_plan([effect]).lobe_split
    elif effect == "glossy":
        assert make_render_plan([effect]).lobe_split and not make_render_plan(["textures"]).lobe_split
    elif effect == "media":  # the first free flight's random number joins the per-sample random parameters
        assert "medium" in with_effect.random_parameters and "medium" not in without.random_parameters
    else:  # textures, area_lights, environment, indirect change what is rendered, not how
        import dataclasses

        assert make_render_plan([effect]) == dataclasses.replace(make_render_plan([]), effects=(effect,))
    assert with_effect.effects == EFFECTS and effect not in without.effects
    # The plan prunes work, never light: no effect, present or absent, restricts transport.
    assert with_effect.max_depth == without.max_depth == make_render_plan([effect]).max_depth == UNBOUNDED_DEPTH


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
    assert plan.max_depth_source == "user" and plan.transport_restricted
    assert "max_depth 3" in plan.transport_line() and "--max-depth" in plan.transport_line()
    assert any("by the user" in note for note in plan.notes)
    for bad in (0, -2, 2.5, True):
        with pytest.raises(ValueError, match="max_depth"):
            RenderOptions(max_depth=bad)
    with pytest.raises(ValueError, match="aperture_scale"):
        RenderOptions(aperture_scale=-1)


def test_pure_and_order_independent():
    a = make_render_plan(["motion_blur", "glossy", "depth_of_field"])
    b = make_render_plan(["depth_of_field", "glossy", "motion_blur", "glossy"])
    assert a == b and a.to_json() == b.to_json()


def test_json_round_trip():
    plan = make_render_plan(EFFECTS, RenderOptions(per_sample=True))
    data = json.loads(plan.to_json())
    assert data["random_parameters"] == ["pixel", "lens", "time", "medium", "light", "bounce"]
    assert data["sample_features"] == ["position2", "normal2"]
    assert RenderPlan.from_dict(data) == plan
    # a plan stored before sample_features existed reads back with it empty
    del data["sample_features"]
    assert RenderPlan.from_dict(data).sample_features == ()


@pytest.mark.parametrize(("max_depth", "bounces"), [(1, False), (2, True), (5, True), (UNBOUNDED_DEPTH, True)])
def test_bounce_channels_only_where_paths_bounce(max_depth, bounces):
    """light/bounce random numbers and second-hit features exist only past the first hit (the rule the
    feature renderer writes them by: tests/generator/render/test_features.py checks the plan against its output)."""
    plan = make_render_plan(["depth_of_field"], RenderOptions(max_depth=max_depth, per_sample=True))
    assert plan.random_parameters == ("pixel", "lens") + (("light", "bounce") if bounces else ())
    assert plan.sample_features == (("position2", "normal2") if bounces else ())


def test_unknown_effect_is_named():
    with pytest.raises(ValueError, match="unknown effect.*caustics"):
        make_render_plan(["glossy", "caustics"])


def test_depth_restriction_sources_and_precedence():
    """Stage metadata restricts depth only when the user does not; the plan names who asked."""
    stage = make_render_plan(["glossy"], stage_max_depth=4)
    assert (stage.max_depth, stage.max_depth_source) == (4, "stage")
    assert "stage" in stage.transport_line()
    user = make_render_plan(["glossy"], RenderOptions(max_depth=2), stage_max_depth=4)
    assert (user.max_depth, user.max_depth_source) == (2, "user")
    # -1 from the user lifts a stage's restriction (and the plan is then the default one).
    lifted = make_render_plan(["glossy"], RenderOptions(max_depth=-1), stage_max_depth=4)
    assert lifted.max_depth == UNBOUNDED_DEPTH and not lifted.transport_restricted
    assert "full transport" in make_render_plan(["glossy"]).transport_line()
    with pytest.raises(ValueError, match="maxDepth"):
        make_render_plan([], stage_max_depth=0)
    assert RenderPlan.from_dict(json.loads(stage.to_json())) == stage


def test_stage_metadata_max_depth_is_read(tmp_path):
    """``customLayerData["denoisebench"]["maxDepth"]`` reaches the translated scene; bad values are user errors."""
    from pxr import Usd, UsdGeom

    from denoisebench.errors import UserInputError
    from denoisebench.generator.usd.translate import translate_usd

    def stage_with(meta):
        path = tmp_path / f"s{len(list(tmp_path.iterdir()))}.usda"
        stage = Usd.Stage.CreateNew(str(path))
        UsdGeom.Camera.Define(stage, "/cam")
        if meta is not None:
            stage.GetRootLayer().customLayerData = {"denoisebench": meta}
        stage.GetRootLayer().Save()
        return path

    assert translate_usd(stage_with(None)).max_depth is None
    assert translate_usd(stage_with({"maxDepth": 3})).max_depth == 3
    with pytest.raises(UserInputError, match="maxDepth"):
        translate_usd(stage_with({"maxDepth": 0}))


def test_report_names_restricted_transport_and_who_asked():
    """The benchmark report's transport line reads the manifest plan (reports show restrictions)."""
    from denoisebench.reports.build import _transport

    assert _transport(make_render_plan(["glossy"]).to_dict()) == "full transport"
    assert _transport(make_render_plan([], RenderOptions(max_depth=2)).to_dict()) == "max_depth 2 (--max-depth)"
    assert _transport(make_render_plan([], stage_max_depth=3).to_dict()) == "max_depth 3 (stage metadata)"
    # A manifest written before plans recorded who asked.
    assert _transport({"max_depth": 8}) == "max_depth 8 (an older plan rule)"


@pytest.mark.slow
def test_preview_max_depth_restricts_transport_and_bad_values_are_user_errors(tmp_path, capsys):
    from denoisebench.cli import main
    from denoisebench.generator.preview import render_preview
    from tests.support.plain_stages import author_plain_box

    box = author_plain_box(tmp_path / "box.usda")
    full, _ = render_preview(box, width=16, height=16, spp=64)
    direct, _ = render_preview(box, width=16, height=16, spp=64, max_depth=2)
    assert direct.mean() < 0.85 * full.mean()  # the box's indirect light is a large share of it
    assert main(["scenes", "preview", str(box), "--out", str(tmp_path / "p.png"), "--max-depth", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and len(err.splitlines()) == 1 and "max-depth" in err
