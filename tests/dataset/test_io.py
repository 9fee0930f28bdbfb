"""The dataset package without a renderer: EXR I/O, manifest, writer, reader, augmentation, torch crops.

Peers: OpenEXR's own reader (channel names and stored pixel types), numpy for the rel_se formula;
invariants: exact float32 round trips, deterministic bytes, warping with augmented motion vectors.
"""

from __future__ import annotations

import json
import os

import numpy as np
import OpenEXR
import pytest

from denoisebench.dataset import (
    DatasetError,
    DatasetWriter,
    assign_splits,
    augment,
    config_hash,
    layout,
    manifest_without_timings,
    open_dataset,
    read_exr,
    read_samples_exr,
    reference_quality,
    write_exr,
)
from denoisebench.dataset.exr_io import encode_exr, load_exr, sha256_file
from denoisebench.dataset.manifest import load_manifest, relative_standard_error
from denoisebench.dataset.synthetic import make_synthetic_dataset

RNG = np.random.default_rng(1234)


def _buffers(h=5, w=7):
    color = RNG.random((h, w, 3), dtype=np.float32)
    color[0, 0] = [1e6, 3e-7, 65504.0 * 4]  # a firefly beyond half's range and a tiny value
    return {
        "color": color,
        "color_var": (color * 1e-3).astype(np.float32),
        "albedo": RNG.random((h, w, 3), dtype=np.float32),
        "normal": (RNG.random((h, w, 3), dtype=np.float32) * 2 - 1),
        "depth": RNG.random((h, w), dtype=np.float32) * 1e4 + 0.123456,  # H×W is accepted for 1 channel
        "roughness": RNG.random((h, w, 1), dtype=np.float32),
        "motion": RNG.normal(size=(h, w, 2)).astype(np.float32),
        "extra5": RNG.random((h, w, 5), dtype=np.float32),
    }


# --------------------------------------------------------------------------- exr_io


def test_exr_round_trip_types_and_channel_names_as_openexr_sees_them(tmp_path):
    buffers = _buffers()
    path = tmp_path / "f.exr"
    written = write_exr(path, buffers, header_extra={"scene": "s", "frame": 3})
    assert written.main.sha256 == sha256_file(path) and written.samples is None
    back = read_exr(path)
    for name in ("color", "color_var", "motion", "extra5"):
        np.testing.assert_array_equal(back[name], buffers[name])  # float32, exact
    np.testing.assert_array_equal(back["depth"], buffers["depth"][..., None])
    for name in ("albedo", "normal", "roughness"):  # half: 11 significant bits
        np.testing.assert_allclose(back[name], buffers[name], rtol=2**-11, atol=2**-25)
        assert back[name].dtype == np.float32
    # The peer: OpenEXR itself reads layer.channel names and the stored pixel types.
    with OpenEXR.File(str(path), True) as exr:
        channels = exr.channels()
        assert {
            "color.R",
            "color.G",
            "color.B",
            "normal.X",
            "depth.Z",
            "motion.X",
            "motion.Y",
            "roughness.Y",
            "extra5.C4",
            "color_var.B",
        } <= set(channels)
        assert channels["color.R"].pixels.dtype == np.float32
        assert channels["albedo.G"].pixels.dtype == np.float16
        assert channels["color_var.R"].pixels.dtype == np.float32
        assert json.loads(exr.header()["denoisebench"]) == {"frame": 3, "scene": "s"}


def test_half_only_where_the_range_is_safe(tmp_path):
    albedo = np.full((2, 3, 3), 0.5, np.float32)
    albedo[1, 2, 0] = 1e5  # a user material out of half's range: the layer stays float32, unclipped
    write_exr(tmp_path / "a.exr", {"color": albedo, "albedo": albedo})
    assert read_exr(tmp_path / "a.exr")["albedo"][1, 2, 0] == np.float32(1e5)
    with OpenEXR.File(str(tmp_path / "a.exr"), True) as exr:
        assert exr.channels()["albedo.R"].pixels.dtype == np.float32


def test_same_arrays_same_bytes_and_key_order_does_not_matter():
    buffers = _buffers()
    reordered = dict(reversed(list(buffers.items())))
    assert encode_exr(buffers, {"a": 1, "b": 2}) == encode_exr(reordered, {"b": 2, "a": 1})
    assert encode_exr(buffers, {"a": 1}) != encode_exr(buffers, {"a": 2})


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_inf_are_refused_and_nothing_is_written(tmp_path, bad):
    buffers = _buffers()
    buffers["color"][2, 3, 1] = bad
    with pytest.raises(ValueError, match="NaN/Inf"):
        write_exr(tmp_path / "f.exr", buffers, per_sample={"color": np.zeros((2, 5, 7, 3), np.float32)})
    assert list(tmp_path.rglob("*.exr")) == []


def test_per_sample_round_trip_one_part_per_sample(tmp_path):
    samples = {
        "color": RNG.random((3, 4, 6, 3), dtype=np.float32) * 100,
        "pixel": RNG.random((3, 4, 6, 2), dtype=np.float32),
        "time": RNG.random((3, 4, 6, 1), dtype=np.float32),
    }
    written = write_exr(tmp_path / "spp0003" / "f.exr", {"color": samples["color"].mean(0)}, per_sample=samples)
    assert written.samples.path == tmp_path / "spp0003" / "samples" / "f.exr"
    with OpenEXR.File(str(written.samples.path)) as exr:
        assert len(exr.parts) == 3
    back = read_samples_exr(written.samples.path)
    for name, array in samples.items():
        np.testing.assert_array_equal(back[name], array)


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (1, 9)])
def test_odd_sizes(tmp_path, shape):
    color = RNG.random((*shape, 3), dtype=np.float32)
    write_exr(tmp_path / "o.exr", {"color": color})
    np.testing.assert_array_equal(read_exr(tmp_path / "o.exr")["color"], color)


def test_corrupt_truncated_and_missing_files_name_the_file(tmp_path):
    path = tmp_path / "f.exr"
    write_exr(path, _buffers())
    data = path.read_bytes()
    cases = {"trunc.exr": data[: len(data) // 2], "empty.exr": b"", "text.exr": b"not an exr at all"}
    for name, content in cases.items():
        (tmp_path / name).write_bytes(content)
        with pytest.raises(DatasetError, match=name) as info:
            read_exr(tmp_path / name)
        assert "\n" not in str(info.value)
    with pytest.raises(DatasetError, match="missing"):
        read_exr(tmp_path / "nope.exr")
    with pytest.raises(DatasetError, match="sha256"):
        load_exr(path, expect_sha256="0" * 64)


def test_nan_stored_by_another_tool_is_reported(tmp_path):
    pixels = np.ones((2, 2), np.float32)
    pixels[1, 1] = np.nan
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"color.R": pixels, "color.G": pixels, "color.B": pixels}).write(str(tmp_path / "n.exr"))
    with pytest.raises(DatasetError, match="NaN/Inf"):
        read_exr(tmp_path / "n.exr")


# --------------------------------------------------------------------------- manifest


def test_config_hash_is_canonical():
    assert config_hash({"a": 1, "b": [1, 2]}) == config_hash({"b": (1, 2), "a": 1})
    assert config_hash({"a": 1}) != config_hash({"a": 2})
    with pytest.raises(ValueError):
        config_hash({"a": float("nan")})


def test_assign_splits_deterministic_partition():
    names = [f"scene_{i:02d}" for i in range(10)]
    splits = assign_splits(names, 3)
    assert splits == assign_splits(list(reversed(names)), 3)  # order-free
    assert sorted(sum(splits.values(), [])) == names  # a partition
    assert [len(splits[k]) for k in ("train", "val", "test")] == [6, 2, 2]  # 10·0.15 = 1.5 rounds up
    assert any(assign_splits(names, seed) != splits for seed in range(4, 8))  # the seed matters
    assert assign_splits(["only"], 0) == {"train": [], "val": [], "test": ["only"]}
    two = assign_splits(["a", "b"], 0)
    assert len(two["train"]) == 1 and len(two["test"]) == 1


def test_relative_standard_error_formula_and_hard_cases():
    color = RNG.random((4, 5, 3)) + 0.5
    var = RNG.random((4, 5, 3)) * 1e-2
    assert relative_standard_error(color, var) == pytest.approx(np.sqrt(var.mean()) / color.mean())
    assert relative_standard_error(np.zeros((2, 2, 3)), np.zeros((2, 2, 3))) == 0.0  # black frame
    assert relative_standard_error(color, None) is None
    with pytest.raises(ValueError):
        relative_standard_error(color, np.full_like(var, np.nan))
    # the 4x rule, at its boundary
    assert reference_quality([0.4, 0.2], 0.11) is True
    assert reference_quality([0.4, 0.2], 0.1) is False
    assert reference_quality([None], 0.5) is False


def test_manifest_without_timings_and_bad_manifests(tmp_path):
    manifest = {
        "a": {"seconds": 1.0, "seconds_per_spp": 0.5, "jit_compile_seconds": 2.0, "spp": 2, "l": [{"seconds": 3}]}
    }
    assert manifest_without_timings(manifest) == {"a": {"spp": 2, "l": [{}]}}
    for name, text in {
        "x.json": "{",
        "y.json": '{"schema": "other"}',
        "z.json": '{"schema": "denoisebench-dataset", "schema_version": 99}',
    }.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(DatasetError, match=name):
            load_manifest(tmp_path / name)


# --------------------------------------------------------------------------- writer

SCENE = {"family": "synthetic", "seed": 0, "frames": 2, "width": 4, "height": 3, "spp": [1, 4], "ref_spp": 64}


def _frame(spp, seed=0):
    rng = np.random.default_rng([seed, spp])
    color = rng.random((3, 4, 3), dtype=np.float32)
    return {"color": color, "color_var": np.full_like(color, 0.1 / spp)}


def _fill(writer, name="s0"):
    for frame in range(2):
        for spp in (1, 4):
            writer.write_frame(name, frame, spp, _frame(spp, frame), seconds=0.01 * spp)
        ref = _frame(64, frame)
        writer.write_reference(name, frame, ref["color"], ref["color_var"], seconds=1.0)


def test_writer_resume_is_done_and_tamper_detection(tmp_path):
    writer = DatasetWriter(tmp_path / "ds", {"k": 1})
    writer.add_scene("s0", SCENE)
    writer.write_frame("s0", 0, 1, _frame(1), seconds=0.5)
    again = DatasetWriter(tmp_path / "ds", {"k": 1})
    assert again.resumed and again.is_done("s0", 0, 1) and not again.is_done("s0", 0, 4)
    again.add_scene("s0", SCENE)  # the same record keeps the frame
    assert again.is_done("s0", 0, 1)
    path = tmp_path / "ds" / layout.noisy_path("s0", 1, 0)
    path.write_bytes(path.read_bytes()[:-1] + b"\0")
    assert not again.is_done("s0", 0, 1)
    assert ("s0", 0, 1) in again.missing(verify=True)
    changed = dict(SCENE, width=5)
    again.add_scene("s0", changed)  # another record (size changed): its frames are dropped
    assert again.manifest["scenes"]["s0"]["renders"] == {}


def test_writer_refuses_another_config_and_force_clears_only_its_scenes(tmp_path):
    out = tmp_path / "ds"
    writer = DatasetWriter(out, {"k": 1})
    writer.add_scene("s0", SCENE)
    _fill(writer)
    (out / "notes.txt").write_text("keep")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "precious").write_text("x")
    os.symlink(elsewhere, out / "s1")
    writer.manifest["scenes"]["s1"] = dict(SCENE, renders={})  # a scene folder that is a symlink
    writer._save()
    with pytest.raises(DatasetError, match="different config"):
        DatasetWriter(out, {"k": 2})
    assert (out / "s0").is_dir()
    fresh = DatasetWriter(out, {"k": 2}, force=True)
    assert not fresh.resumed and not (out / "s0").exists() and not (out / "s1").exists()
    assert (out / "notes.txt").read_text() == "keep" and (elsewhere / "precious").exists()


def test_writer_rejects_bad_frames_without_recording_them(tmp_path):
    writer = DatasetWriter(tmp_path / "ds", {"k": 1})
    writer.add_scene("s0", SCENE)
    with pytest.raises(ValueError, match="spp"):
        writer.write_frame("s0", 0, 2, _frame(2))
    with pytest.raises(ValueError):
        writer.write_frame("s0", 0, 1, {"color": np.zeros((4, 4, 3), np.float32)})
    bad = _frame(1)
    bad["color"][0, 0, 0] = np.inf
    with pytest.raises(ValueError, match="NaN/Inf"):
        writer.write_frame("s0", 0, 1, bad)
    with pytest.raises(ValueError, match="seconds"):
        writer.write_frame("s0", 0, 1, _frame(1), seconds=float("nan"))
    with pytest.raises(ValueError, match="reserved"):
        writer.write_frame("s0", 0, 1, _frame(1), extra={"sha256": "mine"})
    assert writer.manifest["scenes"]["s0"]["renders"] == {}
    assert not list((tmp_path / "ds").rglob("*.exr"))
    with pytest.raises(ValueError, match="not written"):
        writer.finalize({"test": ["s0"]})
    with pytest.raises(ValueError, match="bad scene name"):
        writer.add_scene("../up", SCENE)


def test_writer_flags_reference_and_finalizes(tmp_path):
    writer = DatasetWriter(tmp_path / "ds", {"k": 1})
    writer.add_scene("s0", SCENE)
    _fill(writer)
    with pytest.raises(ValueError, match="no split"):
        writer.finalize({"train": []})
    writer.finalize({"test": ["s0"]})
    manifest = load_manifest(tmp_path / "ds" / layout.MANIFEST_NAME)
    assert manifest["complete"] and manifest["splits"]["test"] == ["s0"]
    ref = manifest["scenes"]["s0"]["renders"]["reference"]["0000"]
    noisy = [manifest["scenes"]["s0"]["renders"][k]["0000"]["rel_se"] for k in ("spp0001", "spp0004")]
    # a 1-spp input has no variance estimate: unknown (None), never "less noisy"
    assert noisy[0] is None and noisy[1] > 0
    assert ref["noisy_rel_se_max"] == noisy[1]
    assert ref["reference_too_noisy"] == reference_quality(noisy, ref["rel_se"])
    # the flag follows the reference's own noise: a 1-spp-noisy reference is flagged
    noisy_ref = _frame(1, 0)
    writer.write_reference("s0", 0, noisy_ref["color"], noisy_ref["color_var"] * 10, seconds=1.0)
    assert writer.manifest["scenes"]["s0"]["renders"]["reference"]["0000"]["reference_too_noisy"] is True


def test_stale_temporaries_of_a_killed_run_are_removed(tmp_path):
    writer = DatasetWriter(tmp_path / "ds", {"k": 1})
    writer.add_scene("s0", SCENE)
    target = tmp_path / "ds" / layout.noisy_path("s0", 1, 0)
    target.parent.mkdir(parents=True)
    stale = target.with_name(f".{target.name}.424242.tmp")
    stale.write_bytes(b"half a file")
    DatasetWriter(tmp_path / "ds", {"k": 1})
    assert not stale.exists() and target.parent.is_dir()


def test_synthetic_dataset_same_bytes(tmp_path):
    a = make_synthetic_dataset(tmp_path / "a", scenes=2, frames=2, per_sample=True)
    b = make_synthetic_dataset(tmp_path / "b", scenes=2, frames=2, per_sample=True)
    files_a = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files_a == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for rel in files_a:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel


# --------------------------------------------------------------------------- reader


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    return make_synthetic_dataset(
        tmp_path_factory.mktemp("syn") / "ds",
        scenes=3,
        frames=4,
        height=12,
        width=20,
        spp=(1, 4),
        per_sample=True,
        velocity=(1.0, 0.0),
    )


def test_reader_catalogue_frames_and_sequences(synthetic):
    ds = open_dataset(synthetic / layout.MANIFEST_NAME, verify=True)
    assert ds.scenes == ["synthetic_000", "synthetic_001", "synthetic_002"] and ds.complete
    assert sorted(sum(ds.splits.values(), [])) == ds.scenes
    frame = ds.frame("synthetic_001", 4, 2)
    assert frame.color.shape == (12, 20, 3) and frame.reference.shape == (12, 20, 3)
    assert frame.samples["pixel"].shape == (4, 12, 20, 2)
    assert frame.meta["reference_spp"] == 1024 and frame.meta["seconds"] == pytest.approx(0.004)
    only = ds.frame("synthetic_001", 1, 0, buffers=["albedo"], reference=False, samples=False)
    assert set(only.buffers) == {"color", "albedo"} and only.reference is None and only.samples is None
    seq = ds.sequence("synthetic_000", 1)
    assert len(seq) == 4 and [f.index for f in seq] == [0, 1, 2, 3]
    assert seq.meta["camera"]["velocity"] == [1.0, 0.0]


def test_reader_errors_are_one_line_and_name_the_problem(synthetic, tmp_path):
    ds = open_dataset(synthetic)
    for call, match in [
        (lambda: ds.scene("nope"), "nope"),
        (lambda: ds.frame("synthetic_000", 2, 0), "spp"),
        (lambda: ds.frame("synthetic_000", 1, 9), "frames 0..3"),
        (lambda: ds.split("holdout"), "unknown split"),
        (lambda: ds.frame("synthetic_000", 1, 0, buffers=["nothing"]), "nothing"),
        (lambda: open_dataset(tmp_path / "absent"), "does not exist"),
        (lambda: open_dataset(tmp_path), "no manifest"),
    ]:
        with pytest.raises(DatasetError, match=match) as info:
            call()
        assert "\n" not in str(info.value)


def test_reader_verify_catches_a_changed_file(tmp_path):
    root = make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=1, spp=(1,))
    path = root / layout.noisy_path("synthetic_000", 1, 0)
    other = encode_exr({"color": np.zeros((16, 16, 3), np.float32)})
    path.write_bytes(other)
    assert open_dataset(root).frame("synthetic_000", 1, 0).color.max() == 0  # unverified: reads it
    with pytest.raises(DatasetError, match="sha256"):
        open_dataset(root, verify=True).frame("synthetic_000", 1, 0)
    path.unlink()
    with pytest.raises(DatasetError, match=str(path.name)):
        open_dataset(root).frame("synthetic_000", 1, 0)


# --------------------------------------------------------------------------- augment


def _warp(prev: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """prev sampled at p + motion(p) (integer motion, periodic borders)."""
    h, w = prev.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    ys = (y + np.rint(motion[..., 1]).astype(int)) % h
    xs = (x + np.rint(motion[..., 0]).astype(int)) % w
    return prev[ys, xs]


def test_the_eight_transforms_are_distinct_and_drawn_uniformly():
    image = np.arange(3 * 5).reshape(3, 5, 1).astype(np.float32)
    outs = {
        augment.transform_array("color", image, t).tobytes() + bytes(augment.transform_array("color", image, t).shape)
        for t in augment.all_transforms()
    }
    assert len(outs) == 8
    rng = np.random.default_rng(0)
    counts = {}
    for _ in range(4000):
        key = augment.transform_array("color", image, augment.random_transform(rng))
        counts[key.tobytes() + bytes(key.shape)] = counts.get(key.tobytes() + bytes(key.shape), 0) + 1
    assert len(counts) == 8 and all(350 < c < 650 for c in counts.values())


@pytest.mark.parametrize(
    "t", augment.all_transforms() + [augment.Transform(1, True, True), augment.Transform(3, False, True)]
)
def test_augmented_motion_still_warps_the_previous_frame_onto_the_current(t):
    prev = RNG.random((6, 9, 3), dtype=np.float32)  # non-square: axis mix-ups fail
    dx, dy = -2, 1
    motion = np.zeros((6, 9, 2), np.float32)
    motion[..., 0], motion[..., 1] = dx, dy
    cur = _warp(prev, motion)
    t_prev = augment.transform_array("color", prev, t)
    t_cur = augment.transform_array("color", cur, t)
    t_motion = augment.transform_array("motion", motion, t)
    np.testing.assert_array_equal(_warp(t_prev, t_motion), t_cur)
    var = np.stack([np.full((6, 9), 1.0), np.full((6, 9), 2.0)], -1).astype(np.float32)
    t_var = augment.transform_array("motion_var", var, t)
    assert t_var[0, 0, 0] == (2.0 if t.rot % 2 else 1.0)
    stacked = np.stack([prev, cur])  # K×H×W×C: one transform for the whole window
    np.testing.assert_array_equal(augment.transform_array("color", stacked, t)[1], t_cur)


# --------------------------------------------------------------------------- torch datasets


def test_crop_dataset_items_are_windows_of_the_frames(synthetic):
    from denoisebench.dataset import CropDataset

    data = CropDataset(synthetic, split=["synthetic_000", "synthetic_001"], spp=[1, 4], crop=8, augment=False, seed=3)
    assert len(data) == 2 * 2 * 4
    item = data[5]
    assert item["color"].shape == (3, 8, 8) and item["reference"].shape == (3, 8, 8)
    assert item["depth"].shape == (1, 8, 8) and str(item["color"].dtype) == "torch.float32"
    scene, spp, index, _ = data.items[5]
    full = open_dataset(synthetic).frame(scene, spp, index).color
    crop = item["color"].permute(1, 2, 0).numpy()
    matches = [(y, x) for y in range(12 - 7) for x in range(20 - 7) if np.array_equal(full[y : y + 8, x : x + 8], crop)]
    assert matches  # a real window of the frame
    assert all((data[5][k] == item[k]).all() for k in item)  # same epoch, same crop
    epoch0 = [data[i]["color"] for i in range(len(data))]
    data.set_epoch(1)
    assert any(not (data[i]["color"] == epoch0[i]).all() for i in range(len(data)))  # new epoch, new crops
    with pytest.raises(DatasetError, match="does not fit"):
        CropDataset(synthetic, split="test", spp=1, crop=13)


def test_sequence_crops_keep_motion_consistent_through_augmentation(synthetic):
    from denoisebench.dataset import SequenceCropDataset

    data = SequenceCropDataset(synthetic, split=["synthetic_002"], spp=4, frames=3, crop=10, augment=True, seed=1)
    assert len(data) == 2  # windows 0-2 and 1-3
    seen = set()
    for epoch in range(6):
        data.set_epoch(epoch)
        for i in range(len(data)):
            item = data[i]
            assert item["color"].shape == (3, 3, 10, 10) and item["motion"].shape == (3, 2, 10, 10)
            ref = item["reference"].permute(0, 2, 3, 1).numpy()
            motion = item["motion"].permute(0, 2, 3, 1).numpy()
            seen.add(tuple(np.rint(motion[1, 0, 0]).astype(int)))
            for k in (1, 2):
                # The synthetic pattern slides by whole pixels: ref_k(p) = ref_{k-1}(p + motion_k(p)) inside the crop.
                h, w = ref.shape[1:3]
                y, x = np.mgrid[0:h, 0:w]
                ys, xs = y + np.rint(motion[k, ..., 1]).astype(int), x + np.rint(motion[k, ..., 0]).astype(int)
                inside = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
                np.testing.assert_allclose(ref[k][inside], ref[k - 1][ys[inside], xs[inside]], rtol=1e-5, atol=1e-6)
    assert len(seen) >= 3  # augmentation turned the motion into several directions
