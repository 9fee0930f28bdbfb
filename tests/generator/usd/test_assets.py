"""Real-world USD input: cameras and lights on demand, UsdLux point/spot lights, texture
channels/varname/transforms/cut-outs/packages, unreadable files, USD diagnostics, moving objects.

Every stage is authored here with usd-core; the expected values come from the USD/UsdLux/
UsdPreviewSurface specs (cited per test), from independent arithmetic, or from invariants
(reprojection with motion vectors must explain the next frame).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, UsdUtils

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.scene_parts import EnvmapEmitter, MeshShape, PointEmitter, SpotEmitter
from denoisebench.generator.usd.translate import translate_usd


def run_cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "denoisebench.cli", *map(str, args)], capture_output=True, text=True, timeout=300
    )


# ------------------------------------------------------------------ authoring helpers


def new_stage(path: Path, up="Y", meters=1.0, frames=None):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, meters)
    if frames:
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(frames - 1)
    return stage


def add_camera(stage, path="/Cam", position=(0, 0, 5), focal=35.0):
    camera = UsdGeom.Camera.Define(stage, path)
    camera.CreateFocalLengthAttr(focal)
    camera.CreateHorizontalApertureAttr(36.0)
    camera.AddTranslateOp().Set(Gf.Vec3d(*position))
    return camera


def add_quad(stage, path, size=2.0, z=0.0, st_name="st", st=((0, 0), (1, 0), (1, 1), (0, 1))):
    mesh = UsdGeom.Mesh.Define(stage, path)
    h = size / 2
    mesh.CreatePointsAttr([(-h, -h, z), (h, -h, z), (h, h, z), (-h, h, z)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        st_name, Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    primvar.Set(list(st))
    return mesh


def textured_material(stage, path, image: Path, connections, varname="st", transform=None, extra=None):
    """UsdPreviewSurface whose inputs (name → (texture output, type)) read one UsdUVTexture."""
    material = UsdShade.Material.Define(stage, path)
    surface = UsdShade.Shader.Define(stage, f"{path}/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(stage, f"{path}/Reader")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set(varname)
    st_source = reader.ConnectableAPI(), "result"
    if transform is not None:
        node = UsdShade.Shader.Define(stage, f"{path}/Transform")
        node.CreateIdAttr("UsdTransform2d")
        node.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        for key, value in transform.items():
            kind = Sdf.ValueTypeNames.Float if key == "rotation" else Sdf.ValueTypeNames.Float2
            node.CreateInput(key, kind).Set(value)
        st_source = node.ConnectableAPI(), "result"
    texture = UsdShade.Shader.Define(stage, f"{path}/Texture")
    texture.CreateIdAttr("UsdUVTexture")
    texture.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(str(image))
    texture.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(*st_source)
    texture.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
    for name, (output, kind) in connections.items():
        texture.CreateOutput(output, kind)
        surface.CreateInput(name, kind).ConnectToSource(texture.ConnectableAPI(), output)
    for name, (kind, value) in (extra or {}).items():
        surface.CreateInput(name, kind).Set(value)
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    return material


def bind(prim, material):
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(material)


def lit_box_stage(path: Path, up="Y", meters=1.0, camera=True, light=True):
    """A 1×2×1 box centred at (3, 1, -2) (Y-up meters; the same box in the stage's own units/axes)."""
    stage = new_stage(path, up, meters)
    scale = 1.0 / meters
    cube = UsdGeom.Cube.Define(stage, "/Box")
    center = np.array([3.0, 1.0, -2.0]) * scale
    if up == "Z":
        center = np.array([center[0], -center[2], center[1]])
    cube.AddTranslateOp().Set(Gf.Vec3d(*center))
    size = np.array([0.5, 1.0, 0.5]) * scale
    cube.AddScaleOp().Set(Gf.Vec3f(*(size if up == "Y" else size[[0, 2, 1]])))
    if camera:
        add_camera(stage)
    if light:
        UsdLux.DomeLight.Define(stage, "/Dome")
    stage.GetRootLayer().Save()
    return path


# ------------------------------------------------------------------ cameras and lights on demand


def test_no_camera_refusal_names_both_options_and_camera_path_is_honoured(tmp_path):
    path = lit_box_stage(tmp_path / "s.usda", camera=False)
    with pytest.raises(UserInputError, match=r"--camera PATH.*--auto-camera"):
        translate_usd(path)
    result = run_cli("scenes", "check", path)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "--auto-camera" in result.stderr

    stage = Usd.Stage.Open(str(path))
    add_camera(stage, "/First", (0, 0, 5))
    add_camera(stage, "/Second", (1, 2, 9))
    stage.GetRootLayer().Save()
    assert translate_usd(path).camera.prim_path == "/First"
    track = translate_usd(path, camera_path="/Second").camera
    assert track.prim_path == "/Second" and np.allclose(track.poses[0][:3, 3], [1, 2, 9])
    with pytest.raises(UserInputError, match="not both"):
        translate_usd(path, camera_path="/Second", auto_camera=True)


def _projected(track, frame, points):
    """Normalized image x, y in [-1, 1] (x across the fov) of world points for ``track`` at ``frame``."""
    pose = np.asarray(track.poses[frame])
    local = (np.linalg.inv(pose) @ np.c_[points, np.ones(len(points))].T).T[:, :3]
    tan_half = math.tan(math.radians(track.fov_x_deg) / 2)
    assert np.all(local[:, 2] < 0), "a corner is behind the camera"
    return local[:, 0] / (-local[:, 2] * tan_half), local[:, 1] / (-local[:, 2] * tan_half)


def test_auto_camera_frames_the_bounds_for_any_up_axis_and_unit(tmp_path):
    """The same box on a Y-up meter stage and a Z-up centimeter stage gets the same camera in Mitsuba
    space (upAxis and metersPerUnit honoured); every box corner is in view at every frame; the camera
    orbits the box centre by 2° per frame at a constant distance, over --frames frames."""
    corners = np.array(
        [[3 + dx * 0.5, 1 + dy * 1.0, -2 + dz * 0.5] for dx in (-1, 1) for dy in (-1, 1) for dz in (-1, 1)]
    )
    tracks = []
    for up, meters in (("Y", 1.0), ("Z", 0.01)):
        path = lit_box_stage(tmp_path / f"{up}.usda", up, meters, camera=False)
        track = translate_usd(path, auto_camera=True, frames=5, strict=True).camera
        assert track.frames == 5 and track.prim_path == "/DenoisebenchAutoCamera"
        tracks.append(track)
        for frame in range(5):
            x, y = _projected(track, frame, corners)
            assert np.all(np.abs(x) < 1) and np.all(np.abs(y) < 1)
            assert np.max(np.abs(x)) > 0.3  # framed, not a speck
        eyes = np.stack([p[:3, 3] for p in track.poses]) - np.array([3.0, 1.0, -2.0])
        distances = np.linalg.norm(eyes, axis=1)
        np.testing.assert_allclose(distances, distances[0], rtol=1e-6)
        flat = eyes[:, [0, 2]] / np.linalg.norm(eyes[:, [0, 2]], axis=1, keepdims=True)
        steps = np.degrees(np.arccos(np.clip(np.sum(flat[1:] * flat[:-1], axis=1), -1, 1)))
        np.testing.assert_allclose(steps, 2.0, atol=1e-4)
    np.testing.assert_allclose(tracks[0].poses, tracks[1].poses, atol=1e-4)


def test_default_light_is_required_for_an_unlit_stage_and_lights_it(tmp_path):
    path = lit_box_stage(tmp_path / "dark.usda", light=False)
    with pytest.raises(UserInputError, match="--default-light"):
        translate_usd(path, strict=True)
    translated = translate_usd(path, default_light=True, strict=True)
    kinds = sorted(e.kind for e in translated.emitters)
    assert kinds == ["constant", "directional"]
    # A lit stage keeps its own lights.
    lit = lit_box_stage(tmp_path / "lit.usda")
    assert [e.kind for e in translate_usd(lit, default_light=True).emitters] == ["constant"]


def test_generate_writes_the_auto_camera_and_lights_into_the_copied_stage(tmp_path):
    from denoisebench.generator.dataset_scenes import check_user_stage, copy_user_stage, stage_options

    path = lit_box_stage(tmp_path / "bare.usda", camera=False, light=False)
    options = stage_options(auto_camera=True, default_light=True, frames=3)
    checked = check_user_stage(path, options)
    files = copy_user_stage(path, tmp_path / "out", options)
    assert files == ("scene.usda",)
    copied = translate_usd(tmp_path / "out" / "scene.usda", strict=True)  # no options needed any more
    np.testing.assert_allclose(copied.camera.poses, checked.camera.poses, atol=1e-9)
    assert len(copied.emitters) == 2
    assert Usd.Stage.Open(str(path)).GetPrimAtPath("/DenoisebenchAutoCamera").IsValid() is False  # source untouched

    # --camera PATH is recorded in the copy's metadata.
    stage = Usd.Stage.Open(str(path))
    add_camera(stage, "/A")
    add_camera(stage, "/B", (0, 1, 7))
    stage.GetRootLayer().Save()
    copy_user_stage(path, tmp_path / "out2", stage_options(camera="/B", default_light=True))
    assert translate_usd(tmp_path / "out2" / "scene.usda").camera.prim_path == "/B"


# ------------------------------------------------------------------ UsdLux point and spot lights


def _light_stage(path, configure):
    stage = lit_box_stage(path, light=False)
    stage = Usd.Stage.Open(str(path))
    configure(stage)
    stage.GetRootLayer().Save()
    return translate_usd(path)


def test_treat_as_point_and_zero_radius_sphere_lights_are_point_lights(tmp_path):
    def configure(stage):
        a = UsdLux.SphereLight.Define(stage, "/A")  # UsdLux's attribute: `treatAsPoint`, no inputs: prefix
        a.CreateRadiusAttr(0.1)
        a.CreateIntensityAttr(8.0)
        a.CreateTreatAsPointAttr(True)
        a.AddTranslateOp().Set(Gf.Vec3d(1, 2, 3))
        b = UsdLux.SphereLight.Define(stage, "/B")  # Blender's export: radius 0, normalize on
        b.CreateRadiusAttr(0.0)
        b.CreateIntensityAttr(12.0)
        b.CreateNormalizeAttr(True)

    assert (
        UsdLux.SphereLight(Usd.Stage.CreateInMemory().DefinePrim("/x", "SphereLight")).GetTreatAsPointAttr().GetName()
        == "treatAsPoint"
    )
    emitters = {e.prim: e for e in _light_stage(tmp_path / "p.usda", configure).emitters}
    assert isinstance(emitters["/A"], PointEmitter) and isinstance(emitters["/B"], PointEmitter)
    np.testing.assert_allclose(emitters["/A"].position, [1, 2, 3])
    # Power of the sphere: I = π r² L (not normalized); radius 0: I = L / 4 (the normalized form).
    np.testing.assert_allclose(emitters["/A"].intensity, [8.0 * math.pi * 0.01] * 3, rtol=1e-6)
    np.testing.assert_allclose(emitters["/B"].intensity, [3.0] * 3, rtol=1e-6)


@pytest.mark.slow
def test_shaping_cone_becomes_a_spot_and_lights_only_inside_its_cone(tmp_path):
    from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
    from denoisebench.generator.render.frame import render_frame
    from denoisebench.generator.render.scene import build_mitsuba_scene

    path = tmp_path / "spot.usda"
    stage = new_stage(path)
    add_camera(stage, position=(0, 0, 4), focal=18.0)  # fov_x = 90°: the floor spans x in [-4, 4]
    floor = add_quad(stage, "/Floor", size=8.0)
    light = UsdLux.SphereLight.Define(stage, "/Spot")
    light.CreateRadiusAttr(0.0)
    light.CreateIntensityAttr(40.0)
    light.CreateTreatAsPointAttr(True)
    light.AddTranslateOp().Set(Gf.Vec3d(0, 0, 1))  # 1 m in front of the floor, shining along -Z at it
    shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
    shaping.CreateShapingConeAngleAttr(30.0)
    shaping.CreateShapingConeSoftnessAttr(0.5)
    shaping.CreateShapingFocusAttr(2.0)
    stage.GetRootLayer().Save()
    translated = translate_usd(path)
    (spot,) = translated.emitters
    assert isinstance(spot, SpotEmitter) and spot.cutoff_angle == pytest.approx(30.0)
    assert spot.beam_width == pytest.approx(15.0)
    assert any("shaping:focus" in w for w in translated.warnings)
    assert floor
    plan = make_render_plan(translated.effects, RenderOptions(max_depth=2))
    image = render_frame(
        build_mitsuba_scene(translated), translated.camera, 0, plan, width=32, height=32, spp=4, seed=0, reference=True
    ).buffers["color"][..., 0]
    # The cone (30°) meets the floor within tan(30°) = 0.58 m of its centre: 0.58 / 4 of the half-width.
    x = (np.arange(32) + 0.5) / 16 - 1
    radius_m = np.hypot(*np.meshgrid(x, x)) * 4.0
    assert image[radius_m < 0.2].min() > 0
    # Outside it by more than half a pixel's diagonal (a box-filtered pixel is 0.25 m wide), no sample of the
    # pixel can reach the cone: those pixels are black.
    assert image[radius_m > 0.58 + 0.125 * np.sqrt(2)].max() == 0


def test_distant_light_angle_is_documented(tmp_path):
    def configure(stage):
        UsdLux.DistantLight.Define(stage, "/Sun").CreateAngleAttr(0.53)
        UsdLux.DistantLight.Define(stage, "/Overcast").CreateAngleAttr(20.0)

    warnings = _light_stage(tmp_path / "d.usda", configure).warnings
    assert [w for w in warnings if "angle" in w] == [
        "/Overcast: DistantLight angle 20° rendered as a delta light (hard shadows)"
    ]


# ------------------------------------------------------------------ textures


def _png(path: Path, array) -> Path:
    Image.fromarray(np.asarray(array, dtype=np.uint8)).save(path)
    return path


def test_packed_channels_varname_and_fallback_on_unreadable_textures(tmp_path):
    """ORM-style packed texture: roughness ← outputs:g, metallic ← outputs:b (UsdPreviewSurface spec:
    a float input reads the channel its connection names); coordinates from primvars:st0 (varname)."""
    packed = _png(tmp_path / "orm.png", np.broadcast_to([51, 128, 204], (4, 4, 3)))
    path = tmp_path / "t.usda"
    stage = new_stage(path)
    add_camera(stage)
    UsdLux.DomeLight.Define(stage, "/Dome")
    mesh = add_quad(stage, "/Quad", st_name="st0", st=((0, 0), (2, 0), (2, 2), (0, 2)))
    UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
        [(9, 9)] * 4
    )
    bind(
        mesh,
        textured_material(
            stage,
            "/Looks/Orm",
            packed,
            {"roughness": ("g", Sdf.ValueTypeNames.Float), "metallic": ("b", Sdf.ValueTypeNames.Float)},
            varname="st0",
        ),
    )
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n this is not an image")
    cmyk = tmp_path / "cmyk.jpg"
    Image.new("CMYK", (4, 4), (0, 255, 255, 0)).save(cmyk)
    for name, image in (("Corrupt", corrupt), ("Missing", tmp_path / "nope.png")):
        quad = add_quad(stage, f"/{name}")
        bind(
            quad,
            textured_material(
                stage,
                f"/Looks/{name}",
                image,
                {"diffuseColor": ("rgb", Sdf.ValueTypeNames.Color3f)},
                extra={"diffuseColor": (Sdf.ValueTypeNames.Color3f, Gf.Vec3f(0.1, 0.2, 0.3))},
            ),
        )
    quad = add_quad(stage, "/Cmyk")
    bind(quad, textured_material(stage, "/Looks/Cmyk", cmyk, {"diffuseColor": ("rgb", Sdf.ValueTypeNames.Color3f)}))
    stage.GetRootLayer().Save()
    translated = translate_usd(path)
    records = {r.name: r for r in translated.shapes}
    bsdfs = translated.bsdfs
    orm = bsdfs[records["/Quad"].bsdf]["bsdf"]
    np.testing.assert_allclose(orm["roughness"]["data"], 128 / 255, rtol=1e-6)
    np.testing.assert_allclose(orm["metallic"]["data"], 204 / 255, rtol=1e-6)
    assert orm["roughness"]["data"].shape == (4, 4, 1) and orm["roughness"]["raw"]
    np.testing.assert_allclose(records["/Quad"].uvs[:, 0], [0, 2, 2, 0])  # st0, not st
    for name in ("/Corrupt", "/Missing"):
        base = bsdfs[records[name].bsdf]["bsdf"]["base_color"]
        assert base == {"type": "rgb", "value": pytest.approx([0.1, 0.2, 0.3])}  # the input's own value
        assert sum(f"/Looks/{name[1:]}/Texture" in w for w in translated.warnings) == 1
    # A CMYK JPEG (Mitsuba's reader: "Unsupported number of components"): a warning, the default grey.
    assert sum("/Looks/Cmyk/Texture" in w and "cannot be read" in w for w in translated.warnings) == 1
    assert bsdfs[records["/Cmyk"].bsdf]["bsdf"]["base_color"]["type"] == "rgb"
    from denoisebench.generator.render.scene import build_mitsuba_scene

    build_mitsuba_scene(translated)


def _albedo(translated, frame=0, size=16, spp=4):
    from denoisebench.generator.contract.render_plan import make_render_plan
    from denoisebench.generator.render.frame import render_frame
    from denoisebench.generator.render.scene import build_mitsuba_scene

    out = render_frame(
        build_mitsuba_scene(translated, frame=frame),
        translated.camera,
        frame,
        make_render_plan(translated.effects),
        width=size,
        height=size,
        spp=spp,
        seed=0,
        _jitter=False,
    )
    return out.buffers


@pytest.mark.slow
def test_transform2d_shifts_the_texture_and_alpha_cutouts_open_holes(tmp_path):
    """UsdTransform2d translation (0.5, 0) with repeat wrapping swaps the halves of a red|blue texture;
    opacityThreshold 0.5 with opacity ← outputs:a cuts the alpha-0 half out (the wall behind shows)."""
    image = np.zeros((8, 8, 4), np.uint8)
    image[:, :4] = (255, 0, 0, 0)  # left half red, alpha 0
    image[:, 4:] = (0, 0, 255, 255)  # right half blue, opaque
    texture = _png(tmp_path / "rb.png", image)
    path = tmp_path / "t.usda"
    stage = new_stage(path)
    add_camera(stage, position=(0, 0, 2), focal=18.0)  # fov_x 90°: the 4 m quad at z=0 fills the view
    UsdLux.DomeLight.Define(stage, "/Dome")
    shifted = add_quad(stage, "/Shifted", size=4.0, z=0.0)
    bind(
        shifted,
        textured_material(
            stage,
            "/Looks/Shifted",
            texture,
            {"diffuseColor": ("rgb", Sdf.ValueTypeNames.Color3f)},
            transform={"translation": Gf.Vec2f(0.5, 0.0)},
        ),
    )
    stage.GetRootLayer().Save()
    albedo = _albedo(translate_usd(path))["albedo"]
    assert albedo[8, 2, 2] > 0.9 and albedo[8, 2, 0] < 0.05  # left is blue now
    assert albedo[8, 13, 0] > 0.9 and albedo[8, 13, 2] < 0.05  # right is red

    stage = Usd.Stage.Open(str(path))
    stage.RemovePrim("/Shifted")
    stage.RemovePrim("/Dome")
    wall = add_quad(stage, "/Wall", size=16.0, z=-2.0)  # the only light: a green emissive wall behind
    wall_material = UsdShade.Material.Define(stage, "/Looks/Green")
    surface = UsdShade.Shader.Define(stage, "/Looks/Green/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0, 0, 0))
    surface.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0, 1, 0))
    wall_material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    bind(wall, wall_material)
    cut = add_quad(stage, "/Cut", size=4.0, z=0.0)
    bind(
        cut,
        textured_material(
            stage,
            "/Looks/Cut",
            texture,
            {"diffuseColor": ("rgb", Sdf.ValueTypeNames.Color3f), "opacity": ("a", Sdf.ValueTypeNames.Float)},
            extra={"opacityThreshold": (Sdf.ValueTypeNames.Float, 0.5)},
        ),
    )
    stage.GetRootLayer().Save()
    translated = translate_usd(path)
    cut_bsdf = translated.bsdfs[[r for r in translated.shapes if r.name == "/Cut"][0].bsdf]
    assert cut_bsdf["type"] == "mask" and set(np.unique(cut_bsdf["opacity"]["data"])) == {0.0, 1.0}
    buffers = _albedo(translated)
    color, position = buffers["color"], buffers["position"]
    np.testing.assert_allclose(color[8, 2], [0, 1, 0], atol=1e-4)  # through the hole: the wall's emission
    assert color[8, 13].max() < 1e-4  # the opaque half faces the camera unlit (the wall lights its back)
    # Features describe what the camera sees: the wall through the hole, the quad where it is opaque.
    assert position[8, 2, 2] == pytest.approx(-2.0, abs=1e-3) and position[8, 13, 2] == pytest.approx(0.0, abs=1e-3)


def test_textures_inside_a_usdz_package_are_read_through_the_resolver(tmp_path):
    from denoisebench.generator.dataset_scenes import copy_user_stage

    folder = tmp_path / "src"
    folder.mkdir()
    _png(folder / "checker.png", np.kron([[1, 0], [0, 1]], np.ones((2, 2)))[..., None].repeat(3, -1) * 255)
    stage = new_stage(folder / "asset.usda")
    add_camera(stage)
    UsdLux.DomeLight.Define(stage, "/Dome")
    quad = add_quad(stage, "/Quad")
    bind(
        quad,
        textured_material(
            stage, "/Looks/M", Path("./checker.png"), {"diffuseColor": ("rgb", Sdf.ValueTypeNames.Color3f)}
        ),
    )
    stage.GetRootLayer().Save()
    package = tmp_path / "asset.usdz"
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(folder / "asset.usda")), str(package))
    (folder / "checker.png").unlink()  # only the package has it now

    def base_color(translated):
        (bsdf,) = translated.bsdfs.values()
        return bsdf["bsdf"]["base_color"]["data"]

    data = base_color(translate_usd(package, strict=True))
    np.testing.assert_allclose(data[..., 0], np.kron([[1, 0], [0, 1]], np.ones((2, 2))), atol=1e-6)
    files = copy_user_stage(package, tmp_path / "out")
    assert files == ("scene.usda", "package.usdz")
    np.testing.assert_array_equal(base_color(translate_usd(tmp_path / "out" / "scene.usda")), data)


# ------------------------------------------------------------------ robustness


def test_unsupported_only_stage_and_usd_diagnostics(tmp_path, capfd):
    path = tmp_path / "curves.usda"
    stage = new_stage(path)
    add_camera(stage)
    UsdLux.DomeLight.Define(stage, "/Dome")
    curves = UsdGeom.NurbsCurves.Define(stage, "/Hair")  # BasisCurves render: NurbsCurves stay unsupported
    curves.CreatePointsAttr([(0, 0, 0), (0, 1, 0), (1, 1, 0), (1, 2, 0)])
    curves.CreateCurveVertexCountsAttr([4])
    stage.GetRootLayer().Save()
    with pytest.raises(UserInputError, match=r"nothing renderable.*NurbsCurves"):
        translate_usd(path, strict=True)
    result = run_cli("scenes", "preview", path, "--out", tmp_path / "p.png", "--width", 8, "--height", 8, "--spp", 1)
    assert result.returncode == 2 and "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1

    text = path.read_text().replace(
        'def NurbsCurves "Hair"',
        'def Xform "Ref" (prepend references = [@./missing_a.usda@, @./missing_b.usda@]) {}\ndef NurbsCurves "Hair"',
    )
    text += '\ndef Cube "Box" {}\n'
    path = tmp_path / "with_references.usda"  # a new file: the open layer above is cached by USD
    path.write_text(text)
    capfd.readouterr()
    translated = translate_usd(path, strict=True)
    captured = capfd.readouterr()
    assert "missing_a" not in captured.err  # USD's own output is caught, not printed
    usd = [w for w in translated.warnings if ": USD: " in w]
    assert len(usd) == 1 and usd[0].startswith("/Ref: USD: Could not open asset") and usd[0].endswith("(+1 more)")


def test_preview_prints_warnings_before_rendering(tmp_path, monkeypatch):
    from denoisebench.generator import preview
    from denoisebench.generator.render import frame as feature_renderer

    path = lit_box_stage(tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(path))
    UsdGeom.NurbsCurves.Define(stage, "/Hair")
    stage.GetRootLayer().Save()
    events = []

    def failing_render(*args, **kwargs):
        events.append("render")
        raise RuntimeError("renderer broke")

    monkeypatch.setattr(feature_renderer, "render_frame", failing_render)
    with pytest.raises(RuntimeError):
        preview.render_preview(
            path, width=8, height=8, spp=1, before_render=lambda t: events.append(("warnings", tuple(t.warnings)))
        )
    assert events[0][0] == "warnings" and any("NurbsCurves" in w for w in events[0][1]) and events[1] == "render"


# ------------------------------------------------------------------ moving objects


def moving_box_stage(path: Path, frames=3, shift=0.25, turn=8.0):
    """Static camera, a textured box translating along +x and turning about y, a static wall behind."""
    stripes = np.zeros((16, 16, 3), np.uint8)
    stripes[:, (np.arange(16) // 4) % 2 == 0] = 255  # 4-texel stripes: a few pixels wide on screen
    stripes[(np.arange(16) // 4) % 2 == 0, :, 1:] //= 4  # and reddish bands across them
    texture = _png(path.parent / "stripes.png", stripes)
    stage = new_stage(path, frames=frames)
    add_camera(stage, position=(0, 0, 4))
    UsdLux.DomeLight.Define(stage, "/Dome")
    wall = add_quad(stage, "/Wall", size=10.0, z=-2.0)
    bind(wall, textured_material(stage, "/Looks/Wall", texture, {"diffuseColor": ("rgb", Sdf.ValueTypeNames.Color3f)}))
    box = UsdGeom.Cube.Define(stage, "/Box")
    bind(box, textured_material(stage, "/Looks/Box", texture, {"diffuseColor": ("rgb", Sdf.ValueTypeNames.Color3f)}))
    translate, rotate = box.AddTranslateOp(), box.AddRotateYOp()
    for frame in range(frames):
        translate.Set(Gf.Vec3d(-0.4 + shift * frame, 0, 0), frame)
        rotate.Set(turn * frame, frame)
    ball = UsdGeom.Sphere.Define(stage, "/Ball")
    ball.CreateRadiusAttr(0.3)
    move = ball.AddTranslateOp()
    for frame in range(frames):
        move.Set(Gf.Vec3d(1.2, 0.8 - 0.1 * frame, 0.5), frame)
    stage.GetRootLayer().Save()
    return path


def test_time_sampled_transforms_move_geometry_per_frame(tmp_path):
    translated = translate_usd(moving_box_stage(tmp_path / "m.usda"))
    assert translated.moving
    records = {r.name: r for r in translated.shapes}
    box, ball, wall = records["/Box"], records["/Ball"], records["/Wall"]
    assert wall.frame_positions is None and isinstance(ball, MeshShape)  # a moving sphere is tessellated
    centers = box.frame_positions.mean(axis=1)
    np.testing.assert_allclose(np.diff(centers[:, 0]), 0.25, atol=1e-5)
    np.testing.assert_allclose(ball.frame_positions.mean(axis=1)[:, 1], [0.8, 0.7, 0.6], atol=1e-5)
    assert not any("first-frame pose" in w for w in translated.warnings)


@pytest.mark.slow
def test_motion_vectors_reproject_a_moving_object_under_a_static_camera(tmp_path):
    """Warping frame 0 by frame 1's motion vectors must reproduce frame 1 where the surface was visible
    in both (the box's texture moved and turned); zero motion (camera-only vectors) must not."""
    translated = translate_usd(moving_box_stage(tmp_path / "m.usda"))
    size = 48
    first = _albedo(translated, frame=0, size=size, spp=1)
    second = _albedo(translated, frame=1, size=size, spp=1)
    motion = second["motion"]
    p = second["position"]
    wall = np.abs(p[..., 2] + 2.0) < 1e-4
    ball = np.linalg.norm(p - np.array([1.2, 0.7, 0.5]), axis=-1) < 0.32
    on_box = ~wall & ~ball & (second["depth"][..., 0] > 0)
    assert on_box.sum() > 100 and np.abs(motion[on_box]).max() > 1.0
    assert np.abs(motion[wall]).max() < 1e-3  # the static wall under a static camera: no motion

    ys, xs = np.nonzero(on_box)
    px = np.rint(xs + 0.5 + motion[ys, xs, 0] - 0.5).astype(int)
    py = np.rint(ys + 0.5 + motion[ys, xs, 1] - 0.5).astype(int)
    inside = (px >= 0) & (px < size) & (py >= 0) & (py < size)
    ys, xs, px, py = ys[inside], xs[inside], px[inside], py[inside]
    # Visible in frame 0 at the reprojected pixel: the same world point, moved back by the box's motion.
    same_surface = np.abs(first["depth"][py, px, 0] - second["depth"][ys, xs, 0]) < 0.3
    error_warped = np.abs(first["albedo"][py, px] - second["albedo"][ys, xs]).mean(-1)[same_surface]
    error_static = np.abs(first["albedo"][ys, xs] - second["albedo"][ys, xs]).mean(-1)[same_surface]
    assert same_surface.sum() > 50
    assert np.median(error_warped) < 0.02 and error_warped.mean() < 0.25 * error_static.mean()


def test_time_sampled_points_deform_the_mesh(tmp_path):
    path = tmp_path / "deform.usda"
    stage = new_stage(path, frames=3)
    add_camera(stage)
    UsdLux.DomeLight.Define(stage, "/Dome")
    mesh = add_quad(stage, "/Flag")
    points = mesh.GetPointsAttr()
    for frame in range(3):
        points.Set([(-1, -1, 0), (1, -1, 0.3 * frame), (1, 1, 0.3 * frame), (-1, 1, 0)], frame)
    stage.GetRootLayer().Save()
    (flag,) = translate_usd(path).shapes
    np.testing.assert_allclose(flag.frame_positions[:, 1, 2], [0.0, 0.3, 0.6], atol=1e-6)


def test_generate_refuses_a_bare_stage_naming_the_options(tmp_path):
    path = lit_box_stage(tmp_path / "bare.usda", camera=False, light=False)
    result = run_cli("generate", "--out", tmp_path / "out", "--usd", path, "--spp", 1, "--ref-spp", 4)
    assert result.returncode == 2 and "Traceback" not in result.stderr and "--auto-camera" in result.stderr
    result = run_cli("generate", "--out", tmp_path / "out", "--usd", path, "--auto-camera", "--spp", 1, "--ref-spp", 4)
    assert result.returncode == 2 and "--default-light" in result.stderr
    assert not (tmp_path / "out").exists()


def test_what_mitsuba_refuses_is_skipped_with_a_warning_never_a_crash(tmp_path):
    from denoisebench.generator.render.scene import build_mitsuba_scene

    translated = translate_usd(lit_box_stage(tmp_path / "s.usda"))
    (key,) = translated.bsdfs
    translated.bsdfs[key] = {"type": "no_such_bsdf_plugin"}
    translated.emitters += (
        EnvmapEmitter(prim="/BrokenDome", data=np.zeros((0, 0, 3), np.float32), scale=1.0, rotation=np.eye(3)),
    )
    scene = build_mitsuba_scene(translated)
    assert len(scene.shapes()) == 1 and len(scene.emitters()) == 1
    assert any(w.startswith(f"{key}: Mitsuba refuses the material") for w in translated.warnings)
    assert any(w.startswith("/BrokenDome: Mitsuba cannot build this light") for w in translated.warnings)
    translated.shapes = ()
    with pytest.raises(UserInputError, match="nothing renderable"):
        build_mitsuba_scene(translated)
