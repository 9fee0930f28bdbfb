"""``denoisebench export --format oidn``: OIDN's training layout, read back with OpenImageIO.

Peers: OpenImageIO (the reader of OIDN's ``training/image.py``) for every file; OIDN's grouping
rule of ``training/dataset.py`` (``get_image_sample_groups``) and metadata look-up
(``load_image_metadata``), restated below from their source, for the names.
"""

from __future__ import annotations

import json
import os
from collections import defaultdict

import numpy as np
import OpenImageIO as oiio
import pytest

from denoisebench.cli import main
from denoisebench.dataset import open_dataset
from denoisebench.dataset.export import oidn
from denoisebench.dataset.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    return make_synthetic_dataset(tmp_path_factory.mktemp("src") / "ds", scenes=4, frames=2, height=20, width=24)


@pytest.fixture(scope="module")
def exported(source, tmp_path_factory):
    out = tmp_path_factory.mktemp("oidn") / "export"
    code = main(["export", str(source), str(out), "--format", "oidn", "--tile-size", "16", "--quiet"])
    assert code == 0
    return out


def _oidn_groups(folder):
    """OIDN's rule: name = file name less ``.<feature>.exr``; group = the part before the last ``_``
    when what follows is a number, ``<n>spp``, ``ref``/``reference``/``gt``/``target``; sorted names,
    the last one the target."""
    groups = defaultdict(set)
    for root, _, files in os.walk(folder):
        for file in files:
            if file.count(".") < 2 or not file.endswith(".exr"):
                continue
            name = os.path.relpath(os.path.join(root, file), folder).rsplit(".", 2)[0]
            group = name
            if "_" in name:
                prefix, suffix = name.rsplit("_", 1)
                s = suffix.lower()
                if (
                    s.isdecimal()
                    or (s.endswith("spp") and s[:-3].isdecimal())
                    or s in ("ref", "reference", "gt", "target")
                ):
                    group = prefix
            groups[group].add(name)
    return {g: (sorted(n)[:-1], sorted(n)[-1]) for g, n in groups.items()}


def _read(path):
    image = oiio.ImageInput.open(str(path))
    assert image, oiio.geterror()
    spec = image.spec()
    pixels = image.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    more = image.seek_subimage(1, 0)
    image.close()
    return spec, pixels, more


def test_groups_follow_oidn_rule_with_the_reference_as_target(source, exported):
    ds = open_dataset(source)
    for split in ("train", "val", "test"):
        groups = _oidn_groups(exported / split)
        expected = {f"{scene}_f{t:04d}" for scene in ds.split(split) for t in range(2)}
        assert set(groups) == expected
        for group, (inputs, target) in groups.items():
            assert target == f"{group}_ref"
            assert inputs == [f"{group}_0001spp", f"{group}_0004spp"]  # every rung, in spp order
            for name in [*inputs, target]:
                for feature in ("hdr", "alb", "nrm"):
                    assert (exported / split / f"{name}.{feature}.exr").is_file()
            # OIDN's load_image_metadata: strip '_' parts until <name>.json exists
            base, found = target, None
            while base:
                if (exported / split / f"{base}.json").is_file():
                    found = base
                    break
                base = base.rsplit("_", 1)[0] if "_" in base else ""
            assert found == group.rsplit("_f", 1)[0]
            assert json.loads((exported / split / f"{found}.json").read_text())["exposure"] > 0


def test_openimageio_reads_single_layer_rgb_float_equal_to_our_buffers(source, exported):
    ds = open_dataset(source)
    scene = ds.split("train")[0]
    for spp in (1, 4):
        frame = ds.frame(scene, spp, 1)
        for feature, buffer, low, high in (
            ("hdr", "color", 0, None),
            ("alb", "albedo", 0, 1),
            ("nrm", "normal", -1, 1),
        ):
            spec, pixels, more = _read(exported / "train" / f"{scene}_f0001_{spp:04d}spp.{feature}.exr")
            assert not more  # one subimage, one layer
            assert list(spec.channelnames) == ["R", "G", "B"]
            assert spec.format == oiio.TypeDesc("float")
            assert (spec.height, spec.width) == (20, 24)
            np.testing.assert_array_equal(pixels, np.clip(frame.buffers[buffer], low, high))
    _, ref, _ = _read(exported / "train" / f"{scene}_f0001_ref.hdr.exr")
    np.testing.assert_array_equal(ref, ds.frame(scene, 4, 1).reference)


def test_clipping_matches_oidn_and_names_sort_by_spp():
    wild = np.array([[[-2.0, 0.5, 3.0]]], np.float32)
    for feature, expected in (("hdr", [0, 0.5, 3]), ("alb", [0, 0.5, 1]), ("nrm", [-1, 0.5, 1])):
        data = oidn.encode_feature(feature, wild)
        spec_path = f"/tmp/.denoisebench-oidn-{os.getpid()}-{feature}.exr"
        with open(spec_path, "wb") as handle:
            handle.write(data)
        try:
            _, pixels, _ = _read(spec_path)
        finally:
            os.unlink(spec_path)
        np.testing.assert_array_equal(pixels[0, 0], np.array(expected, np.float32))
    ladder = [1, 16, 256, 4096, 65536]
    digits = oidn.spp_digits(ladder)
    names = [oidn.image_name("s_01", 3, s, digits) for s in reversed(ladder)] + [oidn.image_name("s_01", 3, None)]
    assert sorted(names) == [oidn.image_name("s_01", 3, s, digits) for s in ladder] + ["s_01_f0003_ref"]
    assert {oidn.oidn_group(n) for n in names} == {"s_01_f0003"}


def test_depth_feature_is_one_z_channel(source, tmp_path):
    out = tmp_path / "z"
    assert (
        main(
            ["export", str(source), str(out), "--format", "oidn", "--tile-size", "16", "--features", "hdr,z", "--quiet"]
        )
        == 0
    )
    ds = open_dataset(source)
    scene = ds.split("val")[0]
    spec, pixels, _ = _read(out / "val" / f"{scene}_f0000_0004spp.z.exr")
    assert list(spec.channelnames) == ["Z"]
    np.testing.assert_array_equal(pixels, ds.frame(scene, 4, 0).buffers["depth"])
    assert not list((out / "val").glob("*.alb.exr"))


@pytest.mark.parametrize(
    "extra, message",
    [
        ([], "smaller than OIDN's tile size 256"),
        (["--tile-size", "16", "--features", "alb,nrm"], "must include hdr"),
        (["--tile-size", "16", "--features", "hdr,sh1"], "unknown OIDN feature"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(source, tmp_path, capsys, extra, message):
    out = tmp_path / "never"
    assert main(["export", str(source), str(out), "--format", "oidn", "--quiet", *extra]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert not out.exists() and not list(tmp_path.iterdir())


def test_existing_out_needs_force_and_a_failed_export_leaves_nothing(source, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("old")
    assert main(["export", str(source), str(out), "--format", "oidn", "--tile-size", "16", "--quiet"]) == 2
    assert "--force" in capsys.readouterr().err
    calls = {"n": 0}
    real = oidn.encode_feature

    def failing(feature, array):
        calls["n"] += 1
        if calls["n"] == 7:
            raise OSError("disk full")
        return real(feature, array)

    monkeypatch.setattr(oidn, "encode_feature", failing)
    with pytest.raises(OSError):
        main(["export", str(source), str(out), "--format", "oidn", "--tile-size", "16", "--quiet", "--force"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging folder left
    assert (out / "keep.txt").read_text() == "old"
    monkeypatch.setattr(oidn, "encode_feature", real)
    assert main(["export", str(source), str(out), "--format", "oidn", "--tile-size", "16", "--quiet", "--force"]) == 0
    assert not (out / "keep.txt").exists() and (out / "train").is_dir()


def test_scenes_option_exports_only_those(source, tmp_path):
    ds = open_dataset(source)
    chosen = [ds.split("train")[0], ds.split("test")[0]]
    out = tmp_path / "some"
    args = ["export", str(source), str(out), "--format", "oidn", "--tile-size", "16", "--quiet"]
    assert main([*args, "--scenes", ",".join(chosen)]) == 0
    names = {p.name.split("_f")[0] for p in out.rglob("*.exr")}
    assert names == set(chosen) and not (out / "val").exists()


def test_scene_without_reference_is_refused_when_oidn_would_pick_a_rung_as_target(tmp_path, capsys):
    from denoisebench.dataset import DatasetWriter, assign_splits
    from denoisebench.dataset.synthetic import synthetic_frame

    source = tmp_path / "noref"
    writer = DatasetWriter(source, {"generator": "test", "no_reference": True}, {"test": "1"})
    record = {"family": "synthetic", "seed": 0, "frames": 1, "width": 16, "height": 16, "spp": [1, 4]}
    writer.add_scene("plain", {**record, "ref_spp": None, "plan": {}, "effects": {"declared": [], "inferred": []}})
    for spp in (1, 4):
        writer.write_frame("plain", 0, spp, synthetic_frame(16, 16, 0, spp)[0], None, seconds=0.001)
    writer.finalize(assign_splits(["plain"], 0))
    out = tmp_path / "never"
    assert main(["export", str(source), str(out), "--format", "oidn", "--tile-size", "16", "--quiet"]) == 2
    assert "no reference: OIDN would take its top rung (4 spp)" in capsys.readouterr().err
    assert not out.exists()
