"""generate-dataset end to end: real Mitsuba renders written, resumed after SIGKILL, and on Ray.

Everything renders at 24×16 (non-square, so row/column mix-ups show), 3 frames, spp 1,2 and a
16-spp reference: the same kernel shapes in every test, so Dr.Jit compiles them once per machine.
The uninterrupted local run (``local_dataset``) is the peer of the interrupted run and of Ray.
"""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from denoisebench.cli import main
from denoisebench.dataset import layout, manifest_without_timings, open_dataset
from denoisebench.dataset.atomic import is_temporary
from denoisebench.dataset.manifest import assign_splits, reference_quality

WIDTH, HEIGHT, FRAMES = 24, 16, 3
ARGS = [
    "--families",
    "cornell",
    "--scenes",
    "2",
    "--frames",
    str(FRAMES),
    "--width",
    str(WIDTH),
    "--height",
    str(HEIGHT),
    "--spp",
    "1,2",
    "--ref-spp",
    "16",
    "--seed",
    "5",
    "--quiet",
]
from tests.support.paths import REPO  # noqa: E402


def _generate(out: Path, *extra: str) -> int:
    return main(["generate", "--out", str(out), *ARGS, *extra])


def _file_hashes(root: Path) -> dict[str, str]:
    """sha256 of every EXR and stage file under ``root`` (relative paths)."""
    import hashlib

    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name not in (layout.MANIFEST_NAME, layout.INDEX_NAME)  # the index: by content
    }


def _assert_same_dataset(a: Path, b: Path) -> None:
    assert _file_hashes(a) == _file_hashes(b)
    assert manifest_without_timings(a / layout.MANIFEST_NAME) == manifest_without_timings(b / layout.MANIFEST_NAME)


@pytest.fixture(scope="module")
def local_dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("local") / "ds"
    assert _generate(out) == 0
    return out


def test_layout_manifest_and_reader(local_dataset):
    ds = open_dataset(local_dataset, verify=True)
    assert ds.complete
    assert ds.scenes == ["cornell_005", "cornell_006"]  # family + scene seed (--seed 5, 2 scenes)
    assert ds.splits == assign_splits(ds.scenes, 5)
    for name in ds.scenes:
        info = ds.scene(name)
        assert (info.frame_count, info.width, info.height, info.spp, info.ref_spp) == (
            FRAMES,
            WIDTH,
            HEIGHT,
            [1, 2],
            16,
        )
        assert (local_dataset / info.usd).is_file()
        assert info.plan["pixel_filter"] == "box"
        for index in range(FRAMES):
            for spp in (1, 2):
                record = info.record["renders"][layout.spp_key(spp)][layout.frame_key(index)]
                assert record["seconds"] >= 0 and record["seconds_per_spp"] == pytest.approx(record["seconds"] / spp)
                assert (local_dataset / layout.noisy_path(name, spp, index)).is_file()
            frame = ds.frame(name, 2, index)
            assert frame.color.dtype == np.float32 and frame.color.shape == (HEIGHT, WIDTH, 3)
            assert frame.reference.shape == (HEIGHT, WIDTH, 3)
            for buffer in ("albedo", "normal", "depth", "position", "roughness", "motion", "color_var"):
                assert np.isfinite(frame.buffers[buffer]).all(), buffer


def test_frames_follow_the_camera_and_streams_are_independent(local_dataset):
    from denoisebench.generator.usd.translate import translate_usd

    ds = open_dataset(local_dataset)
    name = ds.scenes[0]
    camera = translate_usd(local_dataset / ds.scene(name).usd).camera
    refs = []
    for index in range(FRAMES):
        record = ds.scene(name).record["renders"]["spp0001"][layout.frame_key(index)]
        np.testing.assert_allclose(record["camera_pose"], camera.poses[index])
        frame1, frame2 = ds.frame(name, 1, index), ds.frame(name, 2, index)
        # Different spp and the reference draw different random numbers: no two images coincide.
        assert not np.array_equal(frame1.color, frame2.color)
        assert not np.array_equal(frame2.color, frame2.reference)
        refs.append(frame2.reference)
        moving = np.abs(frame2.buffers["motion"]).max()
        assert (moving == 0) if index == 0 else (moving > 0)  # frame 0 has no previous frame
    assert camera.is_animated and not np.array_equal(refs[0], refs[-1])


def test_noisy_inputs_are_unbiased_estimates_of_the_reference(local_dataset):
    """Energy: over the frame, the noisy mean agrees with the reference within its standard error."""
    ds = open_dataset(local_dataset)
    for name in ds.scenes:
        for frame in ds.frames(name, 2):
            ref = frame.meta["reference_buffers"]
            n = frame.color.size
            se = np.sqrt(frame.buffers["color_var"].sum() + ref["color_var"].sum()) / n
            assert abs(frame.color.mean() - frame.reference.mean()) < 5 * se + 1e-6


def test_reference_quality_is_recorded_and_flagged(local_dataset):
    ds = open_dataset(local_dataset)
    for name in ds.scenes:
        renders = ds.scene(name).record["renders"]
        for key, ref in renders[layout.REFERENCE].items():
            noisy = [renders[s][key]["rel_se"] for s in ("spp0001", "spp0002")]
            assert noisy[0] is None  # one sample: no variance estimate (unknown, not "less noisy")
            assert ref["noisy_rel_se_max"] == noisy[1]
            assert ref["reference_too_noisy"] == reference_quality(noisy, ref["rel_se"])
            # rel_se falls as 1/sqrt(spp): 2 → 16 spp is sqrt(8) ≈ 2.8× less, short of the required 4×.
            assert 1.5 < renders["spp0002"][key]["rel_se"] / ref["rel_se"] < 6.0
            assert ref["reference_too_noisy"] is True


def test_sigkill_then_rerun_gives_the_bytes_of_an_uninterrupted_run(local_dataset, tmp_path):
    out = tmp_path / "killed"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen(
        [sys.executable, "-m", "denoisebench.cli", "generate", "--out", str(out), *ARGS],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    manifest_path = out / layout.MANIFEST_NAME
    deadline = time.monotonic() + 120
    killed_with = None
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            written = 0
            if (out / layout.INDEX_NAME).is_file():  # frame records are committed there, one transaction each
                try:
                    db = sqlite3.connect(f"{(out / layout.INDEX_NAME).as_uri()}?mode=ro", uri=True)
                    written = db.execute("SELECT COUNT(*) FROM frames").fetchone()[0]
                    db.close()
                except sqlite3.Error:
                    written = 0
            if written >= 1:
                proc.send_signal(signal.SIGKILL)
                killed_with = written
                break
            time.sleep(0.005)
    finally:
        if proc.poll() is None and killed_with is None:
            proc.kill()
        proc.wait()
    assert killed_with is not None, "the run ended before it could be killed"
    assert proc.returncode == -signal.SIGKILL
    state = json.loads(manifest_path.read_text())
    assert not state["complete"], "killed after the last write: nothing left to resume"
    # What a kill between writing a temporary and renaming it leaves behind.
    stale = out / "cornell_006" / "spp0002" / ".frame_0002.exr.999999.tmp"
    stale.parent.mkdir(parents=True, exist_ok=True)
    stale.write_bytes(b"partial")

    assert _generate(out) == 0
    assert not [p for p in out.rglob("*") if is_temporary(p)]
    _assert_same_dataset(local_dataset, out)


def test_ray_executor_gives_the_same_bytes(local_dataset, tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        assert _generate(tmp_path / "ray", "--executor", "ray") == 0
    finally:
        ray.shutdown()
    _assert_same_dataset(local_dataset, tmp_path / "ray")


def test_config_change_is_refused_unless_forced(local_dataset, tmp_path, capsys):
    out = tmp_path / "ds"
    (out / "keep.txt").parent.mkdir(parents=True)
    (out / "keep.txt").write_text("mine")
    # a folder with the user's own file is not a dataset: written into only with --force, beside the file
    assert main(["generate", "--out", str(out), *ARGS[:-1], "--frames", "1", "--quiet", "--force"]) == 0
    assert (out / "keep.txt").read_text() == "mine"
    capsys.readouterr()
    before = (out / layout.MANIFEST_NAME).read_bytes()
    assert _generate(out) == 2
    err = capsys.readouterr().err
    assert "different config" in err and "--force" in err and len(err.strip().splitlines()) <= 2
    assert (out / layout.MANIFEST_NAME).read_bytes() == before
    assert _generate(out, "--force") == 0
    assert (out / "keep.txt").read_text() == "mine"  # only the old dataset's scene folders go
    (out / "keep.txt").unlink()
    _assert_same_dataset(local_dataset, out)  # forced over an old dataset = made from scratch


@pytest.mark.parametrize(
    "args, message",
    [
        (["--families", "no_such_family"], "no_such_family"),
        (["--spp", "1,x"], "--spp"),
        (["--spp", "0"], "--spp"),
        (["--width", "0"], "--width"),
        (["--ref-error", "-1"], "--ref-error"),
        (["--ref-error", "nan"], "--ref-error"),
        (["--max-depth", "0"], "--max-depth"),
        (["--usd", "missing.usda"], "missing.usda"),
        (["--usd", "{bad}"], "cannot open"),
        (["--usd", "{nocam}"], "camera"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_writes_nothing(tmp_path, capsys, args, message):
    bad = tmp_path / "bad.usda"
    bad.write_text("#usda 1.0\ndef Xform \"A\" {\n  this is not usd\n")
    nocam = tmp_path / "nocam.usda"
    nocam.write_text('#usda 1.0\ndef Sphere "Ball"\n{\n    double radius = 1\n}\n')
    args = [a.format(bad=bad, nocam=nocam) for a in args]
    out = tmp_path / "out"
    assert (
        main(["generate", "--out", str(out), "--frames", "1", "--width", "8", "--height", "8", "--quiet", *args]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and len(err.splitlines()) == 1 and message in err
    assert not out.exists()


def test_user_usd_renders_along_its_own_camera_with_its_textures(tmp_path):
    from denoisebench.scenes import get_family

    shot = tmp_path / "shot"
    get_family("texture_checker").author(shot, seed=2, frames=2, width=WIDTH, height=HEIGHT)
    (shot / "scene.usda").rename(shot / "my shot.usda")
    out = tmp_path / "ds"
    code = main(
        [
            "generate",
            "--out",
            str(out),
            "--usd",
            str(shot / "my shot.usda"),
            "--frames",
            "5",
            "--width",
            str(WIDTH),
            "--height",
            str(HEIGHT),
            "--spp",
            "1,2",
            "--ref-spp",
            "16",
            "--quiet",
        ]
    )
    assert code == 0
    ds = open_dataset(out, verify=True)
    assert ds.scenes == ["usd_my_shot"]
    info = ds.scene("usd_my_shot")
    assert info.frame_count == 2  # the stage's own time samples, not --frames
    textures = sorted(p.name for p in (shot / "textures").glob("*.png"))
    assert textures and sorted(p.name for p in (out / "usd_my_shot" / "textures").glob("*.png")) == textures
    assert {f"textures/{t}" for t in textures} <= set(info.record["stage_files"])
    assert info.record["family"] == "usd" and not info.record["warnings"]
    assert ds.frame("usd_my_shot", 2, 1).reference.std() > 0  # textured, lit, not blank


def test_a_failing_frame_is_reported_others_carry_on_and_a_rerun_completes(
    local_dataset, tmp_path, monkeypatch, capsys
):
    from denoisebench.generator import executors

    real = executors.render_job

    def flaky(job, stage_files=None):
        if (job.scene, job.frame) == ("cornell_006", 1):
            raise RuntimeError("simulated renderer crash\nwith a second line")
        return real(job, stage_files)

    monkeypatch.setattr(executors, "render_job", flaky)
    out = tmp_path / "ds"
    assert _generate(out) == 1
    err = capsys.readouterr().err
    assert "cornell_006 frame 1: RuntimeError: simulated renderer crash" in err and "second line" not in err
    ds = open_dataset(out)
    assert not ds.complete
    assert ds.frame("cornell_006", 2, 2).color.shape == (HEIGHT, WIDTH, 3)  # later frames were rendered
    monkeypatch.setattr(executors, "render_job", real)
    assert _generate(out) == 0
    _assert_same_dataset(local_dataset, out)


def test_per_sample_data_matches_the_pixel_means(tmp_path):
    out = tmp_path / "ds"
    code = main(
        [
            "generate",
            "--out",
            str(out),
            "--families",
            "cornell",
            "--frames",
            "2",
            "--width",
            str(WIDTH),
            "--height",
            str(HEIGHT),
            "--spp",
            "2",
            "--ref-spp",
            "16",
            "--samples",
            "--quiet",
        ]
    )
    assert code == 0
    frame = open_dataset(out, verify=True).frame("cornell_000", 2, 1)
    assert frame.samples["pixel"].shape == (2, HEIGHT, WIDTH, 2)
    assert "lens" not in frame.samples and "time" not in frame.samples  # no depth of field, no motion blur
    assert ((frame.samples["pixel"] >= 0) & (frame.samples["pixel"] < 1)).all()
    np.testing.assert_allclose(frame.samples["color"].mean(axis=0), frame.color, rtol=1e-5, atol=1e-6)


def test_adaptive_reference_stops_at_target_or_names_capped_frames(tmp_path, capsys):
    """A loose --ref-error stops after the fewest rounds with the floor recorded; an unreachable one
    runs to the --ref-spp cap and the warning names every such frame."""
    from denoisebench.generator.render.reference import MIN_ROUNDS, round_schedule

    base = [
        "--families",
        "cornell",
        "--frames",
        "2",
        "--width",
        str(WIDTH),
        "--height",
        str(HEIGHT),
        "--spp",
        "1",
        "--seed",
        "5",
        "--quiet",
    ]
    assert main(["generate", "--out", str(tmp_path / "loose"), *base, "--ref-spp", "64", "--ref-error", "10"]) == 0
    assert "cap" not in capsys.readouterr().err
    round_spp, _ = round_schedule(64)
    for record in open_dataset(tmp_path / "loose").scene("cornell_005").record["renders"][layout.REFERENCE].values():
        adaptive = record["reference_adaptive"]
        assert record["spp"] == adaptive["spp"] == MIN_ROUNDS * round_spp and adaptive["rounds"] == MIN_ROUNDS
        assert (
            adaptive["floor"] <= 10 and not adaptive["stopped_at_cap"] and adaptive["floor_pooled"] <= adaptive["floor"]
        )
    from denoisebench.reports.build import _reference_info

    loose = open_dataset(tmp_path / "loose")
    described = _reference_info(loose, loose.scenes).description  # the report's reference line
    assert (
        described.startswith(f"adaptive {MIN_ROUNDS * round_spp} spp (cap 64), noise floor")
        and "full transport" in described
    )
    assert main(["generate", "--out", str(tmp_path / "tight"), *base, "--ref-spp", "16", "--ref-error", "1e-9"]) == 0
    err = capsys.readouterr().err
    assert "2 reference(s) stopped at the --ref-spp cap" in err and "cornell_005/0000, cornell_005/0001" in err
    manifest = json.loads((tmp_path / "tight" / layout.MANIFEST_NAME).read_text())
    assert manifest["config"]["ref_error"] == 1e-9 and manifest["scenes"]["cornell_005"]["plan"]["max_depth"] == -1
    assert manifest["scenes"]["cornell_005"]["transport"].startswith("full transport")


def test_stage_folders_of_dead_workers_are_swept_and_live_ones_kept(tmp_path):
    """A Ray worker killed at shutdown runs no atexit: its materialised stage folder would stay in the
    temporary directory for good. The next worker sweeps folders whose pid is gone."""
    from denoisebench.generator.frame_jobs import sweep_stale_stage_dirs

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    stale = tmp_path / f"denoisebench-stage-0123456789ab-{dead_pid}-x1y2z3"
    live = tmp_path / f"denoisebench-stage-0123456789ab-{os.getpid()}-a1b2c3"
    other = tmp_path / "denoisebench-stage-not-a-worker-folder"
    for folder in (stale, live, other):
        folder.mkdir()
        (folder / "scene.usda").write_text("#usda 1.0\n")
    assert sweep_stale_stage_dirs(tmp_path) == 1
    assert not stale.exists() and live.exists() and other.exists()
