"""SIGINT and SIGTERM stop ``generate`` and ``benchmark`` within 2 s, exit 130, resumable to the same results.

Each command is interrupted at three points of its work (for ``generate`` one of them on a cold
Dr.Jit kernel cache: Dr.Jit keeps it in ``$HOME/.drjit``, so an empty HOME makes it cold), each
interrupted run resuming the previous one; the last run completes, and what it holds must equal
an uninterrupted run's: the same EXR bytes for the dataset, the same metric values for the store.
No run may report a failed frame or unit because of the interrupt.
"""

from __future__ import annotations

import re
import signal
import sqlite3
from pathlib import Path

import pytest

from denoisebench.cli import main
from denoisebench.interrupts import EXIT_INTERRUPTED, GRACE_SECONDS
from tests.support.signals import signalled

#: The issue's bound on the time from a signal to the exit.
STOP_SECONDS = 2.0

#: Four frames whose reference (16², 4096 spp: 1M samples) takes about 0.3 s on a fast core, so a
#: signal sent on a file count (polled every 20 ms) lands while frames are left to render. Pitfall:
#: at 64 spp the whole dataset rendered in 0.12 s on CI and the third run found it finished.
FRAMES = 4
GENERATE = ["--families", "cornell", "--frames", str(FRAMES), "--width", "16", "--height", "16", "--spp", "1,4"]
GENERATE += ["--ref-spp", "4096", "--ref-error", "0"]
#: One EXR per spp rung and one reference per frame.
ALL_EXR = FRAMES * 3


def _exr_bytes(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*.exr"))}


def _exr_count(out: Path) -> int:
    return sum(1 for _ in out.rglob("*.exr")) if out.is_dir() else 0


def _check_stopped(run) -> None:
    assert run.sent, f"the command ended before the signal:\n{run.output[-2000:]}"
    assert run.returncode == EXIT_INTERRUPTED, run.output[-2000:]
    assert run.seconds_to_exit < STOP_SECONDS, f"{run.seconds_to_exit:.2f} s from the signal to the exit"
    assert not re.search(r"\b[1-9]\d* failed|failed on|^failed:|^error:", run.output, re.M), run.output[-2000:]


def test_grace_is_below_the_bound():
    assert GRACE_SECONDS < STOP_SECONDS - 0.5  # room for the process to end after the watchdog fires


def test_generate_interrupted_three_times_resumes_to_the_same_bytes(tmp_path):
    plain = tmp_path / "plain"
    assert main(["generate", "--out", str(plain), *GENERATE, "--quiet"]) == 0
    out = tmp_path / "out"
    args = ["generate", "--out", str(out), *GENERATE]
    cold = tmp_path / "home"
    cold.mkdir()
    # 1: as soon as the dataset exists (its scene being authored, the first kernels compiling), cold cache
    first = signalled(args, lambda _: (out / "dataset.json").exists(), env={"HOME": str(cold)})
    _check_stopped(first)
    # 2: after the first frame file, SIGINT; 3: halfway, SIGTERM
    second = signalled(args, lambda _: _exr_count(out) >= 1)
    _check_stopped(second)
    assert _exr_count(out) < ALL_EXR // 2, "the second run rendered past halfway before its signal"
    third = signalled(args, lambda _: _exr_count(out) >= ALL_EXR // 2, signum=signal.SIGTERM)
    _check_stopped(third)
    assert _exr_count(out) < ALL_EXR, "the third run finished before its signal: no interrupt was tested"
    assert main(args + ["--quiet"]) == 0
    assert _exr_bytes(out) == _exr_bytes(plain)
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("interrupts") / "ds"
    args = ["generate", "--out", str(out), "--families", "cornell,glossy_fireflies", "--frames", "2"]
    args += ["--width", "16", "--height", "16", "--spp", "1,4", "--ref-spp", "64", "--ref-error", "0", "--quiet"]
    assert main(args) == 0
    return out


def _metrics(db: Path) -> list[tuple]:
    with sqlite3.connect(db) as con:
        return con.execute(
            "SELECT denoiser, scene, spp, frame, metric, value FROM frame_metrics "
            "ORDER BY denoiser, scene, spp, frame, metric"
        ).fetchall()


def _units(db: Path) -> int:
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as con:
            return con.execute("SELECT count(*) FROM units").fetchone()[0]
    except sqlite3.Error:
        return 0


def test_benchmark_interrupted_three_times_resumes_to_the_same_metrics(dataset, tmp_path):
    common = ["--data", str(dataset), "--split", "all", "--denoisers", "identity", "--metrics", "relmse"]
    common += ["--time-size", "none", "--no-render-probe"]
    plain_db = tmp_path / "plain.sqlite"
    assert main(["benchmark", *common, "--db", str(plain_db), "--no-report"]) == 0
    db, report = tmp_path / "run.sqlite", tmp_path / "report"
    args = ["benchmark", *common, "--db", str(db), "--out", str(report)]
    # 1: as soon as the store exists (the dataset's files being verified, denoisers loading)
    _check_stopped(signalled(args, lambda _: db.exists()))
    # 2: after the first unit, SIGTERM
    _check_stopped(signalled(args, lambda _: _units(db) >= 1, signum=signal.SIGTERM))
    # 3: once the units are measured (the report being written)
    _check_stopped(signalled(args, lambda text: " units in " in text))
    assert main(args) == 0
    assert _metrics(db) == _metrics(plain_db)
    assert (report / "index.html").is_file()
