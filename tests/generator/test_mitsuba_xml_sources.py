"""Mitsuba scenes as their authors ship them: ``<path>`` directives, ``--define``
parameters, wrapped (``moment``, ``aov``) and ``direct`` integrators, orthographic sensors, and
portable dataset configs.

Peers: Mitsuba itself. Without any fetched data, small scenes written here are held against
Mitsuba's own renders of the same files: a ``direct`` scene wrapped in ``moment`` against Mitsuba's
``direct`` integrator, an ``orthographic`` sensor against Mitsuba's ``path`` through that sensor
(image mean within 2 %, every 8×8 block within 8 %, the criterion of test_mitsuba_xml.py, with
controls that the criterion rejects full transport and a wrong view). With ``MITSUBA_DATA``
pointing at a fetched mitsuba-data, Mitsuba's render test scenes, unmodified, are loaded from
their own folder and must pass Mitsuba's own z-test (``src/render/tests/test_renders.py``: per
channel p-value above the Šidák-corrected 1 %, for 99.75 % of the pixels, in XYZ, at 2e6 samples
over the image) against their shipped references.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from denoisebench.cli import main
from denoisebench.errors import UserInputError
from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.mitsuba_xml import load_mitsuba_xml
from denoisebench.generator.mitsuba_xml_structure import XML_NAME, parse_defines, portable_files, read_structure
from denoisebench.generator.render.frame import render_frame

SIZE = 16
FILM = f"""<film type="hdrfilm"><integer name="width" value="{SIZE}"/><integer name="height" value="{SIZE}"/>
      <rfilter type="box"/></film>"""
TRIANGLE = "v -1 0 -1\nv 1 0 -1\nv 0 0 1\nf 1 3 2\n"

# A scene as Mitsuba's test scenes are written: <path> to a shared folder, $parameters, a wrapped integrator.
SHIPPED = f"""<scene version="3.0.0">
  <path value="../../common"/>
  <default name="integrator" value="direct"/>
  <integrator type="moment"><integrator type="$integrator"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="$fov"/>
    <transform name="to_world"><lookat origin="0, 3, 4" target="0, 0.3, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
    {FILM}
  </sensor>
  <emitter type="point"><point name="position" x="1" y="3" z="1"/><rgb name="intensity" value="20"/></emitter>
  <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.8"/></bsdf>
  <shape type="obj"><string name="filename" value="meshes/floor.obj"/>
    <transform name="to_world"><scale value="3"/></transform><ref id="white"/></shape>
  <shape type="obj"><string name="filename" value="../shared/tri.obj"/>
    <transform name="to_world"><rotate x="1" angle="90"/><translate y="1" z="-1"/></transform><ref id="white"/></shape>
  <shape type="sphere"><point name="center" x="0" y="0.6" z="0"/><float name="radius" value="0.6"/>
    <ref id="white"/></shape>
</scene>
"""


def write_shipped(root: Path) -> Path:
    """root/common/meshes/floor.obj (found through <path>), root/scenes/shared/tri.obj (named with
    ``..``), and the scene root/scenes/cases/shipped.xml."""
    (root / "common" / "meshes").mkdir(parents=True, exist_ok=True)
    (root / "common" / "meshes" / "floor.obj").write_text(TRIANGLE)
    (root / "scenes" / "shared").mkdir(parents=True, exist_ok=True)
    (root / "scenes" / "shared" / "tri.obj").write_text(TRIANGLE)
    (root / "scenes" / "cases").mkdir(parents=True, exist_ok=True)
    path = root / "scenes" / "cases" / "shipped.xml"
    path.write_text(SHIPPED)
    return path


def _blocks(image, block=8):
    h, w, c = image.shape
    return image.reshape(h // block, block, w // block, block, c).mean(axis=(1, 3))


def _agree(ours, theirs):
    mean = float(np.abs(ours.mean(axis=(0, 1)) / theirs.mean(axis=(0, 1)) - 1).max())
    block = float(np.abs(_blocks(ours) / np.maximum(_blocks(theirs), 1e-6) - 1).max())
    return mean, block


def _collect_garbage():
    """Collect cyclic garbage now, not inside the renderer's frozen pass.

    Notes:
        ``mi.load_file`` and ``mi.render`` leave cyclic garbage (nanobind types); when Python's
        collector happened to free it while a frozen Dr.Jit pass was recording, the process
        aborted (seen once the transport tests ran before the Mitsuba comparisons)."""
    import gc

    gc.collect()


def _ours(translated, scene, spp, max_depth=None, size=SIZE):
    _collect_garbage()
    plan = make_render_plan(translated.effects, RenderOptions(max_depth=max_depth), translated.max_depth)
    out = render_frame(scene, translated.camera, 0, plan, width=size, height=size, spp=spp, seed=3, reference=True)
    return out.buffers["color"].astype(np.float64)


def _mitsuba(mi, scene, integrator=None, spp=256, rounds=4):
    images = [
        np.array(mi.render(scene, integrator=integrator, seed=50 + k, spp=spp), dtype=np.float64)[..., :3]
        for k in range(rounds)
    ]
    return np.mean(images, axis=0)


# ------------------------------------------------------------------ parameters and files


def test_defines_are_parsed_and_malformed_ones_refused():
    assert parse_defines(["spp=16", "integrator=path", "name=a=b", "empty="]) == {
        "spp": "16",
        "integrator": "path",
        "name": "a=b",
        "empty": "",
    }
    for bad in ("spp", "=3", "1x=2", "a b=1"):
        with pytest.raises(UserInputError, match="--define expects NAME=VALUE"):
            parse_defines([bad])


def test_path_directives_and_parameters_resolve_as_mitsuba_does(tmp_path, mi):
    path = write_shipped(tmp_path)
    before = path.read_bytes()
    with pytest.raises(UserInputError, match=r"undefined parameter \$fov .*give --define fov=VALUE") as caught:
        read_structure(path)
    assert "\n" not in str(caught.value)
    with pytest.raises(UserInputError, match=r"--define nope=.*no parameter \$nope"):
        read_structure(path, {"fov": "40", "nope": "1"})
    structure = read_structure(path, {"fov": "40"})
    # $spp has no <default> and needs no --define: denoisebench sets its own sample count
    assert structure.placeholders == ("spp",) and structure.parameters["fov"] == "40"
    assert structure.resolved["meshes/floor.obj"] == (tmp_path / "common" / "meshes" / "floor.obj").resolve()
    assert structure.resolved["../shared/tri.obj"] == (tmp_path / "scenes" / "shared" / "tri.obj").resolve()
    assert structure.search_paths[1] == path.parent.resolve()  # after the <path> folder, as Mitsuba searches
    translated, scene = load_mitsuba_xml(path, frames=1, defines={"fov": "40"})
    assert translated.camera.fov_x_deg == pytest.approx(40.0, abs=1e-3) and len(scene.shapes()) >= 2
    assert path.read_bytes() == before  # the user's file is never changed


def test_the_portable_copy_loads_elsewhere_without_options(tmp_path, mi):
    path = write_shipped(tmp_path / "src")
    copy = portable_files(path, {"fov": "40", "integrator": "path"})
    assert set(copy) == {XML_NAME, "meshes/floor.obj", "files/tri.obj"}
    text = copy[XML_NAME].decode()
    assert "<path" not in text and 'value="files/tri.obj"' in text and "../shared" not in text
    assert '<default name="fov" value="40"' in text and '<default name="integrator" value="path"' in text
    elsewhere = tmp_path / "elsewhere" / "deep"
    for relative, data in copy.items():
        (elsewhere / relative).parent.mkdir(parents=True, exist_ok=True)
        (elsewhere / relative).write_bytes(data)
    shutil.rmtree(tmp_path / "src")  # nothing of the original is left to find
    translated, scene = load_mitsuba_xml(elsewhere / XML_NAME, frames=1)
    assert translated.camera.fov_x_deg == pytest.approx(40.0, abs=1e-3) and len(scene.shapes()) >= 2
    assert translated.max_depth is None  # integrator=path was written into the copy


def test_a_file_that_needs_no_rewriting_is_copied_byte_for_byte(tmp_path, mi):
    path = tmp_path / "plain.xml"
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "t.obj").write_text(TRIANGLE)
    path.write_text(
        f"""<scene version="3.0.0"> <!-- a comment -->
  <sensor type="perspective">{FILM}</sensor><emitter type="constant"/>
  <shape type="obj"><string name="filename" value="meshes/t.obj"/></shape></scene>
"""
    )
    copy = portable_files(path)
    assert copy == {XML_NAME: path.read_bytes(), "meshes/t.obj": TRIANGLE.encode()}


# --------------------------------------------------------------------------- transport


@pytest.mark.parametrize(
    "integrator, depth, origin",
    [
        ('<integrator type="moment"><integrator type="direct"/></integrator>', 2, "'direct' in 'moment'"),
        ('<integrator type="direct"/>', 2, "direct illumination only"),
        (
            '<integrator type="aov"><string name="aovs" value="dd.y:depth"/>'
            '<integrator type="path"><integer name="max_depth" value="3"/></integrator></integrator>',
            3,
            "'path' in 'aov': max_depth 3",
        ),
        ('<integrator type="moment"><integrator type="volpath"/></integrator>', None, ""),
        ('<integrator type="path"><integer name="max_depth" value="-1"/></integrator>', None, ""),
    ],
)
def test_the_scenes_own_transport_is_read_through_wrappers(tmp_path, mi, integrator, depth, origin):
    path = tmp_path / "t.xml"
    path.write_text(
        f'<scene version="3.0.0">{integrator}<sensor type="perspective">{FILM}</sensor>'
        '<emitter type="constant"/><shape type="sphere"/></scene>'
    )
    translated, _ = load_mitsuba_xml(path, frames=1)
    assert translated.max_depth == depth and origin in translated.transport_origin
    assert not translated.warnings
    plan = make_render_plan(translated.effects, RenderOptions(), stage_max_depth=translated.max_depth)
    assert plan.max_depth == (depth or -1) and plan.max_depth_source == ("stage" if depth else "default")
    # --max-depth still wins over the scene's own restriction
    assert make_render_plan(translated.effects, RenderOptions(max_depth=-1), translated.max_depth).max_depth == -1


def test_hide_emitters_is_not_honoured_and_says_so(tmp_path, mi):
    path = tmp_path / "t.xml"
    path.write_text(
        '<scene version="3.0.0"><integrator type="moment"><integrator type="path">'
        '<boolean name="hide_emitters" value="true"/></integrator></integrator>'
        f'<sensor type="perspective">{FILM}</sensor><emitter type="constant"/><shape type="sphere"/></scene>'
    )
    translated, _ = load_mitsuba_xml(path, frames=1)
    assert len(translated.warnings) == 1 and "hide_emitters is not honoured" in translated.warnings[0]


def test_another_integrator_gets_one_warning(tmp_path, mi):
    path = tmp_path / "t.xml"
    path.write_text(
        f'<scene version="3.0.0"><integrator type="depth"/><sensor type="perspective">{FILM}</sensor>'
        '<emitter type="constant"/><shape type="sphere"/></scene>'
    )
    translated, _ = load_mitsuba_xml(path, frames=1)
    assert translated.max_depth is None and len(translated.warnings) == 1 and "'depth'" in translated.warnings[0]


def test_a_direct_scene_renders_what_mitsubas_direct_integrator_renders(tmp_path, mi):
    path = write_shipped(tmp_path)
    translated, scene = load_mitsuba_xml(path, frames=1, defines={"fov": "45"})
    assert translated.max_depth == 2
    theirs = _mitsuba(mi, scene)  # the scene's own integrator: moment(direct)
    mean, block = _agree(_ours(translated, scene, 1024), theirs)
    assert mean < 0.02 and block < 0.08, (mean, block)
    # control: full transport (what was rendered before the direct integrator was honoured) is told apart
    mean, block = _agree(_ours(translated, scene, 256, max_depth=-1), theirs)
    assert mean > 0.02 and block > 0.08, (mean, block)


# ------------------------------------------------------------------------ orthographic

ORTHO = f"""<scene version="3.0.0">
  <sensor type="orthographic">
    <float name="near_clip" value="0.5"/><float name="far_clip" value="100"/>
    <transform name="to_world"><scale x="1.5" y="1.5"/><lookat origin="-4, 2, 3" target="0, 0.3, 0" up="0, 1, 0"/>
    </transform>
    {FILM}
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="0.6"/></emitter>
  <emitter type="point"><point name="position" x="1" y="4" z="1"/><rgb name="intensity" value="15"/></emitter>
  <bsdf type="diffuse" id="checks"><texture name="reflectance" type="checkerboard">
    <transform name="to_uv"><scale x="4" y="4"/></transform></texture></bsdf>
  <shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
    <ref id="checks"/></shape>
  <shape type="sphere"><point name="center" x="0" y="0.7" z="0"/><float name="radius" value="0.7"/>
    <bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf></shape>
</scene>
"""


def test_an_orthographic_sensor_renders_what_mitsubas_path_renders(tmp_path, mi):
    path = tmp_path / "ortho.xml"
    path.write_text(ORTHO)
    translated, scene = load_mitsuba_xml(path, frames=1)
    assert translated.camera.projection == "orthographic" and translated.camera.prim_path == "sensor:orthographic"
    theirs = _mitsuba(mi, scene, mi.load_dict({"type": "path"}))
    mean, block = _agree(_ours(translated, scene, 1024), theirs)
    assert mean < 0.02 and block < 0.08, (mean, block)
    # control: the same pose as a perspective camera is another view
    perspective = CameraTrack(poses=translated.camera.poses, fov_x_deg=60.0, near_clip=0.5, far_clip=100.0)
    translated.camera = perspective
    mean, block = _agree(_ours(translated, scene, 256), theirs)
    assert block > 0.08, (mean, block)


def test_orthographic_features_and_motion_vectors(tmp_path, mi):
    path = tmp_path / "ortho.xml"
    path.write_text(ORTHO)
    translated, scene = load_mitsuba_xml(path, frames=2)
    camera = translated.camera
    # the second frame moves the camera 0.3 units along its own image x axis (+X points left in Mitsuba's frame)
    step = camera.mitsuba_to_world(0)[:3, 0] / np.linalg.norm(camera.mitsuba_to_world(0)[:3, 0]) * 0.3
    poses = camera.poses.copy()
    poses[1, :3, 3] += step
    camera.poses = poses
    plan = make_render_plan(translated.effects, RenderOptions(), translated.max_depth)
    _collect_garbage()
    out = render_frame(scene, camera, 1, plan, width=SIZE, height=SIZE, spp=1, seed=1, _jitter=False)
    buffers = out.buffers
    assert all(np.isfinite(buffers[name]).all() for name in ("color", "normal", "depth", "position", "motion"))
    hit = buffers["depth"][..., 0] > 0
    assert hit.mean() > 0.5
    # the view is 2 * 1.5 = 3 units wide over 16 px: the camera's 0.3-unit step is 1.6 px, and every surface
    # point stood 1.6 px further left in the previous frame's image (motion = previous - current position)
    motion = buffers["motion"][hit]
    np.testing.assert_allclose(motion[:, 0], -0.3 / 3.0 * SIZE, atol=1e-3)
    np.testing.assert_allclose(motion[:, 1], 0.0, atol=1e-3)
    # orthographic depth: distance from the camera plane along the forward axis
    forward = camera.mitsuba_to_world(1)[:3, 2]
    origin = camera.mitsuba_to_world(1)[:3, 3]
    expected = (buffers["position"][hit] - origin) @ (forward / np.linalg.norm(forward))
    np.testing.assert_allclose(buffers["depth"][hit][:, 0], expected, rtol=1e-3, atol=1e-3)


# ------------------------------------------------------------------------ the command line


def test_generate_records_defines_transport_and_a_portable_config(tmp_path, mi):
    from denoisebench.dataset import open_dataset

    def generate(root: Path, out: Path, *extra: str) -> int:
        source = write_shipped(root)
        args = ["generate", "--out", str(out), "--mitsuba", str(source), "--frames", "1"]
        args += ["--width", "8", "--height", "8", "--spp", "1", "--ref-spp", "4", "--ref-error", "0", "--quiet"]
        return main([*args, *extra])

    assert generate(tmp_path / "a", tmp_path / "ds_a", "--define", "fov=45") == 0
    ds = open_dataset(tmp_path / "ds_a")
    config = json.loads((tmp_path / "ds_a" / "dataset.json").read_text())["config"]
    assert config["xml"][0]["path"] == "xml_shipped/scene.xml" and config["defines"] == {"fov": "45"}
    info = ds.scene("xml_shipped")
    assert info.record["stage_files"] == ["scene.xml", "camera.json", "files/tri.obj", "meshes/floor.obj"]
    assert info.record["plan"]["max_depth"] == 2 and info.record["plan"]["max_depth_source"] == "stage"
    assert "max_depth 2" in info.record["transport"] and "'direct' in 'moment'" in info.record["transport"]
    assert ds.frame("xml_shipped", 1, 0).reference.mean() > 0
    # the same files elsewhere make the same config (and so the same hash)
    assert generate(tmp_path / "b" / "c", tmp_path / "ds_b", "-D", "fov=45") == 0
    other = json.loads((tmp_path / "ds_b" / "dataset.json").read_text())
    assert (
        other["config"] == config
        and other["config_hash"] == json.loads((tmp_path / "ds_a" / "dataset.json").read_text())["config_hash"]
    )


def test_the_commands_refuse_a_missing_define_in_one_line(tmp_path, mi, capsys):
    source = write_shipped(tmp_path)
    out = tmp_path / "ds"
    assert main(["generate", "--out", str(out), "--mitsuba", str(source), "--frames", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "undefined parameter $fov" in err and "--define fov=VALUE" in err and "\n" not in err
    assert not out.exists()
    assert main(["scenes", "check", str(source)]) == 2
    assert "--define fov=VALUE" in capsys.readouterr().err
    assert main(["scenes", "check", str(source), "--define", "fov=45", "-D", "integrator=path"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["render_plan"]["max_depth"] == -1  # integrator=path: full transport
    assert report["transport"].startswith("full transport")
    assert main(["scenes", "check", str(source), "--define", "fov=45"]) == 0
    transport = json.loads(capsys.readouterr().out)["transport"]
    assert "max_depth 2" in transport and "'direct' in 'moment'" in transport
    preview = tmp_path / "p.png"
    args = ["scenes", "preview", str(source), "-D", "fov=45", "--out", str(preview), "--width", "8", "--height", "8"]
    assert main([*args, "--spp", "2"]) == 0 and preview.is_file()
    capsys.readouterr()
    usd = tmp_path / "x.usda"
    usd.write_text("#usda 1.0\n")
    assert main(["scenes", "check", str(usd), "-D", "a=1"]) == 2
    assert "--define and --mitsuba-path apply to Mitsuba XML scenes" in capsys.readouterr().err


# ------------------------------------------------------------ Mitsuba's own test scenes

MITSUBA_DATA = os.environ.get("MITSUBA_DATA")
needs_data = pytest.mark.skipif(not MITSUBA_DATA, reason="set MITSUBA_DATA to a fetched mitsuba-data checkout")


def mitsuba_z_test(mi, path: Path, max_depth=None, budget=2e6):
    """Fraction of pixels (XYZ channels averaged) that pass Mitsuba's z-test for our reference of the
    shipped scene ``path`` against its shipped RGB reference (test_renders.py's criterion: >= 0.9975)."""
    from scipy.stats import norm

    stem = path.stem.rsplit("_", 1)[0]
    refs = path.parent / "refs"
    translated, scene = load_mitsuba_xml(path, frames=1)
    width, height = (int(v) for v in scene.sensors()[0].film().size())
    spp = int(budget // (width * height))
    plan = make_render_plan(translated.effects, RenderOptions(max_depth=max_depth), translated.max_depth)
    _collect_garbage()
    out = render_frame(scene, translated.camera, 0, plan, width=width, height=height, spp=spp, seed=0, reference=True)

    def xyz(bitmap):
        return np.array(bitmap.convert(mi.Bitmap.PixelFormat.XYZ, mi.Struct.Type.Float32, False), dtype=np.float64)

    ours = xyz(mi.Bitmap(np.ascontiguousarray(out.buffers["color"][..., :3], dtype=np.float32)))
    reference = xyz(mi.Bitmap(str(refs / f"{stem}_ref_rgb.exr")))
    variance = xyz(mi.Bitmap(str(refs / f"{stem}_ref_rgb_var.exr")))
    z = np.abs(ours - reference) * np.sqrt(spp / np.maximum(variance, 1e-4))
    p_value = 2.0 * (1.0 - norm.cdf(z))
    alpha = 1.0 - (1.0 - 0.01) ** (1.0 / (width * height))
    return np.count_nonzero(p_value > alpha) / 3 / (width * height)


@needs_data
@pytest.mark.parametrize(
    "scene",
    [
        "floating_sphere/test_directional_direct.xml",
        "orthographic_sensor/test_orthographic_path.xml",
        "spot_light/test_spot_direct.xml",
        "bsdf_spheres/test_textured_diffuse_path.xml",
    ],
)
def test_mitsubas_render_test_scenes_pass_its_z_test_as_shipped(mi, scene):
    path = Path(MITSUBA_DATA) / "tests" / "scenes" / scene
    assert mitsuba_z_test(mi, path) >= 0.9975


@needs_data
def test_the_z_test_rejects_full_transport_for_the_direct_scene(mi):
    path = Path(MITSUBA_DATA) / "tests" / "scenes" / "floating_sphere" / "test_directional_direct.xml"
    assert mitsuba_z_test(mi, path, max_depth=-1) < 0.9975


@needs_data
@pytest.mark.parametrize(
    "name, depth, search",
    [
        ("bsdf_diffuse_plain.xml", None, False),
        ("sensor_thinlens.xml", None, False),
        ("integrator_direct_both.xml", 2, False),
        ("sensor_orthographic.xml", None, True),  # written for Mitsuba's -a: --mitsuba-path common
    ],
)
def test_documentation_scenes_load_as_shipped(mi, name, depth, search):
    # <path value="../../common"/>, includes from include/, $spp without a <default> (sensor_thinlens)
    data = Path(MITSUBA_DATA)
    search_paths = [data / "common"] if search else []
    translated, scene = load_mitsuba_xml(data / "docs" / "scenes" / name, frames=1, search_paths=search_paths)
    assert scene.shapes() and translated.camera.frames == 1 and translated.max_depth == depth


@pytest.mark.parametrize("legacy_key", [False, True])
def test_a_dataset_that_recorded_absolute_paths_resumes_without_rendering(tmp_path, mi, capsys, legacy_key):
    import hashlib

    from denoisebench.dataset.manifest import config_hash
    from denoisebench.generator.dataset_run import legacy_config

    # a scene of the kind older datasets held: no <path>, no parameters, files in its folder
    source = tmp_path / "src" / "plain.xml"
    (source.parent / "meshes").mkdir(parents=True)
    (source.parent / "meshes" / "t.obj").write_text(TRIANGLE)
    source.write_text(
        f"""<scene version="3.0.0"><sensor type="perspective">{FILM}</sensor><emitter type="constant"/>
  <shape type="obj"><string name="filename" value="meshes/t.obj"/></shape><shape type="sphere"/></scene>
"""
    )
    out = tmp_path / "ds"
    args = ["generate", "--out", str(out), "--mitsuba", str(source), "--frames", "1", "--width", "8", "--height", "8"]
    args += ["--spp", "1", "--ref-spp", "4", "--ref-error", "0", "--quiet"] + (["--auto-camera"] if legacy_key else [])
    assert main(args) == 0
    # rewrite the manifest as older code wrote it: the file's absolute path (and, before
    # the stage_options rename, usd_options), hashed over that
    path = out / "dataset.json"
    manifest = json.loads(path.read_text())
    config = dict(manifest["config"])
    config["xml"] = [{"path": str(source.resolve()), "sha256": hashlib.sha256(source.read_bytes()).hexdigest()}]
    config = legacy_config(config) if legacy_key else config
    manifest["config"], manifest["config_hash"] = config, config_hash(config)
    path.write_text(json.dumps(manifest, indent=1))
    stamps = {p: p.stat().st_mtime_ns for p in sorted(out.rglob("*.exr"))}
    capsys.readouterr()
    assert main(args) == 0  # resumed, not refused as another config
    assert "0 frame(s) rendered" in capsys.readouterr().out
    assert json.loads(path.read_text())["config_hash"] == config_hash(config)  # its own hash, kept
    assert {p: p.stat().st_mtime_ns for p in sorted(out.rglob("*.exr"))} == stamps


def test_an_orthographic_dataset_records_its_projection_and_noisebase_refuses_it(tmp_path, mi, capsys):
    pytest.importorskip("noisebase")
    source = tmp_path / "ortho.xml"
    source.write_text(ORTHO)
    out = tmp_path / "ds"
    args = ["generate", "--out", str(out), "--mitsuba", str(source), "--frames", "2", "--width", "8", "--height", "8"]
    assert main([*args, "--spp", "2", "--ref-spp", "4", "--ref-error", "0", "--samples", "--quiet"]) == 0
    manifest = json.loads((out / "dataset.json").read_text())
    assert manifest["scenes"]["xml_ortho"]["camera"]["projection"] == "orthographic"
    capsys.readouterr()
    never = tmp_path / "nb"
    assert main(["export", str(out), str(never), "--format", "noisebase", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "orthographic camera" in err and "\n" not in err and not never.exists()


def test_mitsuba_path_is_searched_after_the_scenes_folder_and_not_recorded(tmp_path, mi):
    from denoisebench.generator.mitsuba_xml_structure import read_structure as structure_of

    # a scene written for Mitsuba's -a (as Mitsuba's sensor_orthographic.xml): names a mesh in no folder of its own
    (tmp_path / "lib" / "meshes").mkdir(parents=True)
    (tmp_path / "lib" / "meshes" / "t.obj").write_text(TRIANGLE)
    (tmp_path / "scene").mkdir()
    source = tmp_path / "scene" / "a.xml"
    source.write_text(
        f"""<scene version="3.0.0"><sensor type="perspective">{FILM}</sensor><emitter type="constant"/>
  <shape type="obj"><string name="filename" value="meshes/t.obj"/></shape></scene>
"""
    )
    with pytest.raises(UserInputError, match="names 'meshes/t.obj', which does not exist"):
        structure_of(source)
    with pytest.raises(UserInputError, match="--mitsuba-path .*nowhere: no such folder"):
        structure_of(source, search_paths=[tmp_path / "nowhere"])
    found = structure_of(source, search_paths=[tmp_path / "lib"])
    assert found.resolved["meshes/t.obj"] == (tmp_path / "lib" / "meshes" / "t.obj").resolve()
    # the scene's own folder comes first, as with Mitsuba's -a
    (tmp_path / "scene" / "meshes").mkdir()
    (tmp_path / "scene" / "meshes" / "t.obj").write_text(TRIANGLE)
    found = structure_of(source, search_paths=[tmp_path / "lib"])
    assert found.resolved["meshes/t.obj"] == (tmp_path / "scene" / "meshes" / "t.obj").resolve()
    (tmp_path / "scene" / "meshes" / "t.obj").unlink()
    out = tmp_path / "ds"
    args = ["generate", "--out", str(out), "--mitsuba", str(source), "--frames", "1", "--width", "8", "--height", "8"]
    args += ["--spp", "1", "--ref-spp", "4", "--ref-error", "0", "--quiet", "--mitsuba-path", str(tmp_path / "lib")]
    assert main(args) == 0
    manifest = json.loads((out / "dataset.json").read_text())
    assert str(tmp_path) not in json.dumps(manifest["config"])
    assert (out / "xml_a" / "meshes" / "t.obj").read_text() == TRIANGLE
    assert main(["scenes", "check", str(source), "--mitsuba-path", str(tmp_path / "lib")]) == 0


def test_help_says_which_parameters_need_no_define(capsys):
    import argparse

    from denoisebench.commands import generate

    parser = argparse.ArgumentParser(epilog=generate.EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    generate.add_arguments(parser)
    parser.print_help()
    text = " ".join(capsys.readouterr().out.split())
    assert "--define NAME=VALUE, -D NAME=VALUE" in text and "--mitsuba-path DIR" in text
    assert "$spp and the film size ($res, $resx, $resy) need none" in text
    assert "--define integrator=path" in text
    args = parser.parse_args(["--out", "o", "--mitsuba", "a.xml", "-D", "a=1", "--define", "b=2"])
    assert generate.request_from_args(args).defines == (("a", "1"), ("b", "2"))


@pytest.mark.parametrize(
    "tamper, message",
    [
        ('<path value="/tmp"/>', "has a <path> directive"),
        ('<include filename="../../outside.xml"/>', "outside the dataset's scene folder"),
        (
            '<shape type="obj"><string name="filename" value="../../outside.obj"/></shape>',
            "outside the dataset's scene",
        ),
    ],
)
def test_a_datasets_copy_is_confined_to_its_folder(tmp_path, mi, tamper, message):
    from denoisebench.generator.dataset_scenes import load_scene_file

    (tmp_path / "outside.obj").write_text(TRIANGLE)
    (tmp_path / "outside.xml").write_text('<scene version="3.0.0"><shape type="sphere"/></scene>\n')
    folder = tmp_path / "ds" / "xml_x"
    folder.mkdir(parents=True)
    body = f'<sensor type="perspective">{FILM}</sensor><emitter type="constant"/><shape type="sphere"/>'
    (folder / XML_NAME).write_text(f'<scene version="3.0.0">{body}</scene>\n')
    assert load_scene_file(folder / XML_NAME)[0].camera.frames == 1  # untampered: loads
    (folder / XML_NAME).write_text(f'<scene version="3.0.0">{tamper}{body}</scene>\n')
    with pytest.raises(UserInputError, match=message) as caught:
        load_scene_file(folder / XML_NAME)
    assert "\n" not in str(caught.value)
    if ".obj" in tamper:  # the user's own scene on the command line may name files anywhere
        assert load_mitsuba_xml(folder / XML_NAME, frames=1)[0].camera.frames == 1
