"""`denoisebench study data-value` end to end on a tiny budget, and its training-set rules."""

from __future__ import annotations

import json

import pytest

from denoisebench.cli import main
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.errors import UserInputError
from denoisebench.study.data_value import PoolScene, resolve_sets, round_robin

SCENE_XML = """<scene version="3.0.0">
  <default name="radius" value="{radius}"/>
  <integrator type="path"/>
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="0.8"/></emitter>
  <shape type="sphere"><float name="radius" value="$radius"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="{albedo}"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="3"/><translate z="-1.5"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.7"/></bsdf></shape>
</scene>
"""

SCENE_LIST = """name = "two scenes the test wrote"
repository = "https://example.invalid/tiny-scenes"
licence = "CC0"
camera = "own"

[[scene]]
source = "mitsuba"
path = "a/ball.xml"
defines = {{ radius = "1.0" }}

[[scene]]
source = "mitsuba"
path = "b/plate.xml"
licence = "{licence}"
"""


def _pool(folder):
    """A synthetic pool whose scenes pose as two families: odd ones 'textured' (they declare textures)."""
    root = make_synthetic_dataset(folder, scenes=9, frames=2, height=16, width=16, spp=(1, 4))
    manifest = json.loads((root / "dataset.json").read_text())
    for i, (name, record) in enumerate(sorted(manifest["scenes"].items())):
        record["family"] = "textured" if i % 2 else "plain"
        record["effects"] = {"declared": ["textures"] if i % 2 else [], "inferred": []}
    (root / "dataset.json").write_text(json.dumps(manifest))
    return root


def test_training_sets_follow_their_rules():
    scenes = [
        PoolScene(name=f"{f}_{i}", family=f, effects=("textures",) if f == "b" else ()) for f in "abc" for i in range(3)
    ]
    sets = {s.name: s for s in resolve_sets(["family:a", "without:textures", "loo:c"], [2, 4, 99], scenes)}
    assert set(sets["family:a"].families) == {"a"} and len(sets["family:a"].scenes) == 3
    assert set(sets["without:textures"].families) == {"a", "c"}
    assert set(sets["leave_one_out:c"].families) == {"a", "b"}
    assert len(sets["full"].scenes) == 9 and "n:99" not in sets  # at or above the pool: full itself
    # scaling prefixes stay mixed: 4 scenes hold all three families, and a prefix of the next point
    assert set(sets["n:4"].families) == {"a", "b", "c"} and set(sets["n:2"].scenes) < set(sets["n:4"].scenes)
    assert [s.family for s in round_robin(scenes)][:3] == ["a", "b", "c"]
    for bad in (["family:z"], ["without:fur"], ["nonsense"]):
        with pytest.raises(UserInputError):
            resolve_sets(bad, [], scenes)


def test_study_end_to_end_on_a_tiny_budget(tmp_path, capsys):
    root = tmp_path / "thirdparty"
    for sub, name, radius, albedo in (("a", "ball", "1.0", "0.7, 0.5, 0.3"), ("b", "plate", "0.6", "0.3, 0.6, 0.3")):
        (root / sub).mkdir(parents=True)
        (root / sub / f"{name}.xml").write_text(SCENE_XML.format(radius=radius, albedo=albedo))
    listing = tmp_path / "tiny.toml"
    listing.write_text(SCENE_LIST.format(licence="CC BY 4.0"))
    tp = tmp_path / "tp"
    common = ["--frames", "1", "--width", "16", "--height", "16", "--spp", "1,4", "--ref-spp", "128", "--quiet"]
    # a missing scene: one line naming the repository to clone
    assert main(["generate", "--out", str(tp), "--scene-list", str(listing), "--root", str(tmp_path), *common]) == 2
    assert "https://example.invalid/tiny-scenes" in capsys.readouterr().err.strip().splitlines()[-1]
    assert main(["generate", "--out", str(tp), "--scene-list", str(listing), "--root", str(root), *common]) == 0
    assert sorted(json.loads((tp / "dataset.json").read_text())["scenes"]) == ["xml_ball", "xml_plate"]

    pool = _pool(tmp_path / "pool")
    out = tmp_path / "study"
    args = ["study", "data-value", "--pool", str(pool), "--third-party", str(tp), "--out", str(out), "--models", "kpcn",
            "--sets", "full,family:plain", "--scaling", "2", "--steps", "3", "--batch-size", "2", "--crop", "8",
            "--references", "cross_bilateral", "--quiet"]  # fmt: skip
    assert main(args) == 0
    report = json.loads((out / "study.json").read_text())
    sets = {p["set"]: p for p in report["parts"]}
    assert set(sets) == {"full", "family:plain", "n:2"}
    # same budget for every training set; the set's scenes are the ones trained on
    assert {p["budget_pixels"] for p in report["parts"]} == {3 * 2 * 8 * 8}
    assert all(p["steps"] == 3 for p in report["parts"])
    assert {p["families"][0] for p in report["parts"] if p["set"] == "family:plain"} == {"plain"}
    for part in report["parts"]:
        score = part["scores"]["relmse_robust"]
        assert score["value"] is not None and score["value"] > 0 and score["low"] <= score["value"] <= score["high"]
        assert set(score["per_scene"]) == {"xml_ball", "xml_plate"}
    assert set(report["references"]) == {"noisy", "cross_bilateral"}
    curve = report["scaling"]["kpcn"]
    assert [p["scenes"] for p in curve] == [2, len(sets["full"]["scenes"])]
    text = (out / "study.md").read_text()
    assert "| kpcn | family:plain |" in text and "xml_ball | xml_plate" in text and "## Scaling curve" in text
    # every row is also compared scene by scene with cross_bilateral, which reads 1 against itself
    assert "relmse_robust ÷ cross_bilateral (paired)" in text
    assert "| cross_bilateral | (reference) | – |" in text and text.split("| cross_bilateral | (reference)")[1].split(
        "\n"
    )[0].endswith("| 1 | 1 |")
    assert (out / "scaling.png").stat().st_size > 1000
    # resumable: a second run trains and measures nothing new, and writes the same numbers
    before = {p.name: p.stat().st_mtime_ns for p in (out / "checkpoints").iterdir()}
    assert main(args) == 0
    assert {p.name: p.stat().st_mtime_ns for p in (out / "checkpoints").iterdir()} == before
    assert json.loads((out / "study.json").read_text())["parts"] == report["parts"]

    # several third-party datasets pool into one set of scenes (one generate run has one camera choice)
    (root / "c").mkdir()
    (root / "c" / "disc.xml").write_text(SCENE_XML.format(radius="0.3", albedo="0.9, 0.9, 0.9"))
    single = tmp_path / "one.toml"
    single.write_text(SCENE_LIST.split("[[scene]]")[0] + '[[scene]]\nsource = "mitsuba"\npath = "c/disc.xml"\n')
    tp2 = tmp_path / "tp2"
    assert main(["generate", "--out", str(tp2), "--scene-list", str(single), "--root", str(root), *common]) == 0
    twice = ["--third-party", f"{tp},{tp}"]
    pooled_args = [*args[:4], "--third-party", str(tp), "--third-party", str(tp2), *args[6:]]
    pooled_args[pooled_args.index(str(out))] = str(tmp_path / "pooled")
    assert main([*args[:4], *twice, *args[6:]]) == 2
    assert "xml_ball is also in" in capsys.readouterr().err
    assert main(pooled_args) == 0
    pooled = json.loads((tmp_path / "pooled" / "study.json").read_text())
    assert pooled["third_party"]["kept"] == ["xml_ball", "xml_plate", "xml_disc"]
    assert [d["scenes"] for d in pooled["third_party"]["datasets"]] == [["xml_ball", "xml_plate"], ["xml_disc"]]
    for label, scores in pooled["references"].items():
        for metric, score in scores.items():
            assert score["scenes"] == 3
            alone = report["references"][label][metric]["per_scene"]
            # the first dataset's scenes score as they did alone: pooling adds scenes, changes none
            assert {k: score["per_scene"][k] for k in alone} == pytest.approx(alone, rel=1e-12)
    for part in pooled["parts"]:
        assert set(part["scores"]["flip"]["per_scene"]) == {"xml_ball", "xml_plate", "xml_disc"}
        assert len(part["run_ids"]) == 2

    # --report-only: a report from the finished parts; what was asked for and not run is listed, not trained
    seeds = args.index("--scaling")
    more = [*args[:seeds], "--seeds", "0,1", *args[seeds:], "--report-only"]
    assert main(more) == 0
    after = json.loads((out / "study.json").read_text())
    assert {p.name: p.stat().st_mtime_ns for p in (out / "checkpoints").iterdir()} == before
    assert after["parts"] == report["parts"]
    assert set(after["missing"]) == {"kpcn full seed 1", "kpcn family:plain seed 1", "kpcn n:2 seed 1"}
    assert "## Not run" in (out / "study.md").read_text()
    # a checkpoint trained to the budget but never scored (its record gone) is scored, not retrained
    record = next((out / "parts").glob("kpcn__full__seed0__*.json"))
    record.unlink()
    assert main(more) == 0
    assert {p.name: p.stat().st_mtime_ns for p in (out / "checkpoints").iterdir()} == before
    rescored = json.loads((out / "study.json").read_text())
    assert rescored["parts"] == report["parts"] and record.is_file()
