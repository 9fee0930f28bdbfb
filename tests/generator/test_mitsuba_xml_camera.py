"""Mitsuba XML scenes in ``scenes check/preview`` and with ``--auto-camera``, at 16 px.

Peer for the orbit: the USD auto camera. The same box as a USD stage (translated with
``--auto-camera``) and as a Mitsuba XML file must get the same camera track in Mitsuba world space;
the orbit's geometry is checked on its own too (box in view at every frame, 2° steps, constant
distance). The CLI paths are checked end to end: JSON of ``scenes check``, a PNG from
``scenes preview``, one-line refusals, and a ``generate-dataset --mitsuba --auto-camera`` dataset
whose copied scene re-renders the same camera without options.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from denoisebench.cli import main
from denoisebench.errors import UserInputError
from denoisebench.generator.contract.orbit import fov_x_radians, look_at, orbit
from denoisebench.generator.mitsuba_xml import AUTO_CAMERA, load_mitsuba_xml

CENTER, HALF = np.array([3.0, 1.0, -2.0]), np.array([0.5, 1.0, 0.5])  # a 1×2×1 box

BOX = f"""<scene version="3.0.0">
  {{sensor}}
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  <shape type="cube"><transform name="to_world"><scale x="{HALF[0]}" y="{HALF[1]}" z="{HALF[2]}"/>
    <translate x="{CENTER[0]}" y="{CENTER[1]}" z="{CENTER[2]}"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf></shape>
</scene>
"""
SENSOR = """<sensor type="perspective"><float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="3, 2, 4" target="3, 1, -2" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>"""


def write_box(folder, sensor=True, name="box.xml"):
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(BOX.format(sensor=SENSOR if sensor else ""))
    return path


def usd_box(path):
    """The same box as a Y-up, metre USD stage with a dome light and no camera."""
    from pxr import Gf, Usd, UsdGeom, UsdLux

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    cube = UsdGeom.Cube.Define(stage, "/Box")  # size 2: [-1, 1]^3 before its scale
    cube.AddTranslateOp().Set(Gf.Vec3d(*CENTER))
    cube.AddScaleOp().Set(Gf.Vec3f(*HALF))
    UsdLux.DomeLight.Define(stage, "/Dome")
    stage.GetRootLayer().Save()
    return path


def _projected(pose, fov_x_deg, points):
    local = (np.linalg.inv(pose) @ np.c_[points, np.ones(len(points))].T).T[:, :3]
    assert np.all(local[:, 2] < 0), "a corner is behind the camera"
    tan_half = math.tan(math.radians(fov_x_deg) / 2)
    return local[:, 0] / (-local[:, 2] * tan_half), local[:, 1] / (-local[:, 2] * tan_half)


def test_xml_auto_camera_is_the_usd_auto_camera_of_the_same_box(tmp_path, mi):
    from denoisebench.generator.usd.translate import translate_usd

    usd = translate_usd(usd_box(tmp_path / "box.usda"), auto_camera=True, frames=5, strict=True).camera
    translated, _ = load_mitsuba_xml(write_box(tmp_path), frames=5, auto_camera=True)
    camera = translated.camera
    assert camera.prim_path == AUTO_CAMERA and camera.frames == 5 and camera.is_animated
    np.testing.assert_allclose(camera.poses, usd.poses, atol=1e-5)
    assert camera.fov_x_deg == pytest.approx(usd.fov_x_deg, abs=1e-9)
    assert (camera.near_clip, camera.far_clip) == pytest.approx((usd.near_clip, usd.far_clip), rel=1e-5)
    assert not camera.has_depth_of_field and not camera.has_open_shutter
    # the orbit's geometry on its own: every corner in view, 2° steps at a constant distance, 20° up
    corners = CENTER + HALF * np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    for pose in camera.poses:
        x, y = _projected(pose, camera.fov_x_deg, corners)
        assert np.all(np.abs(x) < 1) and np.all(np.abs(y) < 1) and np.abs(x).max() > 0.3
    eyes = camera.poses[:, :3, 3] - CENTER
    radius = float(np.linalg.norm(HALF))
    np.testing.assert_allclose(np.linalg.norm(eyes, axis=1), radius / math.sin(fov_x_radians() / 2) * 1.1)
    np.testing.assert_allclose(np.degrees(np.arcsin(eyes[:, 1] / np.linalg.norm(eyes, axis=1))), 20.0)
    azimuth = np.degrees(np.arctan2(eyes[:, 2], eyes[:, 0]))
    np.testing.assert_allclose(azimuth, 30.0 + 2.0 * np.arange(5), atol=1e-9)


def test_look_at_looks_down_minus_z_with_y_up():
    pose = look_at([0, 0, 5], [0, 0, 0], [0, 1, 0])
    np.testing.assert_allclose(pose, np.c_[np.eye(4)[:, :3], [0, 0, 5, 1]], atol=1e-12)
    track = orbit([-1, -1, -1], [1, 1, 1], 1)
    forward = -track.poses[0][:3, 2]
    np.testing.assert_allclose(forward, -track.poses[0][:3, 3] / np.linalg.norm(track.poses[0][:3, 3]))


def test_a_scene_without_a_sensor_needs_the_auto_camera(tmp_path, mi):
    path = write_box(tmp_path, sensor=False)
    with pytest.raises(UserInputError, match="no sensor.*--auto-camera"):
        load_mitsuba_xml(path)
    assert load_mitsuba_xml(path, frames=3, auto_camera=True)[0].camera.frames == 3


def test_scenes_check_reads_an_xml_scene(tmp_path, mi, capsys):
    path = write_box(tmp_path)
    assert main(["scenes", "check", str(path)]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["family"] == "mitsuba_xml" and report["camera"] == "sensor:perspective"
    assert report["frames"] == 8 and report["effects_inferred"] == ["environment"]
    assert report["render_plan"]["camera_model"] == "pinhole"
    assert main(["scenes", "check", str(path), "--auto-camera"]) == 0
    assert json.loads(capsys.readouterr().out)["camera"] == AUTO_CAMERA
    for flags, message in (
        (["--camera", "/Cam"], "--camera applies to USD stages"),
        (["--default-light"], "--default-light applies to USD stages"),
        ([], "no sensor"),
    ):
        target = write_box(tmp_path / "bare", sensor=False) if not flags else path
        assert main(["scenes", "check", str(target), *flags]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err


def test_scenes_preview_renders_an_xml_scene_and_its_orbit(tmp_path, mi, capsys):
    from PIL import Image

    path = write_box(tmp_path)
    common = ["--width", "16", "--height", "16", "--spp", "4"]
    pngs = {}
    for name, flags in (("sensor", []), ("orbit0", ["--auto-camera"]), ("orbit7", ["--auto-camera", "--frame", "7"])):
        out = tmp_path / f"{name}.png"
        assert main(["scenes", "preview", str(path), "--out", str(out), *common, *flags]) == 0
        pngs[name] = np.asarray(Image.open(out), dtype=np.float64)
    assert all(image.shape == (16, 16, 3) and image.std() > 5 for image in pngs.values())  # not blank
    assert np.abs(pngs["orbit0"] - pngs["orbit7"]).mean() > 1  # the orbit moved
    assert np.abs(pngs["sensor"] - pngs["orbit0"]).mean() > 1  # another camera than the file's
    assert main(["scenes", "preview", str(path), "--out", str(tmp_path / "x.png"), *common, "--frame", "8"]) == 2
    assert "out of range" in capsys.readouterr().err


def test_generate_with_auto_camera_records_the_orbit_in_the_copy(tmp_path, mi):
    from denoisebench.dataset import open_dataset
    from denoisebench.generator.dataset_scenes import load_scene_file

    source = write_box(tmp_path / "src", sensor=False)
    out = tmp_path / "ds"
    args = ["generate", "--out", str(out), "--mitsuba", str(source), "--auto-camera", "--frames", "2"]
    assert main([*args, "--width", "16", "--height", "16", "--spp", "1", "--ref-spp", "4", "--ref-error", "0"]) == 0
    info = open_dataset(out).scene("xml_box")
    assert info.record["camera"]["prim_path"] == AUTO_CAMERA and info.record["camera"]["animated"] is True
    sidecar = json.loads((out / "xml_box" / "camera.json").read_text())
    assert sidecar["auto_camera"] is True and sidecar["frames"] == 2
    reloaded, _ = load_scene_file(out / "xml_box" / "scene.xml")  # no options: the sidecar says it
    expected, _ = load_mitsuba_xml(source, frames=2, auto_camera=True)
    np.testing.assert_array_equal(reloaded.camera.poses, expected.camera.poses)
    frames = [open_dataset(out).frame("xml_box", 1, i).buffers["color"] for i in (0, 1)]
    assert not np.array_equal(frames[0], frames[1])
