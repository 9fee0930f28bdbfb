"""Datasets at scale: the frame-record index, old manifests, lazy readers, cheap checks first,
metrics that do not apply.

Everything here is tiny (4×4 and 8×8 synthetic frames, no renderer). Speed itself is measured by
``bench/dataset_scaling.py``; these tests pin the behaviours that make the cost per frame constant:
``dataset.json`` is not rewritten per record, a killed writer loses only the frame in flight, a
reader opens a dataset without touching its frame records.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from denoisebench import cli
from denoisebench.benchmark.runner import dataset_hash
from denoisebench.dataset import layout, manifest_without_timings, open_dataset
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.exr_io import canonical_json
from denoisebench.dataset.manifest import load_header, load_manifest
from denoisebench.dataset.synthetic import make_synthetic_dataset, synthetic_frame
from denoisebench.dataset.writer import DatasetWriter
from tests.support.paths import REPO  # noqa: E402

#: A dataset made by an older denoisebench (schema version 1, records inline in dataset.json):
#: make_synthetic_dataset(scenes=2, frames=2, height=8, width=8, spp=(1, 2), ref_spp=64) at commit 928c378.
V1 = REPO / "tests" / "data" / "dataset_v1"
#: runner.dataset_hash of V1 computed by that commit's code (sha256 of the whole manifest without timings).
V1_HASH = "9950d36ee1fc3e876551e5babd109bbede83cd1316d075164f981ef5dd827a1e"

SCENE = {"family": "synthetic", "seed": 0, "frames": 40, "width": 4, "height": 4, "spp": [1], "ref_spp": 4}
CHILD_SCENE = dict(SCENE, frames=30, ref_spp=None)

# The child writes frames one by one and says so after each; the parent kills it with SIGKILL.
CHILD = """
import sys
from denoisebench.dataset.synthetic import synthetic_frame
from denoisebench.dataset.writer import DatasetWriter
out, frames = sys.argv[1], int(sys.argv[2])
writer = DatasetWriter(out, {"k": 1})
writer.add_scene("s0", SCENE_RECORD)
for t in range(frames):
    if not writer.is_done("s0", t, 1):
        buffers, _ = synthetic_frame(4, 4, t, 1, seed=0)
        writer.write_frame("s0", t, 1, buffers, seconds=0.001)
        print(t, flush=True)
"""


def _child(out: Path, frames: int) -> subprocess.Popen:
    code = CHILD.replace("SCENE_RECORD", repr(CHILD_SCENE))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    return subprocess.Popen(
        [sys.executable, "-c", code, str(out), str(frames)], stdout=subprocess.PIPE, text=True, env=env
    )


def test_an_old_version_1_dataset_opens_reads_and_keeps_its_hash():
    ds = open_dataset(V1, verify=True)
    assert ds.manifest["schema_version"] == 1 and ds.complete
    assert ds.scenes == ["synthetic_000", "synthetic_001"]
    frame = ds.frame("synthetic_001", 2, 1)
    assert frame.color.shape == (8, 8, 3) and frame.reference.shape == (8, 8, 3)
    assert set(ds.scene("synthetic_000").record["renders"]) == {"spp0001", "spp0002", "reference"}
    assert dataset_hash(ds) == V1_HASH


def test_resuming_a_version_1_dataset_migrates_it_without_rendering_again(tmp_path):
    out = tmp_path / "v1"
    shutil.copytree(V1, out)
    before = manifest_without_timings(out / layout.MANIFEST_NAME)
    exr = {p: p.stat().st_mtime_ns for p in out.rglob("*.exr")}
    make_synthetic_dataset(out, scenes=2, frames=2, height=8, width=8, spp=(1, 2), ref_spp=64)  # resumes
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.exr")} == exr  # nothing written again
    header = load_header(out / layout.MANIFEST_NAME)
    assert header["schema_version"] == 2 and "renders" not in header["scenes"]["synthetic_000"]
    assert header["frame_records"] == {"store": "sqlite", "file": layout.INDEX_NAME, "count": 12}
    after = manifest_without_timings(out / layout.MANIFEST_NAME)
    assert {k: v for k, v in after.items() if k not in ("schema_version", "frame_records")} == {
        k: v for k, v in before.items() if k != "schema_version"
    }


def test_content_hash_streams_the_same_text_as_the_whole_manifest(tmp_path):
    out = make_synthetic_dataset(tmp_path / "ds", scenes=3, frames=2, height=4, width=4, spp=(1,), ref_spp=4)
    whole = canonical_json(manifest_without_timings(load_manifest(out / layout.MANIFEST_NAME)))
    assert open_dataset(out).content_hash() == hashlib.sha256(whole.encode()).hexdigest()


def test_dataset_json_is_not_rewritten_per_frame(tmp_path):
    writer = DatasetWriter(tmp_path / "ds", {"k": 1})
    writer.add_scenes({name: SCENE for name in ("a", "b", "c")})
    manifest = tmp_path / "ds" / layout.MANIFEST_NAME
    inode = manifest.stat().st_ino  # an atomic rewrite is a new file (rename): a new inode
    for scene in ("a", "b", "c"):
        for t in range(SCENE["frames"]):
            buffers, ref = synthetic_frame(4, 4, t, 1, seed=0)
            writer.write_frame(scene, t, 1, buffers, seconds=0.001)
            writer.write_reference(scene, t, ref, np.full(ref.shape, 1e-6, np.float32), seconds=0.01)
    assert manifest.stat().st_ino == inode
    assert writer.missing() == []
    writer.finalize({"test": ["a", "b", "c"]})
    header = json.loads(manifest.read_text())
    assert header["complete"] and header["frame_records"]["count"] == 3 * 2 * SCENE["frames"]
    assert not any(Path(f"{tmp_path / 'ds' / layout.INDEX_NAME}{s}").exists() for s in ("-wal", "-shm"))


def test_kill_9_loses_at_most_the_frame_in_flight_and_resume_gives_the_same_dataset(tmp_path):
    whole = tmp_path / "whole"
    proc = _child(whole, 30)
    assert proc.wait() == 0
    out = tmp_path / "killed"
    proc = _child(out, 30)
    said = [proc.stdout.readline() for _ in range(12)]
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    said += proc.stdout.readlines()  # what it printed before the signal landed
    reported = [int(line) for line in said if line.strip()]
    assert proc.returncode == -signal.SIGKILL and 12 <= len(reported) < 30
    writer = DatasetWriter(out, {"k": 1})
    assert writer.resumed
    writer.add_scene("s0", CHILD_SCENE)
    done = [t for t in range(30) if writer.is_done("s0", t, 1)]
    assert done[: len(reported)] == reported  # every frame it reported is done...
    assert len(done) <= len(reported) + 1  # ...and at most the one in flight besides
    writer.close()
    assert _child(out, 30).wait() == 0
    for name in ("whole", "killed"):
        DatasetWriter(tmp_path / name, {"k": 1}).finalize({"test": ["s0"]})
    assert manifest_without_timings(out / layout.MANIFEST_NAME) == manifest_without_timings(
        whole / layout.MANIFEST_NAME
    )
    for path in whole.rglob("*.exr"):
        assert (out / path.relative_to(whole)).read_bytes() == path.read_bytes()


def test_readers_open_a_dataset_without_reading_its_frame_records(tmp_path):
    out = make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=4, width=4, spp=(1,), ref_spp=4)
    (out / layout.INDEX_NAME).write_bytes(b"not an SQLite file" * 64)
    ds = open_dataset(out)  # the header only: config, scenes, splits
    assert ds.scenes == ["synthetic_000", "synthetic_001"] and ds.scene("synthetic_000", renders=False).frame_count == 2
    with pytest.raises(DatasetError, match=r"dataset\.sqlite"):
        ds.frame("synthetic_000", 1, 0)


def test_an_index_that_escapes_the_dataset_folder_is_refused(tmp_path):
    out = make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=1, height=4, width=4, spp=(1,), ref_spp=4)
    outside = tmp_path / "elsewhere.sqlite"
    shutil.move(out / layout.INDEX_NAME, outside)
    os.symlink(outside, out / layout.INDEX_NAME)
    with pytest.raises(DatasetError, match="outside the dataset folder"):
        open_dataset(out)


def test_an_unknown_denoiser_is_refused_before_any_file_is_hashed(tmp_path, capsys, monkeypatch):
    out = make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=8, width=8, spp=(1,), ref_spp=4)
    for path in out.rglob("*.exr"):
        path.write_bytes(b"corrupt")  # hashing them would say "does not match the manifest"
    from denoisebench.dataset import verify

    def no_hashing(path):
        raise AssertionError(f"hashed {path} before the denoiser names were checked")

    monkeypatch.setattr(verify, "file_sha256", no_hashing)
    code = cli.main(
        ["benchmark", "--data", str(out), "--db", str(tmp_path / "b.sqlite"), "--split", "all"]
        + ["--denoisers", "nosuch", "--no-report"]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "unknown denoiser 'nosuch'" in err[-1]
    assert not (tmp_path / "b.sqlite").exists() or _unit_count(tmp_path / "b.sqlite") == 0


def _unit_count(db: Path) -> int:
    import sqlite3

    with sqlite3.connect(db) as conn:
        try:
            return conn.execute("SELECT COUNT(*) FROM units").fetchone()[0]
        except sqlite3.OperationalError:
            return 0


def test_a_metric_that_cannot_apply_is_recorded_as_such_and_the_frame_keeps_its_other_metrics(tmp_path):
    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.results.store import ResultsStore

    out = make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=2, height=8, width=8, spp=(1,), ref_spp=4)
    config = BenchmarkConfig(denoisers=["identity"], spp=[1], split="all", metrics=["relmse", "ssim", "psnr"])
    with ResultsStore(tmp_path / "b.sqlite") as store:
        plan = run_benchmark(open_dataset(out), config, store, progress=False)
        assert {u.status for u in store.units(plan.run_id)} == {"ok"}  # before: every unit failed
        frames = store.frames(plan.run_id)
        assert len(frames) == 2 * 2  # noisy and identity, two frames each
        for row in frames:
            assert {"relmse", "psnr", "flip"} <= set(row.metrics) and "ssim" not in row.metrics
        rows = store.not_applicable(plan.run_id)
        assert {(r.denoiser, r.frame, r.metric) for r in rows} == {
            (label, t, "ssim") for label in ("noisy", "identity") for t in (0, 1)
        }
        assert all("at least 11×11" in r.reason and "8×8" in r.reason for r in rows)
        assert store.not_applicable_summary(plan.run_id)["ssim"].count == 4
    # at 16×16 SSIM applies: nothing is recorded as not applicable, SSIM has values
    big = make_synthetic_dataset(tmp_path / "big", scenes=1, frames=2, height=16, width=16, spp=(1,), ref_spp=4)
    with ResultsStore(tmp_path / "c.sqlite") as store:
        plan = run_benchmark(open_dataset(big), config, store, progress=False)
        assert store.not_applicable(plan.run_id) == []
        assert all(0.0 < row.metrics["ssim"] <= 1.0 for row in store.frames(plan.run_id))
