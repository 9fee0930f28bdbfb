"""Untrusted data and outputs: sha256 verification, path confinement,
bounds, writable outputs checked first, CSV formula cells.

Before: a reference scaled ×5 was scored silently under the genuine dataset's hash; a manifest
``file`` of ``/etc/passwd`` or ``../../other/frame.exr`` was opened; a corrupt EXR was found only
mid-run after units were stored; ``--spp 10^12`` grew to 24 GB; ``--out``/``--db`` under a file
ended in a traceback after the whole run was measured; results.csv wrote ``=...`` cells raw.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import time
from pathlib import Path

import pytest

from denoisebench import cli
from denoisebench.dataset import bounds, open_dataset
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.exr_io import encode_exr, load_exr
from denoisebench.dataset.manifest import load_manifest, save_manifest
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.errors import UserInputError
from denoisebench.outputs import check_writable_dir, check_writable_file
from denoisebench.reports.build import csv_cell
from denoisebench.results.store import ResultsStore

REF = "synthetic_000/reference/frame_0000.exr"


@pytest.fixture(scope="module")
def genuine(tmp_path_factory) -> Path:
    return make_synthetic_dataset(tmp_path_factory.mktemp("ds") / "ds", scenes=2, frames=2, height=8, width=8, spp=(1,))


@pytest.fixture()
def dataset(genuine, tmp_path) -> Path:
    copy = tmp_path / "ds"
    shutil.copytree(genuine, copy)
    return copy


def _bench(dataset: Path, db: Path, *extra: str) -> int:
    return cli.main(
        [
            "benchmark",
            "--time-size",
            "64x64",
            "--data",
            str(dataset),
            "--db",
            str(db),
            "--split",
            "all",
            "--metrics",
            "relmse",
            "--denoisers",
            "identity",
            "--no-report",
            *extra,
        ]
    )


def _error_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert err and err[-1].startswith("error: "), err
    return err[-1]


def _units(db: Path) -> int:
    if not db.exists():
        return 0
    with sqlite3.connect(db) as conn:
        try:
            return conn.execute("SELECT COUNT(*) FROM units").fetchone()[0]
        except sqlite3.OperationalError:
            return 0


def _edit_manifest(dataset: Path, edit) -> None:
    path = dataset / "dataset.json"
    manifest = load_manifest(path)  # the whole manifest, frame records from dataset.sqlite included
    edit(manifest)
    save_manifest(path, manifest)


def test_scaled_reference_is_refused_before_the_first_unit_and_no_verify_is_recorded(dataset, tmp_path, capsys):
    contents = load_exr(dataset / REF)
    scaled = {name: (array * 5 if name == "color" else array) for name, array in contents.buffers.items()}
    (dataset / REF).write_bytes(encode_exr(scaled, contents.extra))
    db = tmp_path / "a.sqlite"
    assert _bench(dataset, db) == 2
    line = _error_line(capsys)
    assert REF in line and "does not match the manifest" in line
    assert _units(db) == 0
    # --no-verify runs (and scores the forgery), and the run says it was not verified
    assert _bench(dataset, db, "--no-verify") == 0
    with ResultsStore(db, readonly=True) as store:
        (run,) = store.runs()
        assert run.config["verify"] is False


def test_corrupt_exr_is_found_up_front(dataset, tmp_path, capsys):
    late = dataset / "synthetic_001/spp0001/frame_0001.exr"  # the last scene's last frame
    late.write_bytes(late.read_bytes()[:200])
    db = tmp_path / "b.sqlite"
    assert _bench(dataset, db) == 2
    assert "synthetic_001/spp0001/frame_0001.exr" in _error_line(capsys)
    assert _units(db) == 0  # before: units of synthetic_000 were stored first


@pytest.mark.parametrize("bad", ["/etc/passwd", "../../outside/frame_0000.exr", "synthetic_000/../../x.exr"])
def test_manifest_paths_outside_the_dataset_are_refused(dataset, tmp_path, capsys, bad):
    def edit(manifest):
        manifest["scenes"]["synthetic_000"]["renders"]["reference"]["0000"]["file"] = bad

    _edit_manifest(dataset, edit)
    assert _bench(dataset, tmp_path / "c.sqlite", "--no-verify") == 2
    line = _error_line(capsys)
    assert repr(bad) in line and "refused" in line
    with pytest.raises(DatasetError, match="refused"):
        open_dataset(dataset).frame("synthetic_000", 1, 0)


def test_symlink_escaping_the_dataset_is_refused(dataset, tmp_path, capsys):
    outside = tmp_path / "outside.exr"
    shutil.copy(dataset / REF, outside)
    (dataset / REF).unlink()
    os.symlink(outside, dataset / REF)
    assert _bench(dataset, tmp_path / "d.sqlite", "--no-verify") == 2
    assert "outside the dataset folder" in _error_line(capsys)


def test_forged_frame_count_is_refused_before_any_loop(dataset, tmp_path, capsys):
    _edit_manifest(dataset, lambda m: m["scenes"]["synthetic_000"].update(frames=10**9))
    started = time.monotonic()
    assert _bench(dataset, tmp_path / "e.sqlite") == 2
    assert "out of bounds" in _error_line(capsys) and time.monotonic() - started < 30


@pytest.mark.parametrize(
    "where, option",
    [("file/sub", "--out"), ("file/sub/r.sqlite", "--db"), ("/proc/denoisebench_nope", "--out")],
)
def test_unwritable_outputs_are_exit_2_before_measuring(dataset, tmp_path, capsys, where, option):
    (tmp_path / "file").write_text("not a folder")
    target = where if where.startswith("/") else str(tmp_path / where)
    db = tmp_path / "ok.sqlite" if option == "--out" else Path(target)
    argv = [
        "benchmark",
        "--time-size",
        "64x64",
        "--data",
        str(dataset),
        "--split",
        "all",
        "--denoisers",
        "identity",
        "--metrics",
        "relmse",
        "--db",
        str(db),
        "--out",
        target if option == "--out" else str(tmp_path / "rep"),
    ]
    assert cli.main(argv) == 2
    line = _error_line(capsys)
    assert option in line and "Traceback" not in line
    assert _units(tmp_path / "ok.sqlite") == 0  # nothing was measured


def test_writable_checks_accept_new_folders_and_refuse_files(tmp_path):
    assert check_writable_dir(tmp_path / "a" / "b") == (tmp_path / "a" / "b")
    assert not (tmp_path / "a").exists()  # checking creates nothing
    (tmp_path / "f").write_text("x")
    with pytest.raises(UserInputError, match="is a file"):
        check_writable_dir(tmp_path / "f" / "g")
    with pytest.raises(UserInputError, match="not a folder"):
        check_writable_dir(tmp_path / "f")
    with pytest.raises(UserInputError, match="is a folder"):
        check_writable_file(tmp_path)


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["--spp", "1000000000000"], "--spp at most 1048576"),
        (["--frames", "100000000"], "--frames must be 1..10000"),
        (["--scenes", "100000"], "--scenes must be 1..10000"),
        (["--width", "16384", "--height", "16384"], "pixels per frame"),
        (["--width", "8192", "--height", "8192", "--samples", "--spp", "1024"], "of memory per frame"),
        (["--ref-spp", "100000000"], "--ref-spp at most"),
    ],
)
def test_generate_bounds_are_exit_2_in_a_moment(tmp_path, capsys, argv, fragment):
    started = time.monotonic()
    code = cli.main(["generate", "--out", str(tmp_path / "g"), "--families", "cornell", *argv])
    assert code == 2 and fragment in _error_line(capsys)
    assert time.monotonic() - started < 30 and not (tmp_path / "g").exists()


def test_generate_out_under_a_file_is_exit_2(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    code = cli.main(
        [
            "generate",
            "--out",
            str(tmp_path / "file" / "g"),
            "--families",
            "cornell",
            "--frames",
            "1",
            "--width",
            "8",
            "--height",
            "8",
            "--spp",
            "1",
            "--ref-spp",
            "4",
        ]
    )
    assert code == 2 and "--out" in _error_line(capsys)


def test_memory_estimate_grows_with_per_sample_data():
    plain = bounds.frame_memory_bytes(128, 128, [4], 256, samples=False)
    with_samples = bounds.frame_memory_bytes(128, 128, [4], 256, samples=True)
    assert with_samples - plain >= 128 * 128 * 4 * bounds.SAMPLE_BYTES_PER_SAMPLE  # the top rung's samples, at least
    assert bounds.available_memory() is None or bounds.available_memory() > 0


@pytest.mark.parametrize(
    "value, expected",
    [
        ("=HYPERLINK(\"http://x\")", "'=HYPERLINK(\"http://x\")"),
        ("+1", "'+1"),
        ("-2+3", "'-2+3"),
        ("@SUM(A1)", "'@SUM(A1)"),
        ("\tx", "'\tx"),
        ("\rx", "'\rx"),
        ("cross_bilateral", "cross_bilateral"),
        ("", ""),
        (3, 3),
        (None, None),
    ],
)
def test_csv_cells_that_a_spreadsheet_would_evaluate_are_quoted(value, expected):
    assert csv_cell(value) == expected
