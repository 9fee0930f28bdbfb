"""UsdGeom.PointInstancer → Mitsuba shapegroup + instance: what is placed, and that an
instanced stage renders as the same stage with its instances written out as plain prims."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pxr")

from denoisebench.generator.usd.translate import translate_usd  # noqa: E402

POSITIONS = [(-0.6, 0.0, 0.0), (0.0, 0.0, 0.0), (0.6, 0.0, 0.0), (0.0, 0.5, 0.0), (-0.6, 0.5, 0.0)]
ORIENT = [(1, 0, 0, 0), (0.9238795, 0, 0.3826834, 0), (1, 0, 0, 0), (0.7071068, 0.7071068, 0, 0), (1, 0, 0, 0)]
SCALES = [(1, 1, 1), (0.8, 1.2, 0.8), (1, 1, 1), (1.5, 1.5, 1.5), (1, 1, 1)]
INDICES = [0, 1, 0, 1, 0]
INVISIBLE = [4]


def _common(stage):
    from pxr import Gf, Sdf, UsdGeom, UsdLux, UsdShade

    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    camera = UsdGeom.Camera.Define(stage, "/Camera")
    camera.CreateFocalLengthAttr(35.0)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.CreateVerticalApertureAttr(36.0)
    camera.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.25, 3.0))
    dome = UsdLux.DomeLight.Define(stage, "/Dome")
    dome.CreateIntensityAttr(1.0)
    key = UsdLux.DistantLight.Define(stage, "/Key")
    key.CreateIntensityAttr(2.0)
    key.AddRotateXYZOp().Set(Gf.Vec3f(-45.0, 30.0, 0.0))
    materials = []
    for name, colour in (("Red", (0.8, 0.2, 0.1)), ("Blue", (0.1, 0.3, 0.8))):
        material = UsdShade.Material.Define(stage, f"/Looks/{name}")
        shader = UsdShade.Shader.Define(stage, f"/Looks/{name}/Surface")
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(colour)
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.6)
        material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        materials.append(material)
    return materials


def _prototype(stage, path, kind, material):
    """Prototype 0: a cube mesh (offset inside its root), prototype 1: a sphere with its own scale."""
    from pxr import Gf, UsdGeom, UsdShade

    root = UsdGeom.Xform.Define(stage, path)
    if kind == 0:
        cube = UsdGeom.Cube.Define(stage, f"{path}/Box")
        cube.CreateSizeAttr(0.3)
        cube.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.05, 0.0))
        gprim = cube
    else:
        sphere = UsdGeom.Sphere.Define(stage, f"{path}/Ball")
        sphere.CreateRadiusAttr(0.15)
        root.AddScaleOp().Set(Gf.Vec3f(1.0, 0.7, 1.0))
        gprim = sphere
    UsdShade.MaterialBindingAPI.Apply(gprim.GetPrim()).Bind(material)
    return root


def author_instanced(path, animated=False):
    from pxr import Gf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    materials = _common(stage)
    instancer = UsdGeom.PointInstancer.Define(stage, "/World/Instancer")
    roots = [_prototype(stage, f"/World/Instancer/Proto{k}", k, materials[k]) for k in range(2)]
    rel = instancer.CreatePrototypesRel()
    for root in roots:
        rel.AddTarget(root.GetPath())
    instancer.CreateProtoIndicesAttr(INDICES)
    instancer.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(*q) for q in ORIENT]))
    instancer.CreateScalesAttr([Gf.Vec3f(*s) for s in SCALES])
    instancer.CreateInvisibleIdsAttr(Vt.Int64Array(INVISIBLE))
    if animated:
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(1)
        attribute = instancer.CreatePositionsAttr()
        attribute.Set([Gf.Vec3f(*p) for p in POSITIONS], 0)
        attribute.Set([Gf.Vec3f(p[0] + 0.1, p[1], p[2]) for p in POSITIONS], 1)
    else:
        instancer.CreatePositionsAttr([Gf.Vec3f(*p) for p in POSITIONS])
    stage.GetRootLayer().Save()
    return path


def author_flattened(path):
    """The same instances written out: one Xform per visible instance (its T·R·S) over the prototype."""
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    materials = _common(stage)
    for index, (position, quat, scale, proto) in enumerate(zip(POSITIONS, ORIENT, SCALES, INDICES)):
        if index in INVISIBLE:
            continue
        holder = UsdGeom.Xform.Define(stage, f"/World/Instance{index}")
        holder.AddTranslateOp().Set(Gf.Vec3d(*position))
        holder.AddOrientOp().Set(Gf.Quatf(*quat))
        holder.AddScaleOp().Set(Gf.Vec3f(*scale))
        _prototype(stage, f"/World/Instance{index}/Proto", proto, materials[proto])
    stage.GetRootLayer().Save()
    return path


def test_instances_are_grouped_masked_and_prototypes_not_rendered_in_place(tmp_path):
    translated = translate_usd(author_instanced(tmp_path / "instanced.usda"))
    groups = translated.instance_groups
    assert [len(g.to_world) for g in groups] == [2, 2]  # 3 cubes minus one invisible id, 2 spheres
    assert all(len(g.shapes) == 1 for g in groups)
    assert translated.shapes == ()  # prototypes only where the instancer puts them
    assert not [w for w in translated.warnings if "PointInstancer" in w]
    # The cube's instance 2 sits at x = 0.6 (its prototype's own 0.05 offset is inside the group's shape).
    assert np.allclose(groups[0].to_world[1][:3, 3], [0.6, 0.0, 0.0], atol=1e-6)
    assert np.allclose(groups[0].shapes[0].positions[:, 1].mean(), 0.05, atol=1e-6)


@pytest.mark.parametrize("merged", [False, True], ids=["instances", "merged"])
def test_instanced_stage_renders_as_the_flattened_stage(tmp_path, monkeypatch, merged):
    from denoisebench.generator.render import scene as scene_module
    from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
    from denoisebench.mitsuba_runtime import load_mitsuba

    if merged:  # above INSTANCE_LIMIT the renderer merges each group's instances into one mesh
        monkeypatch.setattr(scene_module, "INSTANCE_LIMIT", 0)

    mi = load_mitsuba()
    images = []
    for author, name in ((author_instanced, "instanced.usda"), (author_flattened, "flat.usda")):
        translated = translate_usd(author(tmp_path / name))
        scene = build_mitsuba_scene(translated, sensor_dict(translated.camera, 0, 32, 32, 64, seed=3), {"type": "path"})
        images.append(np.array(mi.render(scene), dtype=np.float64))
    instanced, flat = images
    assert instanced.mean() > 0.05
    # Same geometry, same sampler seed: equal up to the noise of rays that land differently on edges.
    rel = np.mean((instanced - flat) ** 2 / (flat**2 + 0.01))
    assert rel < 5e-4, rel
    assert abs(instanced.mean() - flat.mean()) < 0.01 * flat.mean()
    assert np.count_nonzero(np.abs(instanced - flat).max(-1) > 0.05) < 0.03 * flat.shape[0] * flat.shape[1]


def test_animated_instancer_is_written_out_with_per_frame_positions(tmp_path):
    translated = translate_usd(author_instanced(tmp_path / "moving.usda", animated=True))
    assert translated.instance_groups == ()
    shapes = translated.shapes
    assert len(shapes) == 4
    assert translated.moving
    for shape in shapes:
        frames = shape.frame_positions
        assert frames.shape[0] == 2
        assert np.allclose(frames[1] - frames[0], [0.1, 0.0, 0.0], atol=1e-5)


def test_animated_instancer_moves_within_the_shutter_and_has_motion_vectors(tmp_path):
    from pxr import Usd, UsdGeom

    from denoisebench.generator.contract.render_plan import make_render_plan
    from denoisebench.generator.render.frame import render_frame
    from denoisebench.generator.render.scene import build_mitsuba_scene

    path = author_instanced(tmp_path / "blur.usda", animated=True)
    stage = Usd.Stage.Open(str(path))
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/Camera"))
    camera.CreateShutterOpenAttr(-0.25)
    camera.CreateShutterCloseAttr(0.25)
    stage.GetRootLayer().Save()
    translated = translate_usd(path)
    assert translated.shutter_moving and "motion_blur" in translated.effects_inferred
    for shape in translated.shapes:
        motion = shape.shutter_motion
        shift = motion.to_world[-1][:3, 3] - motion.to_world[0][:3, 3]
        assert np.allclose(shift, [0.1, 0.0, 0.0], atol=1e-5)  # keys span frame 0 to frame 1 (held at the ends)
    plan = make_render_plan(translated.effects)
    scene = build_mitsuba_scene(translated, frame=1)
    out = render_frame(scene, translated.camera, 1, plan, width=32, height=32, spp=4, seed=1)
    motion = out.buffers["motion"]
    assert np.isfinite(motion).all()
    moving = np.abs(motion[..., 0]) > 0.2
    assert 0.02 < moving.mean() < 0.6  # the instances moved +x between frames: pixels on them carry motion


def test_our_renderer_sees_instances_as_the_flattened_prims(tmp_path):
    """The feature renderer (colour, albedo, normal, depth) through Mitsuba instances equals the plain prims'."""
    from denoisebench.generator.contract.render_plan import make_render_plan
    from denoisebench.generator.render.frame import render_frame
    from denoisebench.generator.render.scene import build_mitsuba_scene

    buffers = []
    for author, name in ((author_instanced, "instanced.usda"), (author_flattened, "flat.usda")):
        translated = translate_usd(author(tmp_path / name))
        plan = make_render_plan(translated.effects)
        out = render_frame(
            build_mitsuba_scene(translated), translated.camera, 0, plan, width=24, height=24, spp=8, seed=2
        )
        buffers.append(out.buffers)
    instanced, flat = buffers
    assert flat["depth"].max() > 0
    for name in ("color", "albedo", "normal", "depth"):
        assert np.abs(instanced[name] - flat[name]).mean() < 1e-3 * (1 + np.abs(flat[name]).mean()), name


def test_velocities_move_instances_between_and_within_frames(tmp_path):
    """Positions authored once, velocities in units per second: USD extrapolates, the instances move."""
    from pxr import Gf, Usd, UsdGeom

    path = author_instanced(tmp_path / "velocity.usda")
    stage = Usd.Stage.Open(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(1)
    stage.SetTimeCodesPerSecond(24)
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Instancer"))
    positions = instancer.GetPositionsAttr().Get()
    instancer.GetPositionsAttr().Clear()
    instancer.GetPositionsAttr().Set(positions, 0)
    instancer.CreateVelocitiesAttr().Set([Gf.Vec3f(2.4, 0.0, 0.0)] * len(positions), 0)
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/Camera"))
    camera.CreateShutterOpenAttr(0.0)
    camera.CreateShutterCloseAttr(0.5)
    stage.GetRootLayer().Save()
    translated = translate_usd(path)
    shapes = translated.shapes
    assert translated.instance_groups == () and len(shapes) == 4
    for shape in shapes:
        assert np.allclose(shape.frame_positions[1] - shape.frame_positions[0], [0.1, 0.0, 0.0], atol=1e-5)
        motion = shape.shutter_motion
        half = int(np.flatnonzero(np.isclose(motion.times, 0.5))[0])
        assert np.allclose(motion.to_world[half][:3, 3] - motion.to_world[0][:3, 3], [0.05, 0, 0], atol=1e-5)
