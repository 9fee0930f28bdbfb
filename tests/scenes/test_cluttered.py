"""The cluttered family: SBMC-style clutter that keeps its promises (placement, materials, held-out variants)."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Usd, UsdShade

from denoisebench.dataset.manifest import pin_held_out
from denoisebench.generator.contract.render_plan import make_render_plan
from denoisebench.generator.render.frame import render_frame
from denoisebench.generator.render.motion import ShutterMotionScene
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family, shapes
from denoisebench.scenes.families import cluttered

FRAMES = 3
# Seeds by what their generator draws (first two draws: depth of field, motion blur; pool by hash).
HELD_OUT_BLUR = 0  # held-out pool, object motion blur
TRAIN_DOF_BLUR = 2  # train pool, depth of field and object motion blur
TRAIN_STILL = 4  # train pool, neither


@pytest.fixture(scope="module")
def stages(tmp_path_factory):
    root = tmp_path_factory.mktemp("cluttered")
    family = get_family("cluttered")
    return {
        seed: family.author(root / str(seed), seed=seed, frames=FRAMES)
        for seed in (HELD_OUT_BLUR, TRAIN_DOF_BLUR, TRAIN_STILL)
    }


@pytest.fixture(scope="module")
def translated(stages):
    return {seed: translate_usd(path) for seed, path in stages.items()}


def test_pools_hold_disjoint_variants_and_are_recorded(translated):
    for kind in ("shapes", "textures", "environments"):
        assert not set(cluttered.TRAIN[kind]) & set(cluttered.HELD_OUT[kind])
    assert set(cluttered.TRAIN["shapes"]) | set(cluttered.HELD_OUT["shapes"]) == set(shapes.SHAPES)
    for seed, scene in translated.items():
        pool = cluttered.variant_pool(seed)
        variants = cluttered.HELD_OUT if pool == "held_out" else cluttered.TRAIN
        assert scene.variants["pool"] == pool
        assert set(scene.variants["shapes"]) <= set(variants["shapes"])
        assert set(scene.variants["textures"]) <= set(variants["textures"])
        assert scene.variants["environment"] in variants["environments"]
    share = np.mean([cluttered.variant_pool(s) == "held_out" for s in range(2000)])
    assert abs(share - cluttered.HELD_OUT_FRACTION) < 0.03


def test_held_out_scenes_are_pinned_to_test():
    splits = {"train": ["a", "b", "h1"], "val": ["h2", "c"], "test": ["d"]}
    out = pin_held_out(splits, ["h1", "h2", "not_a_scene"])
    assert out == {"train": ["a", "b"], "val": ["c"], "test": ["d", "h1", "h2"]}


def test_effects_drawn_per_seed_are_declared_and_found(translated):
    assert set(translated[TRAIN_DOF_BLUR].effects) >= {"depth_of_field", "motion_blur"}
    assert not {"depth_of_field", "motion_blur"} & set(translated[TRAIN_STILL].effects)
    for scene in translated.values():
        assert scene.effects_mismatch == {}
        assert set(cluttered.ALWAYS) <= set(scene.effects) <= set(cluttered.EFFECTS)
    assert translated[HELD_OUT_BLUR].shutter_moving and not translated[TRAIN_STILL].shutter_moving
    moving = sum(s.shutter_motion is not None for s in translated[TRAIN_DOF_BLUR].shapes)
    assert 1 <= moving <= cluttered.MAX_MOVING


def test_objects_never_interpenetrate(translated):
    """Footprint circles (from the translated world vertices) are disjoint at every frame and shutter time."""
    for scene in translated.values():
        objects = [s for s in scene.shapes if "/Object" in s.name]
        assert cluttered.OBJECTS[0] <= len(objects) <= cluttered.OBJECTS[1]
        for frame in range(FRAMES):
            discs = []
            for record in objects:
                points = record.positions if record.frame_positions is None else record.frame_positions[frame]
                xz = points[:, [0, 2]].astype(np.float64)
                centre = 0.5 * (xz.min(0) + xz.max(0))
                discs.append((centre, np.sqrt(np.max(np.sum(np.square(xz - centre), axis=1)))))
                assert points[:, 1].min() > -1e-3  # on or above the ground
            for i in range(len(discs)):
                for j in range(i):
                    gap = np.linalg.norm(discs[i][0] - discs[j][0]) - discs[i][1] - discs[j][1]
                    assert gap > -1e-4, (scene.seed, frame, objects[i].name, objects[j].name, gap)


def test_materials_follow_sbmc_mix_with_every_lobe_present(stages):
    stage = Usd.Stage.Open(str(stages[TRAIN_DOF_BLUR]))
    kinds = []
    for prim in stage.Traverse():
        if prim.GetName().startswith("Object"):
            material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
            kinds.append(material.GetPrim().GetName().split("_", 1)[1])
    assert kinds[:3] == ["glass", "metal", "mirror"]
    assert set(kinds) <= set(cluttered.MATERIAL_MIX)
    # Textured kinds sample through a UsdTransform2d at a scale in [0.5, 8].
    scales = [UsdShade.Shader(p).GetInput("scale").Get()[0] for p in stage.Traverse() if p.GetName() == "StTransform"]
    assert scales and all(0.5 <= s <= 8.0 for s in scales)


def test_material_mix_matches_sbmc_fractions():
    """The mix the family draws from is SBMC's, and sums to one."""
    assert cluttered.MATERIAL_MIX == {
        "mirror": 0.05,
        "glass": 0.05,
        "metal": 0.10,
        "plastic": 0.20,
        "substrate": 0.10,
        "uber": 0.30,
        "matte": 0.20,
    }


def test_blurred_cluttered_scene_renders(translated):
    scene = translated[TRAIN_DOF_BLUR]
    plan = make_render_plan(scene.effects)
    assert plan.time_sampling and plan.camera_model == "thin_lens"
    mitsuba_scene = build_mitsuba_scene(scene, frame=1)
    assert isinstance(mitsuba_scene, ShutterMotionScene)
    out = render_frame(mitsuba_scene, scene.camera, 1, plan, width=16, height=16, spp=4, seed=1)
    for name, buffer in out.buffers.items():
        assert np.all(np.isfinite(buffer)), name
    assert out.buffers["color"].mean() > 0.01


def test_shape_library_is_closed_outward_and_modest():
    rng = np.random.default_rng(3)
    for kind in shapes.SHAPES:
        mesh = shapes.make(kind, rng, 0.6)
        assert mesh.triangles < 2500
        assert np.all(np.isfinite(mesh.points)) and np.all(np.isfinite(mesh.normals))
        assert abs(mesh.points[:, 1].min()) < 1e-9 and mesh.extra["radius"] > 0
        if kind != "leaf":  # closed shapes: normals point away from the centroid on average
            centre = mesh.points.mean(0)
            assert np.mean(np.sum(mesh.normals * (mesh.points - centre), axis=1)) > 0
    with pytest.raises(ValueError, match="unknown shape kind"):
        shapes.make("teapot", rng, 1.0)
