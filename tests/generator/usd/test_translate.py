"""USD → Mitsuba translation on hand-written stages in the style of real exports (tests/data/usd)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.scene_parts import ConstantEmitter, DirectionalEmitter, SphereShape
from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
from denoisebench.generator.usd.translate import scene_bounds, translate_stage, translate_usd
from denoisebench.mitsuba_runtime import load_mitsuba
from tests.support.paths import DATA as TEST_DATA  # noqa: E402

DATA = TEST_DATA / "usd"


@pytest.fixture(scope="module")
def zup():
    return translate_usd(DATA / "zup_centimeters.usda")


@pytest.fixture(scope="module")
def yup():
    return translate_usd(DATA / "yup_lens_shutter.usda")


def _records(translated, name_part):
    return [s for s in translated.shapes if name_part in s.name]


def test_zup_centimeters_become_yup_meters(zup):
    ball = _records(zup, "/World/Geo/Ball")[0]
    # Authored at z = 50 cm with radius 50 cm in a Z-up stage: center (0, 0.5, 0) m, radius 0.5 m.
    assert isinstance(ball, SphereShape)
    np.testing.assert_allclose(ball.center, [0.0, 0.5, 0.0], atol=1e-9)
    assert ball.radius == pytest.approx(0.5)
    ground = _records(zup, "/World/Geo/Ground")
    positions = np.concatenate([r.positions for r in ground])
    np.testing.assert_allclose(positions[:, 1], 0.0, atol=1e-6)  # ground plane z=0 → y=0
    np.testing.assert_allclose(np.abs(positions[:, [0, 2]]).max(), 2.0, rtol=1e-6)
    # Z-up +Y (away from the camera) becomes Mitsuba -Z.
    box = _records(zup, "/World/Geo/Box")[0]
    center = box.positions.mean(0)
    np.testing.assert_allclose(center, [-1.2, 0.2, -0.6], atol=1e-6)
    # The post is a Z-axis cylinder 1.2 m tall standing on the ground.
    post = _records(zup, "/World/Geo/Post")[0]
    assert post.positions[:, 1].min() == pytest.approx(0.0, abs=1e-6)
    assert post.positions[:, 1].max() == pytest.approx(1.2, abs=1e-6)


def test_animated_camera_over_the_stage_time_range(zup):
    camera = zup.camera
    assert camera.frames == 3  # startTimeCode 1 .. endTimeCode 3
    positions = camera.poses[:, :3, 3]
    np.testing.assert_allclose(positions[0], [0.0, 0.6, 5.0], atol=1e-9)
    np.testing.assert_allclose(positions[2] - positions[0], [0.4, 0.0, 0.0], atol=1e-9)
    forward = -camera.poses[0][:3, 2]  # USD cameras look down their local -Z
    np.testing.assert_allclose(forward, [0.0, 0.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(camera.poses[0][:3, 1], [0.0, 1.0, 0.0], atol=1e-9)  # up
    assert camera.fov_x_deg == pytest.approx(math.degrees(2 * math.atan(18 / 35)))
    assert not camera.has_depth_of_field and not camera.has_open_shutter
    assert camera.near_clip == pytest.approx(0.01)


def test_geom_subsets_split_materials_and_keep_every_triangle(zup):
    parts = _records(zup, "/World/Geo/Ground")
    assert len(parts) == 2
    assert sum(len(p.faces) for p in parts) == 4  # two quads
    assert len({p.bsdf for p in parts}) == 2
    bsdfs = zup.bsdfs
    kinds = sorted(bsdfs[p.bsdf]["bsdf"]["base_color"]["type"] for p in parts)
    assert kinds == ["bitmap", "rgb"]  # the checker subset is textured, the gold one is not


def test_texture_resolves_beside_the_stage(zup):
    bitmaps = [
        b["bsdf"]["base_color"]
        for b in zup.bsdfs.values()
        if b.get("bsdf", {}).get("base_color", {}).get("type") == "bitmap"
    ]
    assert len(bitmaps) == 1
    # Decoded at translation (through USD's resolver), image row 0 = the top: red on top, blue below.
    # The PNG holds (230, 20, 20) and (20, 20, 230); sRGB decoding gives 0.79130 and 0.0069954.
    data = bitmaps[0]["data"]
    high, low = ((230 / 255 + 0.055) / 1.055) ** 2.4, ((20 / 255 + 0.055) / 1.055) ** 2.4
    np.testing.assert_allclose(data[0, 0], [high, low, low], rtol=1e-5)
    np.testing.assert_allclose(data[-1, 0], [low, low, high], rtol=1e-5)
    assert bitmaps[0]["raw"] is True  # already linear: diffuseColor with sourceColorSpace auto was sRGB-decoded


def test_face_varying_normals_and_uvs_unrolled(zup):
    part = _records(zup, "/World/Geo/Ground")[0]
    assert part.positions.shape == (6, 3) and part.normals.shape == (6, 3) and part.uvs.shape == (6, 2)
    np.testing.assert_allclose(part.normals, np.tile([0, 1, 0], (6, 1)), atol=1e-6)  # +Z up → +Y
    assert set(np.round(part.uvs.ravel(), 6)) <= {0.0, 1.0}


def test_lights_radiance_and_kinds(zup, yup):
    bulb = _records(zup, "/World/Lights/Bulb")[0]
    np.testing.assert_allclose(bulb.emitter.radiance, np.array([1, 0.9, 0.8]) * 50 * 2.0, rtol=1e-6)
    assert bulb.radius == pytest.approx(0.1)
    disk = _records(zup, "/World/Lights/Fill")[0]
    area = (
        0.5
        * np.linalg.norm(
            np.cross(
                disk.positions[disk.faces[:, 1]] - disk.positions[disk.faces[:, 0]],
                disk.positions[disk.faces[:, 2]] - disk.positions[disk.faces[:, 0]],
            ),
            axis=1,
        ).sum()
    )
    assert area == pytest.approx(math.pi * 0.2**2, rel=0.01)
    sun = [e for e in zup.emitters if isinstance(e, DirectionalEmitter)][0]
    assert np.linalg.norm(sun.direction) == pytest.approx(1.0)
    np.testing.assert_allclose(sun.irradiance, [2, 2, 2])
    sky = [e for e in yup.emitters if isinstance(e, ConstantEmitter)][0]
    np.testing.assert_allclose(sky.radiance, [0.3, 0.35, 0.5], rtol=1e-6)
    softbox = _records(yup, "/World/Softbox")[0]
    normal = np.cross(
        softbox.positions[softbox.faces[0, 1]] - softbox.positions[softbox.faces[0, 0]],
        softbox.positions[softbox.faces[0, 2]] - softbox.positions[softbox.faces[0, 0]],
    )
    assert normal[1] < 0  # rotated -90° about X: emits downward


def test_lens_and_shutter(yup):
    camera = yup.camera
    # 50 mm lens (0.5 tenths of a meter) at f/1.4: aperture radius 0.05 / 2.8 m.
    assert camera.aperture_radius == pytest.approx(0.05 / (2 * 1.4))
    assert camera.focus_distance == pytest.approx(4.0)
    assert (camera.shutter_open, camera.shutter_close) == (-0.25, 0.25)
    assert camera.frames == 5 and camera.is_animated
    np.testing.assert_allclose(camera.pose_at(2.0)[:3, 3], [0.0, 1.0, 4.0])
    np.testing.assert_allclose(camera.pose_at(0.5)[:3, 3], [-0.75, 1.0, 4.0])


def test_effects_inferred_and_declared(zup, yup):
    assert set(zup.effects_inferred) == {"glossy", "textures", "area_lights"}
    assert zup.effects_declared == () and zup.effects_mismatch == {}
    assert set(yup.effects_inferred) == {
        "depth_of_field",
        "motion_blur",
        "specular",
        "transmission",
        "area_lights",
        "environment",
    }
    assert yup.effects_mismatch == {}
    assert yup.family == "handwritten" and yup.seed == 0


def test_effects_mismatch_is_reported(tmp_path):
    text = (DATA / "yup_lens_shutter.usda").read_text()
    text = text.replace('"environment"]', '"environment", "textures"]')
    (tmp_path / "s.usda").write_text(text)
    assert translate_usd(tmp_path / "s.usda").effects_mismatch == {"declared_not_found": ["textures"]}


def _render(translated, frame=0, width=32, height=24, spp=16, depth=3):
    mi = load_mitsuba()
    scene = build_mitsuba_scene(
        translated,
        sensor=sensor_dict(translated.camera, frame, width, height, spp),
        integrator={"type": "path", "max_depth": depth},
    )
    return np.array(mi.render(scene, spp=spp, seed=1))


def test_texture_orientation_matches_usd(tmp_path):
    """A camera facing a textured quad sees the image's top row at the top (v flipped correctly)."""
    from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade

    stage = Usd.Stage.CreateNew(str(tmp_path / "quad.usda"))
    (tmp_path / "textures").mkdir()
    (tmp_path / "textures" / "t.png").write_bytes((DATA / "textures" / "red_top_blue_bottom.png").read_bytes())
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    mesh = UsdGeom.Mesh.Define(stage, "/Quad")
    mesh.CreatePointsAttr([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    material = UsdShade.Material.Define(stage, "/Mat")
    surface = UsdShade.Shader.Define(stage, "/Mat/S")
    surface.CreateIdAttr("UsdPreviewSurface")
    texture = UsdShade.Shader.Define(stage, "/Mat/T")
    texture.CreateIdAttr("UsdUVTexture")
    texture.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./textures/t.png")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(texture.ConnectableAPI(), "rgb")
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    camera = UsdGeom.Camera.Define(stage, "/Cam")
    camera.AddTranslateOp().Set((0, 0, 3))
    UsdLux.DomeLight.Define(stage, "/Sky").CreateIntensityAttr(1.0)
    stage.Save()
    image = _render(translate_usd(tmp_path / "quad.usda"), width=16, height=16, spp=8, depth=2)
    top, bottom = image[5, 8], image[10, 8]
    assert top[0] > 3 * top[2], f"top of the quad should be red, got {top}"
    assert bottom[2] > 3 * bottom[0], f"bottom of the quad should be blue, got {bottom}"


def test_rect_light_seen_directly_has_its_radiance(tmp_path):
    """Looking up at a RectLight, pixel values equal color · intensity · 2^exposure."""
    from pxr import Usd, UsdGeom, UsdLux

    stage = Usd.Stage.CreateNew(str(tmp_path / "light.usda"))
    light = UsdLux.RectLight.Define(stage, "/Light")
    light.CreateWidthAttr(4.0)
    light.CreateHeightAttr(4.0)
    light.CreateIntensityAttr(3.0)
    light.CreateExposureAttr(1.0)
    light.CreateColorAttr((1.0, 0.5, 0.25))
    light.AddTranslateOp().Set((0, 0, -2))  # faces -Z: toward a camera looking down -Z? no: away
    light.AddRotateYOp().Set(180.0)  # now emits toward +Z, where the camera is
    camera = UsdGeom.Camera.Define(stage, "/Cam")
    camera.CreateFocalLengthAttr(50)
    stage.Save()
    image = _render(translate_usd(tmp_path / "light.usda"), width=8, height=8, spp=4, depth=1)
    np.testing.assert_allclose(image[4, 4], [6.0, 3.0, 1.5], rtol=1e-5)


def test_zup_centimeter_stage_renders_like_its_yup_meter_twin(tmp_path):
    """The same scene authored Z-up in centimeters and Y-up in meters gives the same image."""
    from pxr import Gf, Usd, UsdGeom, UsdLux

    def author(path, up, meters_per_unit):
        stage = Usd.Stage.CreateNew(str(path))
        UsdGeom.SetStageUpAxis(stage, up)
        UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
        scale = 1.0 / meters_per_unit

        def point(x, y_up, depth):  # (right, up, toward the viewer) in meters → stage coordinates
            return Gf.Vec3d(x, y_up, depth) * scale if up == UsdGeom.Tokens.y else Gf.Vec3d(x, -depth, y_up) * scale

        ball = UsdGeom.Sphere.Define(stage, "/Ball")
        ball.CreateRadiusAttr(0.5 * scale)
        ball.AddTranslateOp().Set(point(0.2, 0.5, 0.0))
        floor = UsdGeom.Cube.Define(stage, "/Floor")
        floor.CreateSizeAttr(1.0)
        floor.AddTranslateOp().Set(point(0, -0.05, 0))
        floor.AddScaleOp().Set(
            Gf.Vec3f(4 * scale, 0.1 * scale, 4 * scale)
            if up == UsdGeom.Tokens.y
            else Gf.Vec3f(4 * scale, 4 * scale, 0.1 * scale)
        )
        light = UsdLux.SphereLight.Define(stage, "/Bulb")
        light.CreateRadiusAttr(0.2 * scale)
        light.CreateIntensityAttr(20.0)
        light.AddTranslateOp().Set(point(1.0, 2.0, 1.0))
        camera = UsdGeom.Camera.Define(stage, "/Cam")
        camera.CreateFocalLengthAttr(3.5 * scale / 10)  # tenths of a scene unit: a 35 mm lens
        camera.CreateHorizontalApertureAttr(3.6 * scale / 10)
        camera.AddTranslateOp().Set(point(0, 0.8, 4.0))
        if up == UsdGeom.Tokens.z:
            camera.AddRotateXOp().Set(90.0)  # USD cameras look down -Z; stand the Z-up one upright
        stage.Save()
        return translate_usd(path)

    meters = author(tmp_path / "m.usda", UsdGeom.Tokens.y, 1.0)
    centimeters = author(tmp_path / "cm.usda", UsdGeom.Tokens.z, 0.01)
    lo_m, hi_m = scene_bounds(meters)
    lo_cm, hi_cm = scene_bounds(centimeters)
    np.testing.assert_allclose(lo_m, lo_cm, atol=1e-5)
    np.testing.assert_allclose(hi_m, hi_cm, atol=1e-5)
    np.testing.assert_allclose(meters.camera.poses, centimeters.camera.poses, atol=1e-9)
    a, b = _render(meters), _render(centimeters)
    assert a.mean() > 0.01
    # Same seed, but float rounding of the two transforms sends a few paths differently.
    np.testing.assert_allclose(a, b, rtol=0.05, atol=2e-3)
    assert abs(a.mean() - b.mean()) < 1e-3 * a.mean() + 1e-5


# ---- bad input ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "name, message",
    [
        ("bad_not_usd.usda", "cannot open USD stage (line 3:5: Expected }"),
        ("bad_no_camera.usda", "no camera (UsdGeom.Camera) in the stage"),
        ("bad_nan_points.usda", "/World/Broken.points holds 1 NaN/Inf value(s)"),
        ("bad_face_indices.usda", "/World/OutOfRange: faceVertexIndices reference point 7 but the mesh has 3 points"),
        ("missing.usda", "no such USD file"),
    ],
)
def test_bad_stage_is_a_one_line_user_error(name, message):
    with pytest.raises(UserInputError) as caught:
        translate_usd(DATA / name)
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_unsupported_prims_and_degenerate_input_warn_once_each():
    translated = translate_usd(DATA / "unsupported_and_degenerate.usda")
    warnings = translated.warnings
    assert "/World/Hair: prim type NurbsCurves is not supported; skipped" in warnings
    assert "/World/Dust: prim type Points is not supported; skipped" in warnings
    assert "/World/Sliver: 2 face(s) with fewer than 3 vertices cannot be triangulated; skipped" in warnings
    assert "/World/Flat: RectLight has zero area; skipped (it would emit nothing)" in warnings
    assert len(warnings) == 4
    sliver = _records(translated, "/World/Sliver")[0]
    assert sliver.faces.shape == (1, 3)  # the valid triangle is kept
    assert not _records(translated, "/World/Flat")


def test_nan_in_material_and_camera_attributes_is_rejected(tmp_path):
    text = (DATA / "yup_lens_shutter.usda").read_text()
    (tmp_path / "a.usda").write_text(text.replace("float inputs:roughness = 0", "float inputs:roughness = nan"))
    with pytest.raises(UserInputError, match=r"/World/Glass/PBR.inputs:roughness holds 1 NaN/Inf"):
        translate_usd(tmp_path / "a.usda")
    (tmp_path / "b.usda").write_text(text.replace("float focusDistance = 4", "float focusDistance = inf"))
    with pytest.raises(UserInputError, match=r"/World/Cam.focusDistance holds 1 NaN/Inf"):
        translate_usd(tmp_path / "b.usda")


def test_in_memory_stage_and_explicit_camera_path():
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.Camera.Define(stage, "/A")
    UsdGeom.Camera.Define(stage, "/B").AddTranslateOp().Set((0, 0, 7))
    translated = translate_stage(stage, camera_path="/B")
    assert translated.camera.prim_path == "/B"
    assert translated.camera.poses[0][2, 3] == pytest.approx(0.07)  # unauthored metersPerUnit: USD says centimeters
    with pytest.raises(UserInputError, match="/C: no camera prim"):
        translate_stage(stage, camera_path="/C")
