"""run-benchmark against the SQLite store: concurrent writers, a killed run and its resume, bad datasets.

These run the real command in subprocesses on a tiny synthetic dataset (16×16, 3 frames).
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from denoisebench.benchmark.measure import kept_images
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.results.records import FrameRecord, UnitRecord
from denoisebench.results.schema import SCHEMA_VERSION
from denoisebench.results.store import ResultsStore

FRAMES = 3


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    # 4 scenes → one test scene; 2 spp
    return make_synthetic_dataset(
        tmp_path_factory.mktemp("ds") / "ds", scenes=4, frames=FRAMES, height=16, width=16, spp=(1, 4)
    )


@pytest.fixture(scope="module")
def plugins(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("plugins")
    (folder / "plugins.py").write_text(
        textwrap.dedent(
            """
        import time
        import numpy as np

        class Slow:
            name = "slow"
            needs = frozenset({"color"})
            temporal = False
            def reset(self):
                pass
            def denoise(self, frame):
                time.sleep(0.25)
                return np.array(frame.color, dtype=np.float32)

        class Broken:
            name = "broken"
            def denoise(self, frame):
                raise RuntimeError("kaboom")
        """
        )
    )
    return folder


def _command(dataset: Path, db: Path, *extra: str) -> list[str]:
    return [
        sys.executable,
        "-m",
        "denoisebench.cli",
        "benchmark",
        "--time-size",
        "64x64",
        "--data",
        str(dataset),
        "--db",
        str(db),
        "--metrics",
        "relmse",
        "--no-report",
        *extra,
    ]


def _env(plugins: Path | None = None) -> dict:
    env = dict(os.environ)
    if plugins is not None:
        env["PYTHONPATH"] = f"{plugins}{os.pathsep}{env.get('PYTHONPATH', '')}"
    return env


def _counts(db: Path) -> dict:
    with ResultsStore(db, readonly=True) as store:
        problems = store.integrity_problems()
        runs = store.runs()
        return {
            "problems": problems,
            "runs": {r.run_id: (len(store.units(r.run_id)), len(store.frames(r.run_id))) for r in runs},
            "finished": {r.run_id: r.finished_at is not None for r in runs},
            "metric_rows": store.conn.execute("SELECT COUNT(*) FROM frame_metrics").fetchone()[0],
        }


def test_two_processes_writing_one_database_lose_no_rows(dataset, tmp_path):
    db = tmp_path / "shared.sqlite"
    # two processes on the same run (they race for the same units) and a third on another run
    same = _command(dataset, db, "--denoisers", "identity,cross_bilateral_fast")
    other = _command(dataset, db, "--denoisers", "nlmeans", "--spp", "4")
    procs = [
        subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
        for cmd in (same, same, other)
    ]
    outputs = [p.communicate(timeout=300) for p in procs]
    for proc, (out, err) in zip(procs, outputs):
        assert proc.returncode == 0, err
    counts = _counts(db)
    assert counts["problems"] == []
    units_same = 3 * 1 * 2  # (noisy, identity, cross_bilateral_fast) × 1 test scene × 2 spp
    units_other = 2 * 1 * 1  # (noisy, nlmeans) × 1 scene × 1 spp
    assert sorted(counts["runs"].values()) == sorted(
        [(units_other, units_other * FRAMES), (units_same, units_same * FRAMES)]
    )
    assert all(counts["finished"].values())
    # relmse_robust, relmse and flip (always) per frame, three flicker scores (temporal_relmse_robust,
    # temporal_relmse, tpsnr) on frames 1.. : nothing lost, nothing doubled
    expected_metrics = (units_same + units_other) * (3 * FRAMES + 3 * (FRAMES - 1))
    assert counts["metric_rows"] == expected_metrics


def test_killed_run_leaves_a_consistent_database_and_a_rerun_completes_it(dataset, plugins, tmp_path):
    db = tmp_path / "killed.sqlite"
    cmd = _command(dataset, db, "--denoisers", "identity", "--denoiser", "plugins:Slow")
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=_env(plugins))
    try:
        deadline = time.monotonic() + 120
        written = 0
        while time.monotonic() < deadline and written < 2:
            time.sleep(0.2)
            if db.exists():
                try:
                    with sqlite3.connect(db, timeout=5) as conn:
                        written = conn.execute("SELECT COUNT(*) FROM units").fetchone()[0]
                except sqlite3.OperationalError:
                    written = 0  # schema not there yet
        assert proc.poll() is None, "the run finished before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)  # no clean-up handlers run
    finally:
        proc.wait(timeout=30)
    before = _counts(db)
    assert before["problems"] == []
    ((run_id, (units, frames)),) = before["runs"].items()
    total = 3 * 1 * 2  # (noisy, identity, slow) × 1 scene × 2 spp
    assert 2 <= units < total and frames == units * FRAMES
    assert before["finished"][run_id] is False

    rerun = subprocess.run(cmd, capture_output=True, text=True, env=_env(plugins), timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert "resumed" in rerun.stdout
    after = _counts(db)
    assert after["problems"] == []
    assert after["runs"] == {run_id: (total, total * FRAMES)}
    assert after["finished"][run_id] is True


def test_failing_denoiser_is_recorded_and_the_run_goes_on(dataset, plugins, tmp_path):
    db = tmp_path / "broken.sqlite"
    cmd = _command(dataset, db, "--denoisers", "identity", "--denoiser", "plugins:Broken", "--spp", "1")
    result = subprocess.run(cmd, capture_output=True, text=True, env=_env(plugins), timeout=300)
    assert result.returncode == 3, result.stderr  # the run completed with failed units: the broken plugin's only
    assert "broken failed" in result.stderr and "kaboom" in result.stderr
    with ResultsStore(db, readonly=True) as store:
        (run,) = store.runs()
        units = {u.denoiser: u for u in store.units(run.run_id)}
        assert {name for name, u in units.items() if u.status != "ok"} == {"broken"}
        assert units["broken"].status == "failed" and "RuntimeError: kaboom" in units["broken"].error
        assert units["identity"].status == "ok" and units["noisy"].status == "ok"
        frames = [f for f in store.frames(run.run_id) if f.denoiser == "broken"]
        assert len(frames) == FRAMES and all(f.status == "failed" and not f.metrics for f in frames)


def test_missing_reference_is_a_clear_error_naming_the_frame(tmp_path):
    data = make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=FRAMES, height=16, width=16, spp=(1,))
    missing = data / "synthetic_000" / "reference" / "frame_0001.exr"
    missing.unlink()
    db = tmp_path / "r.sqlite"
    result = subprocess.run(
        _command(data, db, "--denoisers", "identity"), capture_output=True, text=True, env=_env(), timeout=120
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert "synthetic_000" in lines[0] and "frame 1" in lines[0] and str(missing) in lines[0]
    assert "Traceback" not in result.stderr
    # nothing was measured
    if db.exists():
        assert _counts(db)["runs"] == {}


def test_split_all_scores_every_scene_of_the_dataset(dataset, tmp_path):
    # the demo's benchmark-only dataset: --split all covers the 4 scenes, --split test only its one
    db = tmp_path / "all.sqlite"
    for split in ("all", "test"):
        result = subprocess.run(
            _command(dataset, db, "--denoisers", "identity", "--spp", "1", "--split", split),
            capture_output=True,
            text=True,
            env=_env(),
            timeout=300,
        )
        assert result.returncode == 0, result.stderr
    with ResultsStore(db, readonly=True) as store:
        scenes = {run.config["split"]: {u.scene for u in store.units(run.run_id)} for run in store.runs()}
    assert len(scenes["all"]) == 4 and len(scenes["test"]) == 1 and scenes["test"] < scenes["all"]


def test_scores_on_a_denoisers_own_training_scenes_are_marked_not_held_out(tmp_path, capsys):
    """A learned denoiser scored on scenes it was trained on (same name: same family and seed, the same stage)
    looks better than it is: the run warns, the store records those scenes and the report marks them. The
    built-in models read their train scenes from the checkpoint; a plugin declares ``trained_scenes``
    (here from its isolated worker process)."""
    from denoisebench.cli import main
    from denoisebench.dataset import open_dataset

    data = make_synthetic_dataset(tmp_path / "ds", scenes=4, frames=2, height=16, width=16, spp=(2,))
    ck = tmp_path / "dpcn.pt"
    assert (
        main(
            [
                "train",
                "--model",
                "dpcn",
                "--data",
                str(data),
                "--steps",
                "1",
                "--out",
                str(ck),
                "--batch-size",
                "2",
                "--crop",
                "8",
                "--quiet",
            ]
        )
        == 0
    )
    ds = open_dataset(data)
    train_scenes, test_scene = ds.split("train"), ds.split("test")[0]
    plugin = tmp_path / "memoriser.py"
    plugin.write_text(
        textwrap.dedent(f"""
        import numpy as np
        class Memoriser:
            name = "memoriser"
            trained_scenes = frozenset({{{test_scene!r}, "a_scene_of_another_dataset"}})
            def denoise(self, frame):
                return np.array(frame.color, dtype=np.float32)
        """)
    )
    db, out = tmp_path / "b.sqlite", tmp_path / "report"
    capsys.readouterr()
    assert (
        main(
            [
                "benchmark",
                "--time-size",
                "64x64",
                "--data",
                str(data),
                "--db",
                str(db),
                "--out",
                str(out),
                "--metrics",
                "relmse",
                "--split",
                "all",
                "--denoisers",
                f"identity,dpcn,{plugin}:Memoriser",
                "--option",
                f"dpcn:checkpoint={ck}",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert f"warning: dpcn was trained on {len(train_scenes)} of this run's 4 scene(s)" in err
    assert f"warning: memoriser was trained on 1 of this run's 4 scene(s) ({test_scene})" in err
    assert "warning: identity" not in err
    with ResultsStore(db, readonly=True) as store:
        (run,) = store.runs()
        declared = {d.label: d.trained_on for d in store.denoisers(run.run_id)}
    assert declared["dpcn"] == sorted(train_scenes) and declared["memoriser"] == [test_scene]
    assert declared["identity"] == [] and declared["noisy"] == []
    html, md = (
        (out / "index.html").read_text(),
        (out / "report.md").read_text().replace("\\_", "_"),
    )  # Markdown escapes _
    for text in (html, md):
        assert f"memoriser was trained on 1 of the 4 scene(s) scored here ({test_scene})" in text
        assert f"dpcn was trained on {len(train_scenes)} of the 4 scene(s)" in text and "not held-out" in text
    # held out: on the test split dpcn saw none of the scenes, and nothing is marked
    capsys.readouterr()
    assert (
        main(
            [
                "benchmark",
                "--time-size",
                "64x64",
                "--data",
                str(data),
                "--db",
                str(db),
                "--out",
                str(tmp_path / "r2"),
                "--metrics",
                "relmse",
                "--denoisers",
                "dpcn",
                "--option",
                f"dpcn:checkpoint={ck}",
            ]
        )
        == 0
    )
    assert "not held-out" not in capsys.readouterr().err + (tmp_path / "r2" / "report.md").read_text()


def _unit_with_images(frames: dict[int, float]) -> UnitRecord:
    records = [
        FrameRecord(
            frame=f,
            status="ok",
            error=None,
            render_seconds=1.0,
            denoise_seconds=0.1,
            total_seconds=1.1,
            sanitized=0,
            metrics={"relmse": v},
        )
        for f, v in frames.items()
    ]
    return UnitRecord(denoiser="d", scene="s", spp=4, status="ok", error=None, frames=records)


def test_a_unit_keeps_its_last_frame_and_the_frames_its_deciding_scores_are_worst_on(tmp_path):
    """Frame 2 is the worst relMSE (kept beside the last frame 3), and the store gives back each kept frame."""
    outputs = [np.full((4, 4, 3), i, np.float32) for i in range(4)]
    unit = _unit_with_images({0: 0.1, 1: 0.2, 2: 9.0, 3: 0.15})
    unit.images = kept_images(unit.frames, outputs)
    assert sorted(unit.images) == [2, 3]
    flip_decides = _unit_with_images({0: 0.1, 1: 0.2, 2: 9.0, 3: 0.15})
    for record, value in zip(flip_decides.frames, (0.9, 0.1, 0.1, 0.1)):
        record.metrics["flip"] = value
    assert sorted(kept_images(flip_decides.frames, outputs)) == [0, 2, 3]
    with ResultsStore(tmp_path / "r.sqlite") as store:
        store.ensure_run("r", dataset_hash="h", dataset_path="/d", config={}, versions={})
        assert store.write_unit("r", unit)
        assert store.image_frames("r", "d", spp=4, scene="s") == [2, 3]
        assert store.image("r", "d", spp=4, scene="s")[0] == 3  # no frame asked: the last
        frame, image = store.image("r", "d", spp=4, scene="s", frame=2)
        assert frame == 2 and np.array_equal(image, outputs[2])
        assert store.image("r", "d", spp=4, scene="s", frame=1) is None


def test_a_version_5_store_migrates_its_images_to_the_frame_key_and_keeps_them(tmp_path):
    path = tmp_path / "old.sqlite"
    with ResultsStore(path) as store:
        store.ensure_run("r", dataset_hash="h", dataset_path="/d", config={}, versions={})
        unit = _unit_with_images({0: 0.1, 1: 0.2})
        unit.images = {1: np.ones((2, 2, 3), np.float32)}
        assert store.write_unit("r", unit)
    with sqlite3.connect(path) as conn:  # the version-5 table: one image per unit
        conn.execute("ALTER TABLE images RENAME TO images_new")
        conn.execute(
            "CREATE TABLE images (run_id TEXT NOT NULL, denoiser TEXT NOT NULL, scene TEXT NOT NULL, spp INTEGER NOT "
            "NULL, frame INTEGER NOT NULL, height INTEGER NOT NULL, width INTEGER NOT NULL, data BLOB NOT NULL, "
            "PRIMARY KEY (run_id, denoiser, scene, spp))"
        )
        conn.execute("INSERT INTO images SELECT * FROM images_new")
        conn.execute("DROP TABLE images_new")
        conn.execute("UPDATE schema_version SET version = 5")
    with ResultsStore(path, readonly=True) as old:
        assert old.version == 5 and old.image("r", "d", spp=4, scene="s")[0] == 1
    with ResultsStore(path) as store:
        assert store.version == SCHEMA_VERSION == 6
        assert store.image_frames("r", "d", spp=4, scene="s") == [1]
        more = _unit_with_images({0: 0.3, 1: 0.2})
        more.scene, more.images = "t", {0: np.zeros((2, 2, 3), np.float32), 1: np.ones((2, 2, 3), np.float32)}
        assert store.write_unit("r", more)
        assert store.image_frames("r", "d", spp=4, scene="t") == [0, 1]
    with sqlite3.connect(path) as conn:
        key = [r[1] for r in conn.execute("PRAGMA table_info(images)") if r[5]]
    assert key == ["run_id", "denoiser", "scene", "spp", "frame"]
