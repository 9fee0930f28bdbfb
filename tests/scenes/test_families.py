"""Scene families: every family authors a valid, deterministic stage that keeps its promises."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdShade

from denoisebench.scenes import EFFECTS, METADATA_KEY, camera_paths, get_family, list_families
from denoisebench.scenes.authoring import STAGE_FILENAME
from denoisebench.scenes.media import has_medium
from tests.support.paths import REPO

FRAMES = 4
SEED = 5
NAMES = [f.name for f in list_families()]
#: Families whose stages draw some effects per seed: the family lists their union, the stage its own.
PER_SEED_EFFECTS = {"cluttered"}


@pytest.fixture(scope="module")
def authored(tmp_path_factory) -> dict[str, Path]:
    """Every family authored once (seed 5, 4 frames); shared by the tests of this module."""
    root = tmp_path_factory.mktemp("families")
    return {name: get_family(name).author(root / name, seed=SEED, frames=FRAMES) for name in NAMES}


def _open(path: Path) -> Usd.Stage:
    stage = Usd.Stage.Open(str(path))
    assert stage is not None
    return stage


def _camera(stage: Usd.Stage) -> UsdGeom.Camera:
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera"))
    assert cam, "no camera at /World/Camera"
    return cam


def _poses(stage: Usd.Stage, frames: int) -> np.ndarray:
    cam = _camera(stage)
    return np.stack([np.array(cam.ComputeLocalToWorldTransform(Usd.TimeCode(f))) for f in range(frames)])


def _surface(material: UsdShade.Material) -> UsdShade.Shader:
    source = material.GetSurfaceOutput().GetConnectedSources()[0][0].source
    shader = UsdShade.Shader(source.GetPrim())
    assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
    return shader


def _bound_materials(stage: Usd.Stage) -> list[UsdShade.Material]:
    found = {}
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Gprim) or prim.IsA(UsdGeom.Subset):
            mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
            if mat:
                found[str(mat.GetPath())] = mat
    return [found[k] for k in sorted(found)]


def _value(shader: UsdShade.Shader, name: str):
    return shader.GetInput(name).Get()


def _infer_effects(stage: Usd.Stage, frames: int) -> set[str]:
    """The translator's rules, read straight off the stage (``indirect`` is never inferred)."""
    found = set()
    cam = _camera(stage)
    if (cam.GetFStopAttr().Get() or 0.0) > 0.0:
        found.add("depth_of_field")
    poses = _poses(stage, frames)
    if cam.GetShutterCloseAttr().Get() > cam.GetShutterOpenAttr().Get() and not np.allclose(poses, poses[:1]):
        found.add("motion_blur")
    for mat in _bound_materials(stage):
        s = _surface(mat)
        rough, metal, opacity = _value(s, "roughness"), _value(s, "metallic"), _value(s, "opacity")
        non_diffuse = metal > 0.5 or opacity < 1.0
        if non_diffuse and rough < 0.05:
            found.add("specular")
        elif non_diffuse and rough < 0.4:
            found.add("glossy")
        if opacity < 1.0:
            found.add("transmission")
        if max(_value(s, "emissiveColor")) > 0.0:
            found.add("area_lights")
    for prim in stage.Traverse():
        info = prim.GetAttribute("info:id").Get() if prim.IsA(UsdShade.Shader) else None
        if info == "UsdUVTexture":
            found.add("textures")
        if prim.IsA(UsdLux.RectLight) or prim.IsA(UsdLux.SphereLight) or prim.IsA(UsdLux.DiskLight):
            found.add("area_lights")
        if prim.IsA(UsdLux.DomeLight):
            found.add("environment")
        if has_medium(prim):
            found.add("media")
    return found


# --------------------------------------------------------------------------- registry


def test_registry_lists_at_least_eight_described_families():
    families = list_families()
    assert len(families) >= 8
    assert len({f.name for f in families}) == len(families)
    for fam in families:
        assert fam.effects and set(fam.effects) <= set(EFFECTS)
        assert list(fam.effects) == [e for e in EFFECTS if e in fam.effects]  # vocabulary order
        assert fam.description and "\n" not in fam.description
        assert fam.up_axis in ("Y", "Z") and fam.meters_per_unit > 0 and fam.camera_move


def test_unknown_family_is_a_value_error_naming_the_known_ones():
    with pytest.raises(ValueError) as err:
        get_family("no_such_family")
    for name in NAMES:
        assert name in str(err.value)


def test_declared_effects_cover_the_whole_vocabulary():
    covered = set().union(*(f.effects for f in list_families()))
    assert covered == set(EFFECTS)


def test_scenes_package_never_imports_mitsuba():
    code = (
        "import sys, tempfile; from denoisebench.scenes import get_family; "
        "get_family('cornell').author(tempfile.mkdtemp(), seed=0, frames=1); "
        "assert 'mitsuba' not in sys.modules and 'drjit' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


# --------------------------------------------------------------------------- every family


@pytest.mark.parametrize("name", NAMES)
def test_stage_opens_with_metadata_units_and_time_range(authored, name):
    fam = get_family(name)
    path = authored[name]
    assert path.name == STAGE_FILENAME and path.is_file()
    stage = _open(path)
    meta = stage.GetRootLayer().customLayerData[METADATA_KEY]
    assert meta["family"] == name and meta["seed"] == SEED and meta["frames"] == FRAMES
    if name in PER_SEED_EFFECTS:
        assert set(meta["effects"]) <= set(fam.effects) and list(meta["effects"]) == sorted(
            meta["effects"], key=list(EFFECTS).index
        )
    else:
        assert tuple(meta["effects"]) == fam.effects
    assert UsdGeom.GetStageUpAxis(stage) == fam.up_axis
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(fam.meters_per_unit)
    assert stage.GetStartTimeCode() == 0 and stage.GetEndTimeCode() == FRAMES - 1
    assert stage.GetTimeCodesPerSecond() == 24 and stage.GetFramesPerSecond() == 24
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/World")
    assert stage.GetDefaultPrim().IsA(UsdGeom.Xform)


@pytest.mark.parametrize("name", NAMES)
def test_camera_transform_is_sampled_at_every_frame(authored, name):
    stage = _open(authored[name])
    cam = _camera(stage)
    ops = cam.GetOrderedXformOps()
    assert len(ops) == 1 and ops[0].GetOpType() == UsdGeom.XformOp.TypeTransform
    assert ops[0].GetTimeSamples() == [float(f) for f in range(FRAMES)]
    poses = _poses(stage, FRAMES)
    assert np.all(np.isfinite(poses))
    for pose in poses:  # rigid: orthonormal rotation, no scale, right-handed
        rot = pose[:3, :3]
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-5)
        assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-5)
    assert not np.allclose(poses, poses[:1]), "camera does not move"
    assert cam.GetFocalLengthAttr().Get() > 0 and cam.GetHorizontalApertureAttr().Get() > 0
    near, far = cam.GetClippingRangeAttr().Get()
    assert 0 < near < far


@pytest.mark.parametrize("name", NAMES)
def test_every_gprim_has_a_preview_surface_material(authored, name):
    stage = _open(authored[name])
    gprims = [p for p in stage.Traverse() if p.IsA(UsdGeom.Gprim)]
    assert gprims
    for prim in gprims:
        mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        assert mat, f"{prim.GetPath()} has no material"
        surface = _surface(mat)
        for key in ("diffuseColor", "roughness", "metallic", "ior", "opacity", "emissiveColor"):
            assert surface.GetInput(key).GetAttr().HasAuthoredValue(), f"{mat.GetPath()}: {key} not authored"
    for subset in (p for p in stage.Traverse() if p.IsA(UsdGeom.Subset)):
        assert UsdGeom.Subset(subset).GetFamilyNameAttr().Get() == "materialBind"
        assert UsdShade.MaterialBindingAPI(subset).ComputeBoundMaterial()[0]


@pytest.mark.parametrize("name", NAMES)
def test_declared_effects_match_what_the_stage_contains(authored, name):
    declared = _stage_effects(authored[name])
    inferred = _infer_effects(_open(authored[name]), FRAMES)
    assert inferred == declared - {"indirect"}


@pytest.mark.parametrize("name", NAMES)
def test_textures_exist_beside_the_stage(authored, name):
    stage = _open(authored[name])
    root = authored[name].parent
    referenced = set()
    for prim in stage.Traverse():
        for attr in prim.GetAttributes():
            if attr.GetTypeName() == Sdf.ValueTypeNames.Asset and attr.Get() is not None:
                asset = attr.Get().path
                assert asset.startswith("textures/") and asset.endswith(".png"), asset
                assert (root / asset).is_file(), asset
                referenced.add(asset)
    on_disk = (
        {f"textures/{p.name}" for p in (root / "textures").glob("*.png")} if (root / "textures").exists() else set()
    )
    assert on_disk == referenced
    if "textures" in get_family(name).effects:
        assert any(
            prim.GetAttribute("info:id").Get() == "UsdUVTexture"
            for prim in stage.Traverse()
            if prim.IsA(UsdShade.Shader)
        )


@pytest.mark.parametrize("name", NAMES)
def test_geometry_stays_modest_and_finite(authored, name):
    stage = _open(authored[name])
    triangles = 0
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh):
            mesh = UsdGeom.Mesh(prim)
            counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
            indices = np.asarray(mesh.GetFaceVertexIndicesAttr().Get())
            points = np.asarray(mesh.GetPointsAttr().Get())
            assert counts.min() >= 3 and counts.sum() == len(indices)
            assert indices.min() >= 0 and indices.max() < len(points)
            assert np.all(np.isfinite(points))
            triangles += int(np.sum(counts - 2))
            st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
            if st:
                n = len(points) if st.GetInterpolation() == UsdGeom.Tokens.vertex else len(indices)
                assert len(st.Get()) == n
            if mesh.GetNormalsAttr().HasAuthoredValue():
                interp = mesh.GetNormalsInterpolation()
                n = len(points) if interp == UsdGeom.Tokens.vertex else len(indices)
                assert len(mesh.GetNormalsAttr().Get()) == n
    assert triangles < 20000


# --------------------------------------------------------------------------- determinism


@pytest.mark.parametrize("name", NAMES)
def test_same_seed_gives_identical_bytes_and_another_seed_differs(authored, name, tmp_path):
    first = authored[name]
    again = get_family(name).author(tmp_path / "again", seed=SEED, frames=FRAMES)
    assert again.read_bytes() == first.read_bytes()
    files_a = sorted(p.relative_to(first.parent) for p in first.parent.rglob("*") if p.is_file())
    files_b = sorted(p.relative_to(again.parent) for p in again.parent.rglob("*") if p.is_file())
    assert files_a == files_b
    for rel in files_a:
        assert (first.parent / rel).read_bytes() == (again.parent / rel).read_bytes(), rel
    other = get_family(name).author(tmp_path / "other", seed=SEED + 1, frames=FRAMES)
    assert other.read_bytes() != first.read_bytes()


def test_reauthoring_into_the_same_folder_leaves_no_stale_textures(tmp_path):
    fam = get_family("texture_checker")
    fam.author(tmp_path, seed=0, frames=2)
    (tmp_path / "textures" / "stale.png").write_bytes(b"not a texture")
    stage = _open(fam.author(tmp_path, seed=1, frames=2))
    stage_assets = {
        attr.Get().path
        for prim in stage.Traverse()
        for attr in prim.GetAttributes()
        if attr.GetTypeName() == Sdf.ValueTypeNames.Asset and attr.Get() is not None
    }
    assert {f"textures/{p.name}" for p in (tmp_path / "textures").iterdir()} == stage_assets


def test_exported_layer_has_no_doc_string_or_absolute_path(authored):
    text = authored["cornell"].read_text()
    assert text.startswith("#usda 1.0\n")
    assert "doc = " not in text and str(authored["cornell"].parent) not in text


def test_single_frame_and_bad_arguments(tmp_path):
    fam = get_family("cornell")
    stage = _open(fam.author(tmp_path / "one", seed=0, frames=1))
    assert stage.GetEndTimeCode() == 0
    assert _camera(stage).GetOrderedXformOps()[0].GetTimeSamples() == [0.0]
    with pytest.raises(ValueError):
        fam.author(tmp_path / "zero", seed=0, frames=0)
    with pytest.raises(ValueError):
        fam.author(tmp_path / "neg", seed=-1, frames=2)


def test_aspect_sets_vertical_aperture(tmp_path):
    stage = _open(get_family("cornell").author(tmp_path, seed=0, frames=2, width=320, height=240))
    cam = _camera(stage)
    assert cam.GetHorizontalApertureAttr().Get() / cam.GetVerticalApertureAttr().Get() == pytest.approx(
        320 / 240, rel=1e-5
    )


# --------------------------------------------------------------------------- family promises


def _stage_effects(path: Path) -> set[str]:
    """The effects a stage's metadata declares (the family's own, or a per-seed subset of them)."""
    stage = _open(path)  # keep the stage alive while its layer is read
    return set(stage.GetRootLayer().customLayerData[METADATA_KEY]["effects"])


def _lens(stage: Usd.Stage) -> tuple[float, float]:
    """(horizontal field of view in degrees, thin-lens radius in meters) per UsdGeomCamera units."""
    cam = _camera(stage)
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    focal, aperture, fstop = (
        cam.GetFocalLengthAttr().Get(),
        cam.GetHorizontalApertureAttr().Get(),
        cam.GetFStopAttr().Get(),
    )
    fov = math.degrees(2 * math.atan(0.5 * aperture / focal))
    radius = focal * 0.1 * mpu / (2 * fstop) if fstop > 0 else 0.0
    return fov, radius


@pytest.mark.parametrize("name", NAMES)
def test_lens_is_physical_and_depth_of_field_only_where_declared(authored, name):
    stage = _open(authored[name])
    fov, radius = _lens(stage)
    assert 15.0 < fov < 100.0
    cam = _camera(stage)
    if "depth_of_field" in _stage_effects(authored[name]):
        assert cam.GetFStopAttr().Get() > 0 and cam.GetFocusDistanceAttr().Get() > 0
        assert 0.005 < radius < 0.05  # a real lens: 1 to 10 cm wide
    else:
        assert radius == 0.0
    if "motion_blur" not in _stage_effects(authored[name]):
        assert cam.GetShutterOpenAttr().Get() == cam.GetShutterCloseAttr().Get() == 0.0


def test_depth_of_field_family_is_strong(authored):
    stage = _open(authored["depth_of_field"])
    cam = _camera(stage)
    assert 0 < cam.GetFStopAttr().Get() <= 2.0
    _, radius = _lens(stage)
    focus = cam.GetFocusDistanceAttr().Get() * UsdGeom.GetStageMetersPerUnit(stage)
    focal = cam.GetFocalLengthAttr().Get() * 0.1 * UsdGeom.GetStageMetersPerUnit(stage)
    # Circle of confusion of a point at infinity, as a fraction of the film width.
    film = cam.GetHorizontalApertureAttr().Get() * 0.1 * UsdGeom.GetStageMetersPerUnit(stage)
    coc = 2 * radius * focal / (focus - focal) / film
    assert coc > 0.015  # > 7 px at 512 px wide


def test_motion_blur_family_has_open_shutter_and_fast_camera(authored):
    stage = _open(authored["motion_blur"])
    cam = _camera(stage)
    assert cam.GetShutterCloseAttr().Get() - cam.GetShutterOpenAttr().Get() >= 0.25
    step, turn = camera_paths.per_frame_motion(_poses(stage, FRAMES))
    assert turn >= 5.0


def test_fireflies_family_has_small_intense_light_and_glossy_metal(authored):
    stage = _open(authored["glossy_fireflies"])
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    small = [
        UsdLux.SphereLight(p)
        for p in stage.Traverse()
        if p.IsA(UsdLux.SphereLight) and UsdLux.SphereLight(p).GetRadiusAttr().Get() * mpu < 0.03
    ]
    assert small
    for light in small:
        assert light.GetTreatAsPointAttr().Get() is False
        assert light.GetIntensityAttr().Get() * 2 ** light.GetExposureAttr().Get() >= 1e4
    glossy = [
        m
        for m in _bound_materials(stage)
        if _value(_surface(m), "metallic") > 0.5 and 0.05 <= _value(_surface(m), "roughness") < 0.4
    ]
    assert glossy


def test_families_exercise_z_up_centimeters_and_geom_subsets(authored):
    fams = list_families()
    assert any(f.up_axis == "Z" for f in fams)
    assert any(f.meters_per_unit == pytest.approx(0.01) for f in fams)
    with_subsets = []
    for name, path in authored.items():
        stage = _open(path)
        for prim in stage.Traverse():
            if prim.IsA(UsdGeom.Mesh):
                subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
                if subsets:
                    mats = {
                        str(UsdShade.MaterialBindingAPI(s.GetPrim()).ComputeBoundMaterial()[0].GetPath())
                        for s in subsets
                    }
                    assert len(mats) >= 2
                    with_subsets.append(name)
    assert with_subsets


def test_thin_geometry_is_thin(authored):
    stage = _open(authored["thin_geometry"])
    radii = [UsdGeom.Cylinder(p).GetRadiusAttr().Get() for p in stage.Traverse() if p.IsA(UsdGeom.Cylinder)]
    assert min(radii) * UsdGeom.GetStageMetersPerUnit(stage) < 0.005


def test_room_families_are_closed(authored):
    """cornell and dim_room are closed rooms: the camera sits inside their wall meshes' bounds."""
    for name, mesh_path in (("cornell", "/World/Geometry/Room"), ("dim_room", "/World/Geometry/WallsAndCeiling")):
        stage = _open(authored[name])
        points = np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath(mesh_path)).GetPointsAttr().Get())
        lo, hi = points.min(axis=0), points.max(axis=0)
        for pose in _poses(stage, FRAMES):
            assert np.all(pose[3, :3] > lo) and np.all(pose[3, :3] < hi)


# --------------------------------------------------------------------------- camera paths


def test_look_at_points_minus_z_at_the_target():
    m = camera_paths.look_at((1.0, 2.0, 3.0), (1.0, 2.0, -5.0))
    np.testing.assert_allclose(m[3, :3], (1.0, 2.0, 3.0))
    np.testing.assert_allclose(-m[2, :3], (0.0, 0.0, -1.0), atol=1e-12)
    np.testing.assert_allclose(m[1, :3], (0.0, 1.0, 0.0), atol=1e-12)
    z_up = camera_paths.look_at((0.0, -5.0, 1.0), (0.0, 0.0, 1.0), up=(0.0, 0.0, 1.0))
    np.testing.assert_allclose(z_up[1, :3], (0.0, 0.0, 1.0), atol=1e-12)
    straight_down = camera_paths.look_at((0.0, 3.0, 0.0), (0.0, 0.0, 0.0))
    assert np.all(np.isfinite(straight_down))
    np.testing.assert_allclose(-straight_down[2, :3], (0.0, -1.0, 0.0), atol=1e-12)


def test_handheld_shake_is_seeded_and_small():
    base = camera_paths.static((0.0, 1.0, 5.0), (0.0, 1.0, 0.0), 16)
    a = camera_paths.handheld_shake(base, np.random.default_rng(3), 0.02, 0.5)
    b = camera_paths.handheld_shake(base, np.random.default_rng(3), 0.02, 0.5)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, base)
    assert np.max(np.abs(a[:, 3, :3] - base[:, 3, :3])) < 0.05
