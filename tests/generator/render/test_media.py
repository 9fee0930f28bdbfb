"""Participating media in the feature renderer (render/volpath.py), against Mitsuba's ``volpath``.

Peers: Mitsuba's ``volpath`` (``volpathmis`` where the extinction is chromatic: Mitsuba 3.9's
``volpath`` then disagrees with its own shipped references, ``volpathmis`` and us) at its defaults
(unbounded depth, Russian roulette from depth 5). Scenes are small dicts built here (16 px, a few
seconds each): homogeneous fog behind a null boundary, a heterogeneous grid with a Henyey-Greenstein
phase, a subsurface sphere (dielectric boundary), a camera inside fog, an emitter inside a medium.
Statistics: block means (4×4 px) and the image mean, z-scores of ours minus Mitsuba's independent
replicas. Pruning: a scene without media never imports the volumetric tracer.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.mitsuba_xml import camera_track, load_mitsuba_xml
from denoisebench.generator.render.frame import FrameStream, render_frame
from denoisebench.generator.render.media import scene_has_media
from denoisebench.scenes.effects import EFFECTS

SIZE = 16
BLOCK = 4
SPP = 256
REPLICAS = 8


def _scene_dict(mi, **extra) -> dict:
    T = mi.ScalarTransform4f
    out = {
        "type": "scene",
        "sensor": {
            "type": "perspective",
            "fov": 45,
            "to_world": T().look_at(origin=[0, 0.3, 4], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {
                "type": "hdrfilm",
                "width": SIZE,
                "height": SIZE,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
        },
        "back": {
            "type": "rectangle",
            "to_world": T().translate([0, 0, -1.6]).scale(3.0),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.6, 0.5, 0.4]}},
        },
        "light": {
            "type": "rectangle",
            "to_world": T().look_at(origin=[1.6, 2.4, 1.2], target=[0, 0, 0], up=[0, 1, 0]).scale(0.6),
            "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [9.0, 8.0, 7.0]}},
        },
    }
    out.update(extra)
    return out


def _fog(sigma_t, albedo, g=None, scale=1.0) -> dict:
    peak = max(sigma_t)  # Mitsuba's rgb values lie in [0, 1]: the magnitude goes to the scale
    medium = {
        "type": "homogeneous",
        "sigma_t": {"type": "rgb", "value": [v / peak for v in sigma_t]},
        "albedo": {"type": "rgb", "value": list(albedo)},
        "scale": scale * peak,
    }
    if g is not None:
        medium["phase"] = {"type": "hg", "g": g}
    return medium


def _grid(mi) -> dict:
    z, y, x = np.meshgrid(*(np.linspace(-1, 1, 10),) * 3, indexing="ij")
    density = np.clip(1.0 - np.sqrt(x**2 + (y * 1.5) ** 2 + z**2), 0.0, None) ** 0.7
    density *= 1.0 + 0.5 * np.sin(5 * x) * np.cos(4 * z)
    T = mi.ScalarTransform4f
    return {
        "type": "heterogeneous",
        "sigma_t": {
            "type": "gridvolume",
            "data": mi.TensorXf(density[..., None].astype(np.float32)),
            "to_world": T().translate([-1, -1, -1]).scale(2.0),
        },
        "albedo": {"type": "rgb", "value": [0.9, 0.8, 0.7]},
        "scale": 6.0,
        "phase": {"type": "hg", "g": 0.5},
    }


def _scenes(mi):
    T = mi.ScalarTransform4f
    null = {"type": "null"}
    return {
        "homogeneous_fog": (
            _scene_dict(
                mi, fog={"type": "sphere", "radius": 1.0, "bsdf": null, "interior": _fog([1.5] * 3, [0.8, 0.7, 0.6])}
            ),
            "volpath",
        ),
        "chromatic_fog": (
            _scene_dict(
                mi, fog={"type": "sphere", "radius": 1.0, "bsdf": null, "interior": _fog([2.5, 1.0, 0.4], [0.8] * 3)}
            ),
            "volpathmis",
        ),
        "heterogeneous_grid": (
            _scene_dict(mi, smoke={"type": "cube", "bsdf": null, "interior": _grid(mi)}),
            "volpath",
        ),
        "subsurface_sphere": (
            _scene_dict(
                mi,
                # a dielectric boundary blocks next-event estimation from inside: light enters by
                # refraction, so an environment (not a small lamp, whose caustics are heavy-tailed)
                light={"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 0.9, 0.8]}},
                jelly={
                    "type": "sphere",
                    "radius": 0.9,
                    "bsdf": {"type": "dielectric", "int_ior": 1.4},
                    "interior": _fog([3.0] * 3, [0.95, 0.8, 0.6], g=0.3),
                },
            ),
            "volpath",
        ),
        "camera_in_fog": (
            {
                **_scene_dict(
                    mi,
                    world={
                        "type": "sphere",
                        "radius": 8.0,
                        "bsdf": null,
                        "interior": {"type": "ref", "id": "air"},
                    },
                    ball={"type": "sphere", "radius": 0.6, "bsdf": {"type": "diffuse"}},
                ),
                "air": {**_fog([0.25] * 3, [0.7] * 3), "id": "air"},
            },
            "volpath",
        ),
        "emitter_in_medium": (
            _scene_dict(
                mi,
                fog={"type": "sphere", "radius": 1.0, "bsdf": null, "interior": _fog([1.2] * 3, [0.9] * 3, g=-0.3)},
                lamp={
                    "type": "sphere",
                    "radius": 0.2,
                    "to_world": T().translate([0.2, 0.1, 0.0]),
                    "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6.0, 5.0, 3.0]}},
                },
            ),
            "volpath",
        ),
    }


def _load(mi, name: str):
    scene_dict, integrator = _scenes(mi)[name]
    if name == "camera_in_fog":
        scene_dict["sensor"]["medium"] = {"type": "ref", "id": "air"}
    return mi.load_dict(scene_dict), integrator


def _ours(mi, scene, spp=SPP, seed=7, reference=True, per_sample=False):
    camera = camera_track(mi, scene.sensors()[0], 2, Path("test.xml"))
    plan = make_render_plan(("media",), RenderOptions(per_sample=per_sample))
    return render_frame(scene, camera, 1, plan, width=SIZE, height=SIZE, spp=spp, seed=seed, reference=reference)


def _blocks(image):
    *lead, h, w, c = image.shape
    return image.reshape(*lead, h // BLOCK, BLOCK, w // BLOCK, BLOCK, c).mean(axis=(-4, -2))


def _z_scores(ours_mean, ours_var, replicas):
    n = BLOCK * BLOCK
    ours_blocks = _blocks(ours_mean.astype(np.float64))
    ours_block_var = _blocks(ours_var.astype(np.float64)) / n
    rep_blocks = _blocks(replicas)
    theirs = rep_blocks.mean(axis=0)
    theirs_var = rep_blocks.var(axis=0, ddof=1) / len(replicas)
    # float32 rounding of noise-free pixels (a constant sky): a relative floor of 1e-5
    floor = np.square(1e-5 * np.abs(theirs)) + 1e-20
    z_blocks = (ours_blocks - theirs) / np.sqrt(ours_block_var + theirs_var + floor)
    ours_image = ours_mean.mean(axis=(0, 1), dtype=np.float64)
    ours_image_var = ours_var.astype(np.float64).sum(axis=(0, 1)) / (SIZE * SIZE) ** 2
    rep_image = replicas.mean(axis=(1, 2))
    z_image = (ours_image - rep_image.mean(0)) / np.sqrt(ours_image_var + rep_image.var(0, ddof=1) / len(replicas))
    return z_blocks, z_image


@pytest.mark.parametrize(
    "name",
    [
        "homogeneous_fog",
        "chromatic_fog",
        "heterogeneous_grid",
        "subsurface_sphere",
        "camera_in_fog",
        "emitter_in_medium",
    ],
)
def test_media_reference_agrees_with_mitsuba_volpath(mi, name):
    scene, integrator_type = _load(mi, name)
    assert scene_has_media(scene)
    ours = _ours(mi, scene)
    integrator = mi.load_dict({"type": integrator_type})  # its defaults: unbounded, roulette from depth 5
    replicas = np.stack(
        [
            np.array(mi.render(scene, integrator=integrator, seed=500 + k, spp=SPP // REPLICAS))[..., :3]
            for k in range(REPLICAS)
        ]
    ).astype(np.float64)
    color, var = ours.buffers["color"], ours.buffers["color_var"]
    assert np.isfinite(color).all() and np.isfinite(var).all()
    z_blocks, z_image = _z_scores(color, var, replicas)
    # 48 block z-scores: all within 4.5 (a Bonferroni-style bound); the image mean within 4
    assert np.abs(z_blocks).max() < 4.5, (name, np.abs(z_blocks).max(), color.mean((0, 1)), replicas.mean((0, 1, 2)))
    assert np.abs(z_image).max() < 4.0, (name, z_image, color.mean((0, 1)), replicas.mean((0, 1, 2)))


def test_media_frames_have_every_feature_and_the_medium_albedo(mi):
    """Dense grey fog in front of the camera: the first event is a scattering, whose albedo is the medium's."""
    T = mi.ScalarTransform4f
    fog = _fog([40.0] * 3, [0.6, 0.5, 0.4])
    scene = mi.load_dict(
        _scene_dict(
            mi,
            fog={"type": "sphere", "radius": 1.0, "bsdf": {"type": "null"}, "interior": fog},
            glass={
                "type": "sphere",
                "radius": 0.3,
                "to_world": T().translate([2.2, 0, 0]),
                "bsdf": {"type": "dielectric"},
            },
        )
    )
    frame = _ours(mi, scene, spp=8, reference=False, per_sample=True)
    b = frame.buffers
    for name, value in b.items():
        assert np.isfinite(value).all(), name
    np.testing.assert_allclose(b["diffuse"] + b["specular"], b["color"], atol=1e-5)
    centre = b["albedo"][SIZE // 2 - 1 : SIZE // 2 + 1, SIZE // 2 - 1 : SIZE // 2 + 1]
    np.testing.assert_allclose(centre.reshape(-1, 3).mean(0), [0.6, 0.5, 0.4], atol=1e-4)
    assert np.abs(b["normal"][SIZE // 2, SIZE // 2]).max() < 1e-6  # a scattering has no normal
    assert b["roughness"][SIZE // 2, SIZE // 2, 0] == pytest.approx(1.0)
    # the scattering points lie inside the fog sphere, near its front
    p = b["position"][SIZE // 2, SIZE // 2]
    assert np.linalg.norm(p) < 1.0 and p[2] > 0.8
    assert 2.9 < b["depth"][SIZE // 2, SIZE // 2, 0] < 3.3
    assert frame.samples is not None
    for name in ("light", "bounce", "position2", "normal2", "pixel", "medium"):
        assert name in frame.samples and np.isfinite(frame.samples[name]).all(), name
    # every camera ray at the centre flies into the fog first: its free flight's number is drawn
    centre_u = frame.samples["medium"][:, SIZE // 2, SIZE // 2, 0]
    assert np.all((centre_u > 0) & (centre_u < 1)) and np.unique(centre_u).size == centre_u.size


def test_media_renders_are_deterministic_and_nested(mi):
    scene, _ = _load(mi, "heterogeneous_grid")
    camera = camera_track(mi, scene.sensors()[0], 1, Path("test.xml"))
    plan = make_render_plan(("media",))
    full = render_frame(scene, camera, 0, plan, width=SIZE, height=SIZE, spp=4, seed=3)
    again = render_frame(scene, camera, 0, plan, width=SIZE, height=SIZE, spp=4, seed=3)
    for name in full.buffers:
        np.testing.assert_array_equal(full.buffers[name], again.buffers[name])
    stream = FrameStream(scene, camera, 0, plan, width=SIZE, height=SIZE, seed=3)
    stream.advance(1)
    stream.advance(3)
    np.testing.assert_array_equal(stream.buffers()["color"], full.buffers["color"])


def test_media_is_an_effect_that_adds_only_its_random_parameter():
    """``media`` is in the vocabulary; the plan records it and the ``medium`` random parameter; the scene
    itself decides the tracer."""
    assert "media" in EFFECTS
    with_media, without = make_render_plan(("media", "glossy")), make_render_plan(("glossy",))
    assert with_media.effects == ("glossy", "media")
    assert with_media.features == without.features and with_media.max_depth == without.max_depth
    assert with_media.random_parameters == ("pixel", "medium", "light", "bounce")
    assert without.random_parameters == ("pixel", "light", "bounce")


def test_scene_without_media_never_enters_the_medium_code(mi, monkeypatch):
    """A media-free scene renders with the volumetric tracer unimportable, and its kernel options say so."""
    scene_dict = _scene_dict(mi, ball={"type": "sphere", "radius": 0.7, "bsdf": {"type": "roughplastic"}})
    scene = mi.load_dict(scene_dict)
    assert not scene_has_media(scene)
    camera = camera_track(mi, scene.sensors()[0], 2, Path("test.xml"))
    plan = make_render_plan(("glossy",))
    expected = render_frame(scene, camera, 1, plan, width=SIZE, height=SIZE, spp=4, seed=11)
    monkeypatch.setitem(sys.modules, "denoisebench.generator.render.volpath", None)  # importing it now fails
    stream = FrameStream(scene, camera, 1, plan, width=SIZE, height=SIZE, seed=11)
    assert not stream._opts.media
    stream.advance(4)
    for name, value in expected.buffers.items():
        np.testing.assert_array_equal(stream.buffers()[name], value)


def test_mitsuba_xml_with_a_medium_loads_and_infers_media(mi, tmp_path):
    xml = tmp_path / "fog.xml"
    xml.write_text(
        """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <ref id="air" name="medium"/>
  </sensor>
  <medium type="homogeneous" id="air"><rgb name="sigma_t" value="0.2"/><rgb name="albedo" value="0.8"/>
    <phase type="hg"><float name="g" value="0.4"/></phase></medium>
  <shape type="sphere"><float name="radius" value="10"/><bsdf type="null"/><ref id="air" name="interior"/></shape>
  <shape type="sphere"><float name="radius" value="0.5"/></shape>
  <emitter type="point"><point name="position" x="1" y="2" z="1"/><rgb name="intensity" value="10"/></emitter>
</scene>
"""
    )
    translated, scene = load_mitsuba_xml(xml, frames=1)
    assert "media" in translated.effects_inferred
    camera = translated.camera
    plan = make_render_plan(translated.effects_inferred)
    frame = render_frame(scene, camera, 0, plan, width=8, height=8, spp=4, seed=1)
    assert np.isfinite(frame.buffers["color"]).all() and frame.buffers["color"].mean() > 0


# --------------------------------------------------------------------------- USD stages with media


def test_fog_smoke_family_reference_agrees_with_mitsuba_volpath(mi, tmp_path):
    """The procedural media family (fog, smoke grid, subsurface sphere) through USD, against ``volpath``."""
    from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import get_family

    translated = translate_usd(get_family("fog_smoke").author(tmp_path, seed=3, frames=1, width=SIZE, height=SIZE))
    assert "media" in translated.effects_inferred and "media" in translated.effects_declared
    scene = build_mitsuba_scene(translated)
    assert scene_has_media(scene)
    plan = make_render_plan(translated.effects_inferred)
    ours = render_frame(scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=SPP, seed=2, reference=True)
    sensor = mi.load_dict(sensor_dict(translated.camera, 0, SIZE, SIZE, SPP // REPLICAS))
    peer = build_mitsuba_scene(translated, integrator={"type": "volpath"})
    replicas = np.stack(
        [np.array(mi.render(peer, sensor=sensor, seed=700 + k))[..., :3] for k in range(REPLICAS)]
    ).astype(np.float64)
    z_blocks, z_image = _z_scores(ours.buffers["color"], ours.buffers["color_var"], replicas)
    assert np.abs(z_blocks).max() < 4.5, (np.abs(z_blocks).max(), ours.buffers["color"].mean((0, 1)))
    assert np.abs(z_image).max() < 4.0, z_image


def _medium_stage(tmp_path, **medium):
    from pxr import Usd, UsdGeom, UsdLux

    from denoisebench.scenes.media import author_medium

    stage = Usd.Stage.CreateNew(str(tmp_path / "stage.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    cube = UsdGeom.Cube.Define(stage, "/World/Smoke")
    author_medium(cube, **medium)
    UsdLux.DomeLight.Define(stage, "/World/Sky")
    camera = UsdGeom.Camera.Define(stage, "/World/Camera")
    camera.AddTranslateOp().Set((0.0, 0.0, 6.0))
    stage.Save()
    return tmp_path / "stage.usda"


def test_usd_medium_encoding_translates_and_bad_values_are_one_line_errors(tmp_path):
    from denoisebench.errors import UserInputError
    from denoisebench.generator.usd.translate import translate_usd

    density = np.linspace(0, 1, 4 * 3 * 2, dtype=np.float32).reshape(4, 3, 2)
    path = _medium_stage(tmp_path, kind="heterogeneous", sigma_t=(2, 2, 2), density=density, g=0.3)
    translated = translate_usd(path)
    assert "media" in translated.effects_inferred
    (record,) = [s for s in translated.shapes if s.medium is not None]
    medium = record.medium
    assert medium.kind == "heterogeneous" and medium.null_boundary and medium.g == pytest.approx(0.3)
    np.testing.assert_allclose(medium.density, density, atol=1e-5)
    # the grid spans the cube's extent [-1, 1]^3
    np.testing.assert_allclose(medium.grid_to_world @ [0, 0, 0, 1], [-1, -1, -1, 1])
    np.testing.assert_allclose(medium.grid_to_world @ [1, 1, 1, 1], [1, 1, 1, 1])
    for bad, message in (
        (dict(kind="plasma"), "plasma"),
        (dict(albedo=(1.5, 0.5, 0.5)), "albedo"),
        (dict(sigma_t=(-1, 1, 1)), "sigmaT"),
        (dict(g=1.0), "g must"),
        (dict(boundary="glass"), "boundary"),
    ):
        folder = tmp_path / message.replace(" ", "_")
        folder.mkdir()
        with pytest.raises(UserInputError, match=message) as error:
            translate_usd(_medium_stage(folder, **bad))
        assert "\n" not in str(error.value)


# --------------------------------------------------------------------------- datasets and denoisers

_FOG_XML = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0,0.4,4" target="0,0,0" up="0,1,0"/></transform>
  </sensor>
  <medium type="homogeneous" id="fog"><rgb name="sigma_t" value="1"/><float name="scale" value="2"/>
    <rgb name="albedo" value="0.9, 0.8, 0.7"/><phase type="hg"><float name="g" value="0.3"/></phase></medium>
  <shape type="sphere"><float name="radius" value="1"/><bsdf type="null"/><ref id="fog" name="interior"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="3"/><translate z="-1.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.4, 0.3"/></bsdf></shape>
  <shape type="sphere"><float name="radius" value="0.3"/><point name="center" x="1.6" y="1.8" z="1"/>
    <emitter type="area"><rgb name="radiance" value="20"/></emitter></shape>
</scene>
"""


@pytest.fixture(scope="module")
def fog_dataset(tmp_path_factory):
    """A two-frame dataset of a Mitsuba XML scene with fog (per-sample data), via ``generate --mitsuba``."""
    from denoisebench.cli import main
    from denoisebench.dataset import open_dataset

    root = tmp_path_factory.mktemp("fog_dataset")
    (root / "src").mkdir()
    (root / "src" / "fog.xml").write_text(_FOG_XML)
    out = root / "ds"
    args = ["generate", "--out", str(out), "--mitsuba", str(root / "src" / "fog.xml"), "--frames", "2"]
    args += ["--width", "24", "--height", "16", "--spp", "1,4", "--ref-spp", "32", "--ref-error", "0"]
    args += ["--samples", "--quiet"]
    assert main(args) == 0
    return open_dataset(out)


def test_generate_dataset_with_media_records_the_effect(fog_dataset):
    (name,) = fog_dataset.scenes
    info = fog_dataset.scene(name)
    assert "media" in info.effects["inferred"]
    frame = fog_dataset.frame(name, 4, 1)
    assert frame.reference.mean() > 0
    for key, value in frame.buffers.items():
        assert np.isfinite(value).all(), key


def test_every_builtin_passes_the_hard_case_rules_on_media_frames(fog_dataset):
    """Denoisers keep working on media frames: every built-in (classical baselines, peers and the learned
    models with their shipped weights) under the hard-case suite's contract and energy rule."""
    from denoisebench.denoisers.hard_cases import HardCase, run_case
    from denoisebench.denoisers.registry import BUILTINS, load_denoiser

    (name,) = fog_dataset.scenes
    frames = [fog_dataset.frame(name, spp, index) for spp in (1, 4) for index in (0, 1)]
    case = HardCase("media", "fog frames from a Mitsuba XML scene", lambda: frames)
    failed = {}
    for baseline in sorted(BUILTINS):
        outcome = run_case(load_denoiser(baseline), case)
        if not outcome.passed:
            failed[baseline] = outcome.reason
    assert not failed


def test_fog_smoke_has_held_out_variants(tmp_path):
    """About a fifth of the seeds draw media train stages never show; the stage records its pool."""
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import get_family
    from denoisebench.scenes.families.fog_smoke import HELD_OUT, TRAIN, variant_pool

    pools = [variant_pool(seed) for seed in range(200)]
    assert 0.1 < pools.count("held_out") / len(pools) < 0.3
    assert not set(HELD_OUT.values()) & set(TRAIN.values())
    held = pools.index("held_out")
    translated = translate_usd(get_family("fog_smoke").author(tmp_path / "held", seed=held, frames=1))
    assert translated.variants == {"pool": "held_out", **HELD_OUT}
    media = [s.medium for s in translated.shapes if s.medium is not None]
    (fog,) = [m for m in media if m.kind == "homogeneous" and m.null_boundary]
    assert fog.g < 0  # back-scattering fog: held out
    train = pools.index("train")
    translated = translate_usd(get_family("fog_smoke").author(tmp_path / "train", seed=train, frames=1))
    assert translated.variants == {"pool": "train", **TRAIN}


def test_usdvol_volume_is_a_one_line_error_never_dropped_light(tmp_path):
    from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdVol

    from denoisebench.errors import UserInputError
    from denoisebench.generator.usd.translate import translate_usd

    stage = Usd.Stage.CreateNew(str(tmp_path / "smoke.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.Sphere.Define(stage, "/World/Ball")
    UsdLux.DomeLight.Define(stage, "/World/Sky")
    UsdGeom.Camera.Define(stage, "/World/Camera").AddTranslateOp().Set((0.0, 0.0, 6.0))
    volume = UsdVol.Volume.Define(stage, "/World/Smoke")
    field = UsdVol.OpenVDBAsset.Define(stage, "/World/Smoke/density")
    field.GetFilePathAttr().Set(Sdf.AssetPath("smoke.vdb"))
    volume.CreateFieldRelationship("density", field.GetPath())
    stage.Save()
    with pytest.raises(UserInputError, match="UsdVol volumes are not rendered") as error:
        translate_usd(tmp_path / "smoke.usda")
    assert "density (OpenVDBAsset)" in str(error.value) and "\n" not in str(error.value)


def test_usd_camera_inside_fog_finds_its_medium_and_agrees_with_volpath(mi, tmp_path):
    """A USD camera inside a fog box (no sensor: the tracer finds the enclosing medium) against Mitsuba
    ``volpath`` given that medium as its sensor's."""
    from pxr import Usd, UsdGeom, UsdLux

    from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes.media import author_medium

    stage = Usd.Stage.CreateNew(str(tmp_path / "room.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    fog = UsdGeom.Cube.Define(stage, "/World/Fog")
    fog.AddScaleOp().Set((6.0, 6.0, 6.0))  # [-6, 6]^3 around the camera and the ball
    author_medium(fog, sigma_t=(0.3, 0.3, 0.3), albedo=(0.8, 0.8, 0.8), g=0.4)
    UsdGeom.Sphere.Define(stage, "/World/Ball")
    UsdLux.SphereLight.Define(stage, "/World/Lamp").AddTranslateOp().Set((2.0, 2.5, 1.0))
    UsdGeom.Camera.Define(stage, "/World/Camera").AddTranslateOp().Set((0.0, 0.5, 4.0))
    stage.Save()
    translated = translate_usd(tmp_path / "room.usda")
    scene = build_mitsuba_scene(translated)
    plan = make_render_plan(translated.effects_inferred)
    ours = render_frame(scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=SPP, seed=4, reference=True)
    (air,) = [s.interior_medium() for s in scene.shapes() if s.interior_medium() is not None]
    sensor = mi.load_dict({**sensor_dict(translated.camera, 0, SIZE, SIZE, SPP // REPLICAS), "medium": air})
    integrator = mi.load_dict({"type": "volpath"})
    replicas = np.stack(
        [
            np.array(mi.render(scene, sensor=sensor, integrator=integrator, seed=60 + k))[..., :3]
            for k in range(REPLICAS)
        ]
    ).astype(np.float64)
    z_blocks, z_image = _z_scores(ours.buffers["color"], ours.buffers["color_var"], replicas)
    assert np.abs(z_blocks).max() < 4.5 and np.abs(z_image).max() < 4.0, (z_image, np.abs(z_blocks).max())
    # in vacuum the image is another (the fog matters): the probe really found the camera's medium
    vacuum = mi.load_dict(sensor_dict(translated.camera, 0, SIZE, SIZE, SPP // REPLICAS))
    clear = np.array(mi.render(scene, sensor=vacuum, integrator=integrator, seed=1))[..., :3]
    assert abs(clear.mean() - ours.buffers["color"].mean()) > 0.1 * ours.buffers["color"].mean()


def test_motion_vectors_follow_moving_objects_in_media_scenes(tmp_path):
    """A moving-objects frame with a fog ball out of view: the volumetric tracer's motion vectors (pixel
    centres) equal the surface tracer's on the same scene without it (a first hit on a moving mesh
    reprojects where its point was)."""
    import dataclasses

    from denoisebench.generator.contract.scene_parts import MediumRecord, SphereShape
    from denoisebench.generator.render.scene import build_mitsuba_scene
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import get_family

    translated = translate_usd(get_family("moving_objects").author(tmp_path, seed=1, frames=3, width=SIZE, height=SIZE))
    assert translated.moving and not translated.shutter_moving
    fog = MediumRecord(kind="homogeneous", sigma_t=(1.0,) * 3, albedo=(0.8,) * 3, g=0.0, null_boundary=True)
    far = SphereShape(name="FarFog", center=(0.0, -500.0, 0.0), radius=1.0, medium=fog)
    foggy = dataclasses.replace(translated, shapes=(*translated.shapes, far))
    plan = make_render_plan(translated.effects)
    frames = {}
    for name, source in (("surface", translated), ("media", foggy)):
        scene = build_mitsuba_scene(source, frame=2)
        assert scene_has_media(scene) == (name == "media")
        frames[name] = render_frame(
            scene, source.camera, 2, plan, width=SIZE, height=SIZE, spp=1, seed=0, _jitter=False
        )
    ours, theirs = frames["media"].buffers["motion"], frames["surface"].buffers["motion"]
    assert np.abs(theirs).max() > 0.05  # something moves
    np.testing.assert_allclose(ours, theirs, atol=1e-3)
    # and every first-hit feature is the surface tracer's where no medium is seen
    for name in ("position", "normal", "depth", "albedo", "roughness"):
        np.testing.assert_allclose(
            frames["media"].buffers[name], frames["surface"].buffers[name], atol=1e-4, err_msg=name
        )


def test_a_medium_on_a_material_fills_every_gprim_bound_to_it(tmp_path):
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes.authoring import SceneBuilder
    from denoisebench.scenes.media import author_medium

    b = SceneBuilder(tmp_path, family="test", seed=0, frames=1, effects=("specular", "transmission", "media"))
    jade = b.material("Jade", diffuse=(1.0, 1.0, 1.0), roughness=0.0, opacity=0.0, ior=1.6)
    author_medium(jade, sigma_t=(8.0, 8.0, 8.0), albedo=(0.6, 0.9, 0.8), g=0.2)
    b.sphere("A", 0.5, jade, translate=(-1.0, 0.5, 0.0))
    b.sphere("B", 0.4, jade, translate=(1.0, 0.4, 0.0))
    b.sphere("Plain", 0.4, b.material("Grey"), translate=(0.0, 0.4, -1.0))
    b.dome_light("Sky", intensity=1.0)
    b.camera(np.stack([np.eye(4)]), focal_length_mm=35.0, clipping=(0.1, 100.0))
    translated = translate_usd(b.save())
    media = {s.name.rsplit("/", 1)[-1]: s.medium for s in translated.shapes if s.kind == "sphere"}
    assert media["Plain"] is None and "media" in translated.effects_inferred
    for name in ("A", "B"):
        assert media[name].albedo == pytest.approx([0.6, 0.9, 0.8]) and not media[name].null_boundary


def test_nested_media_get_the_enclosing_medium_as_exterior_and_agree_with_volpath(mi, tmp_path):
    """Smoke inside a fog bank (both null boundaries, USD): leaving the smoke a ray is in the fog again."""
    from denoisebench.generator.render.media import enclosing_media
    from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import camera_paths, geometry
    from denoisebench.scenes.authoring import SceneBuilder
    from denoisebench.scenes.media import author_medium

    b = SceneBuilder(tmp_path, family="test", seed=0, frames=1, effects=("media",))
    haze = b.material("Haze")
    b.mesh("Floor", geometry.grid(8.0, 8.0, 1, 1, axis="y"), b.material("Floor", diffuse=(0.5, 0.5, 0.5)))
    fog = b.cube("Fog", 1.0, haze, translate=(0.0, 1.0, 0.0), scale=(3.0, 2.0, 3.0))
    author_medium(fog, sigma_t=(0.4, 0.4, 0.4), albedo=(0.9, 0.9, 0.9))
    smoke = b.sphere("Smoke", 0.6, haze, translate=(0.0, 1.0, 0.0))
    author_medium(smoke, sigma_t=(3.0, 3.0, 3.0), albedo=(0.7, 0.5, 0.4), g=0.3)
    b.sphere_light("Lamp", 0.3, intensity=40.0, translate=(2.5, 3.0, 2.0))
    b.camera(camera_paths.dolly((0.0, 1.2, 5.0), (0.0, 1.2, 5.0), (0.0, 1.0, 0.0), 1), focal_length_mm=35.0)
    translated = translate_usd(b.save())
    shapes = translated.shapes
    outer = enclosing_media(shapes)
    (inner,) = outer  # the smoke sits in the fog; the fog in nothing
    assert shapes[inner].name.endswith("Smoke") and shapes[outer[inner]].name.endswith("Fog")
    scene = build_mitsuba_scene(translated)
    (nested,) = [s for s in scene.shapes() if s.exterior_medium() is not None]  # the smoke ball
    fog_medium = next(
        s.interior_medium()
        for s in scene.shapes()
        if s.interior_medium() is not nested.interior_medium() and s.interior_medium() is not None
    )
    assert nested.exterior_medium() is fog_medium
    plan = make_render_plan(translated.effects_inferred)
    ours = render_frame(scene, translated.camera, 0, plan, width=SIZE, height=SIZE, spp=SPP, seed=8, reference=True)
    sensor = mi.load_dict(sensor_dict(translated.camera, 0, SIZE, SIZE, SPP // REPLICAS))
    integrator = mi.load_dict({"type": "volpath"})
    replicas = np.stack(
        [
            np.array(mi.render(scene, sensor=sensor, integrator=integrator, seed=80 + k))[..., :3]
            for k in range(REPLICAS)
        ]
    ).astype(np.float64)
    z_blocks, z_image = _z_scores(ours.buffers["color"], ours.buffers["color_var"], replicas)
    assert np.abs(z_blocks).max() < 4.5 and np.abs(z_image).max() < 4.0, (z_image, np.abs(z_blocks).max())
