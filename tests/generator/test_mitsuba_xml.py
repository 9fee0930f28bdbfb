"""Mitsuba XML scene files as a scene source (``generate-dataset --mitsuba``, alias ``--xml``).

Peer: Mitsuba itself. The reference our feature renderer makes of a hand-written Cornell-like XML
file is held against Mitsuba's ``path`` integrator at its defaults rendering the same file through
the file's own sensor (so the camera conversion is checked too): image mean within 2 % and every
12×12 block within 8 % (the field-tools criterion), with a control that the criterion rejects direct
light only. Effects and the camera are read off the loaded plugins; bad files are one-line refusals.
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.mitsuba_xml import load_mitsuba_xml
from denoisebench.generator.mitsuba_xml_structure import XML_NAME, read_structure
from denoisebench.generator.render.frame import render_frame

SIZE = 24
FILM = f"""<film type="hdrfilm"><integer name="width" value="{SIZE}"/><integer name="height" value="{SIZE}"/>
      <rfilter type="box"/></film>"""

CORNELL = f"""<scene version="3.0.0">
  <default name="depth" value="-1"/>
  <integrator type="path"><integer name="max_depth" value="$depth"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="42"/>
    <transform name="to_world"><lookat origin="0.1, 1, 3.6" target="0, 0.95, 0" up="0, 1, 0"/></transform>
    {FILM}
  </sensor>
  <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.75, 0.75, 0.75"/></bsdf>
  <bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.7, 0.1, 0.1"/></bsdf>
  <bsdf type="diffuse" id="green"><rgb name="reflectance" value="0.1, 0.7, 0.1"/></bsdf>
  <bsdf type="roughconductor" id="metal"><float name="alpha" value="0.25"/></bsdf>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/></transform><ref id="white"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/><translate y="2"/></transform>
    <ref id="white"/></shape>
  <shape type="rectangle"><transform name="to_world"><translate y="1" z="-1"/></transform><ref id="white"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate y="1" angle="90"/><translate x="-1" y="1"/></transform>
    <ref id="red"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate y="1" angle="-90"/><translate x="1" y="1"/></transform>
    <ref id="green"/></shape>
  <shape type="obj"><string name="filename" value="meshes/block.obj"/>
    <transform name="to_world"><scale value="0.3"/><translate x="0.35" y="0.3" z="0.2"/></transform><ref id="metal"/></shape>
  <shape type="sphere"><point name="center" x="-0.4" y="0.35" z="-0.2"/><float name="radius" value="0.35"/>
    <ref id="white"/></shape>
  <shape type="rectangle">
    <transform name="to_world"><scale value="0.3"/><rotate x="1" angle="90"/><translate y="1.98"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0, 0, 0"/></bsdf>
    <emitter type="area"><rgb name="radiance" value="12, 12, 12"/></emitter>
  </shape>
</scene>
"""

# a unit cube, 8 vertices and 12 triangles (the file the XML names, relative to itself)
BLOCK_OBJ = "\n".join(
    [f"v {x} {y} {z}" for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    + [
        f"f {a} {b} {c}"
        for a, b, c in [(1, 3, 4), (1, 4, 2), (5, 6, 8), (5, 8, 7), (1, 2, 6), (1, 6, 5)]
        + [(3, 7, 8), (3, 8, 4), (1, 5, 7), (1, 7, 3), (2, 4, 8), (2, 8, 6)]
    ]
)


def write_cornell(folder):
    (folder / "meshes").mkdir(parents=True, exist_ok=True)
    (folder / "meshes" / "block.obj").write_text(BLOCK_OBJ + "\n")
    path = folder / "cornell.xml"
    path.write_text(CORNELL)
    return path


def _blocks(image, block=12):
    h, w, c = image.shape
    return image.reshape(h // block, block, w // block, block, c).mean(axis=(1, 3))


def _agree(ours, theirs):
    mean = np.abs(ours.mean(axis=(0, 1)) / theirs.mean(axis=(0, 1)) - 1).max()
    block = np.abs(_blocks(ours) / _blocks(theirs) - 1).max()
    return mean, block


def test_reference_agrees_with_mitsuba_path_through_the_files_own_sensor(tmp_path, mi):
    translated, scene = load_mitsuba_xml(write_cornell(tmp_path), frames=1)
    assert translated.max_depth is None  # max_depth -1 ($depth default): full transport
    plan = make_render_plan(translated.effects, RenderOptions(), stage_max_depth=translated.max_depth)

    def ours(plan, spp):
        out = render_frame(scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=spp, seed=7, reference=True)
        return out.buffers["color"].astype(np.float64)

    theirs = np.mean(
        [np.array(mi.render(scene, integrator=mi.load_dict({"type": "path"}), seed=100 + k, spp=64)) for k in range(8)],
        axis=0,
    )[..., :3]
    mean, block = _agree(ours(plan, 512), theirs)
    assert mean < 0.02 and block < 0.08, (mean, block)
    # control: direct light only is told apart by the same criterion
    direct = make_render_plan(translated.effects, RenderOptions(max_depth=2))
    mean, block = _agree(ours(direct, 128), theirs)
    assert mean > 0.02 and block > 0.08, (mean, block)


def test_camera_and_effects_come_from_the_plugins(tmp_path, mi):
    path = tmp_path / "lens.xml"
    path.write_text(
        f"""<scene version="3.0.0">
  <sensor type="thinlens">
    <float name="fov" value="35"/><float name="aperture_radius" value="0.05"/><float name="focus_distance" value="3"/>
    <transform name="to_world"><lookat origin="1, 2, 5" target="0, 0.5, 0" up="0, 1, 0"/></transform>
    {FILM}
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  <shape type="sphere"><bsdf type="roughdielectric"><float name="alpha" value="0.1"/></bsdf></shape>
  <shape type="sphere"><point name="center" x="2" y="0" z="0"/><bsdf type="conductor"/></shape>
  <shape type="rectangle"><bsdf type="diffuse"><texture type="checkerboard" name="reflectance"/></bsdf></shape>
</scene>
"""
    )
    translated, scene = load_mitsuba_xml(path, frames=3)
    assert set(translated.effects_inferred) == {"depth_of_field", "environment", "glossy", "specular", "transmission"}
    # a bitmap texture (a file beside the XML) is the textures effect
    mi.Bitmap(np.full((4, 4, 3), 0.5, np.float32)).write(str(tmp_path / "tex.exr"))
    textured = tmp_path / "textured.xml"
    textured.write_text(
        path.read_text().replace(
            '<texture type="checkerboard" name="reflectance"/>',
            '<texture type="bitmap" name="reflectance"><string name="filename" value="tex.exr"/></texture>',
        )
    )
    assert "textures" in load_mitsuba_xml(textured)[0].effects_inferred
    camera = translated.camera
    assert camera.frames == 3 and not camera.is_animated
    assert camera.fov_x_deg == pytest.approx(35.0, abs=1e-4)
    assert camera.aperture_radius == pytest.approx(0.05) and camera.focus_distance == pytest.approx(3.0)
    np.testing.assert_allclose(
        camera.mitsuba_to_world(1), np.array(scene.sensors()[0].world_transform().matrix).reshape(4, 4), atol=1e-6
    )
    # the USD-convention pose looks down its -Z axis, at the lookat target
    forward = -camera.poses[0][:3, 2]
    to_target = np.array([0, 0.5, 0]) - np.array([1, 2, 5])
    np.testing.assert_allclose(forward, to_target / np.linalg.norm(to_target), atol=1e-6)
    plan = make_render_plan(translated.effects, RenderOptions())
    assert plan.camera_model == "thin_lens" and "lens" in plan.random_parameters


@pytest.mark.parametrize(
    "text, message",
    [
        ("<scene version='3.0.0'><shape type='sphere'>", "not well-formed XML"),
        ("<shape type='sphere'/>", "not a Mitsuba <scene>"),
        (
            "<scene version='3.0.0'><shape type='ply'><string name='filename' value='../x.ply'/></shape></scene>",
            "names '../x.ply', which does not exist",
        ),
        ("<scene version='3.0.0'><integer name='a' value='$n'/></scene>", r"undefined parameter \$n .*--define n="),
        ("<scene version='3.0.0'><path value='nowhere'/></scene>", "Mitsuba cannot parse"),
        ("<scene version='3.0.0'><shape type='warp_drive'/></scene>", "Mitsuba cannot load"),
        (
            f"<scene version='3.0.0'><sensor type='perspective'>{FILM}</sensor><shape type='sphere'/></scene>",
            "no emitter",
        ),
        (
            "<scene version='3.0.0'><sensor type='radiancemeter'><film type='hdrfilm'><integer name='width' "
            "value='1'/><integer name='height' value='1'/></film></sensor><shape type='sphere'/>"
            "<emitter type='constant'/></scene>",
            "not supported",
        ),
    ],
)
def test_bad_files_are_one_line_refusals(tmp_path, mi, text, message):
    folder = tmp_path / "scene"
    folder.mkdir()
    path = folder / "bad.xml"
    path.write_text(text)
    with pytest.raises(UserInputError, match=message) as caught:
        load_mitsuba_xml(path)
    assert "\n" not in str(caught.value)


def test_integrator_depth_and_files_are_read_with_defaults_resolved(tmp_path):
    path = write_cornell(tmp_path)
    structure = read_structure(path)
    assert structure.integrator == "path" and structure.max_depth is None and structure.files == ["meshes/block.obj"]
    path.write_text(CORNELL.replace('value="-1"', 'value="3"'))
    assert read_structure(path).max_depth == 3
    assert XML_NAME == "scene.xml"


def test_generate_dataset_renders_an_xml_scene_and_copies_its_files(tmp_path, mi, capsys):
    from denoisebench.cli import main
    from denoisebench.dataset import open_dataset

    source = write_cornell(tmp_path / "src")
    out = tmp_path / "ds"
    args = ["generate", "--out", str(out), "--mitsuba", str(source), "--frames", "2", "--width", "16", "--height", "16"]
    args += ["--spp", "1,2", "--ref-spp", "16", "--ref-error", "0", "--quiet"]
    assert main(args) == 0
    ds = open_dataset(out)
    assert ds.scenes == ["xml_cornell"]
    info = ds.scene("xml_cornell")
    assert info.usd == "xml_cornell/scene.xml" and info.frame_count == 2
    assert info.record["stage_files"] == ["scene.xml", "camera.json", "meshes/block.obj"]
    assert (out / "xml_cornell" / "scene.xml").read_bytes() == source.read_bytes()
    assert set(info.effects["inferred"]) == {"area_lights", "glossy"}
    frame = ds.frame("xml_cornell", 2, 1)
    assert frame.reference.mean() > 0 and np.isfinite(frame.buffers["albedo"]).all()
    # samplers render the XML scene live (sampling/live.py loads scene.xml as frame_jobs does): uniform
    # sampling at the scene's render seed gives the stored 2-spp input's bytes
    from denoisebench.sampling.harness import run_sampler
    from denoisebench.sampling.live import LiveScene
    from denoisebench.sampling.protocol import Budget
    from denoisebench.sampling.registry import load_sampler

    live = LiveScene.from_dataset(ds, "xml_cornell")
    assert live.frames == 2
    again = run_sampler(load_sampler("uniform"), live.open(1, seed=info.record["render_seed"]), Budget(spp=2))
    np.testing.assert_array_equal(again.buffers["color"], frame.buffers["color"])
    capsys.readouterr()
    assert main(args) == 0  # resumes: everything is there already
    captured = capsys.readouterr()
    assert "1 scene(s), 0 frame(s) rendered" in captured.out + captured.err


def test_generate_refuses_a_malformed_xml_in_one_line_and_writes_nothing(tmp_path, capsys):
    from denoisebench.cli import main

    bad = tmp_path / "bad.xml"
    bad.write_text("<scene version='3.0.0'><shape type='sphere'>")
    out = tmp_path / "ds"
    assert main(["generate", "--out", str(out), "--xml", str(bad), "--frames", "1", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert "not well-formed XML" in err and "\n" not in err
    assert not out.exists()


def test_included_fragments_are_read_and_are_dependencies(tmp_path, mi):
    from denoisebench.generator.mitsuba_xml_structure import dependencies

    write_cornell(tmp_path)
    body = CORNELL.split("\n", 1)[1].rsplit("</scene>", 1)[0].replace('value="$depth"', 'value="4"')
    body = body.replace('<default name="depth" value="-1"/>', "")
    (tmp_path / "fragments").mkdir()
    (tmp_path / "fragments" / "all.xml").write_text(f'<scene version="3.0.0">{body}</scene>\n')
    main = tmp_path / "main.xml"
    main.write_text('<scene version="3.0.0"><include filename="fragments/all.xml"/></scene>\n')
    structure = read_structure(main)
    assert structure.integrator == "path" and structure.max_depth == 4
    assert [relative for _, relative in dependencies(main)] == ["fragments/all.xml", "meshes/block.obj"]
    translated, scene = load_mitsuba_xml(main)
    assert translated.max_depth == 4 and len(scene.emitters()) == 1


def test_mitsuba_is_the_documented_option_and_xml_its_alias(capsys):
    import argparse

    from denoisebench.commands import generate

    parser = argparse.ArgumentParser()
    generate.add_arguments(parser)
    assert parser.parse_args(["--out", "o", "--mitsuba", "a.xml", "--xml", "b.xml"]).xml == ["a.xml", "b.xml"]
    parser.print_help()
    assert "--mitsuba FILE, --xml FILE" in capsys.readouterr().out
    assert "--mitsuba staircase/scene_v3.xml" in generate.EPILOG
