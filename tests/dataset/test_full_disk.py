"""Full disks: generate-dataset and run-benchmark on a small tmpfs stop in one line.

Each test runs the commands inside a private mount namespace (``unshare -m``, root) where a tmpfs
of a few hundred KiB is mounted over a folder of its own; the same namespace then grows the tmpfs
(``mount -o remount,size=``: space freed) and runs the same command again, which resumes.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from denoisebench.dataset.synthetic import make_synthetic_dataset

BIN = Path(sys.executable).parent


def _can_unshare() -> bool:
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    done = subprocess.run(["unshare", "-m", "true"], capture_output=True)
    return done.returncode == 0


pytestmark = pytest.mark.skipif(not _can_unshare(), reason="needs root and `unshare -m` for a private tmpfs")

GENERATE = "--families cornell --scenes 1 --frames 6 --width 32 --height 32 --spp 1,4 --ref-spp 16 --ref-error 0"


def _in_namespace(script: str, timeout: float = 240) -> str:
    """Run ``script`` (sh) in a private mount namespace; its stdout and stderr together."""
    done = subprocess.run(
        ["unshare", "-m", "sh", "-c", f"set -u\n{script}"], capture_output=True, text=True, timeout=timeout
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout + done.stderr


def _exr_hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*.exr"))}


def _lines(output: str, prefix: str) -> list[str]:
    return [line for line in output.splitlines() if line.startswith(prefix)]


def test_generate_refuses_up_front_where_even_the_lower_bound_does_not_fit(tmp_path):
    mount = tmp_path / "small"
    mount.mkdir()
    out = _in_namespace(
        f"mount -t tmpfs -o size=256k none {mount}\n"
        f"{BIN / 'generate-dataset'} --out {mount}/ds --families cornell --scenes 1 --frames 8 --width 256 "
        "--height 256 --spp 1,4 --quiet; echo rc=$?\n"
        f"ls -A {mount} | wc -l | sed 's/^/entries=/'"
    )
    (error,) = _lines(out, "error: ")
    assert "rc=2" in out and "entries=0" in out, out  # exit 2 before rendering; nothing written
    assert f"--out {mount}/ds: the dataset needs at least 18.0 MiB" in error and "256.0 KiB free" in error, error


def test_generate_stops_on_a_full_disk_and_resumes_to_the_same_bytes(tmp_path):
    mount, copy, peer = tmp_path / "small", tmp_path / "copy", tmp_path / "peer"
    mount.mkdir()
    command = f"{BIN / 'generate-dataset'} --out {mount}/ds {GENERATE} --quiet"
    out = _in_namespace(
        f"mount -t tmpfs -o size=512k none {mount}\n"
        f"{command}; echo rc1=$?\n"
        f"find {mount} -name '.*.tmp' | sed 's/^/partial=/'\n"
        f"mount -o remount,size=16m {mount}\n"  # space freed
        f"{command}; echo rc2=$?\n"
        f"cp -a {mount}/ds {copy}"
    )
    assert "rc1=2" in out and "rc2=0" in out and "partial=" not in out, out
    (error,) = _lines(out, "error: ")
    assert error.startswith(f"error: no space left on the filesystem of {mount}") and "more (" in error, error
    assert "run the same command again to resume" in error
    assert "resuming" in out
    subprocess.run(
        [str(BIN / "generate-dataset"), "--out", str(peer), *GENERATE.split(), "--quiet"], check=True, timeout=240
    )
    assert _exr_hashes(copy) == _exr_hashes(peer) and len(_exr_hashes(peer)) == 18


def test_benchmark_stops_on_a_full_disk_and_resumes_with_every_unit_once(tmp_path, installed_example):
    data = make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=16, width=16, spp=(1,))
    mount = tmp_path / "small"
    mount.mkdir()
    db = mount / "r.sqlite"
    denoisers = f"identity,cross_bilateral,cross_bilateral_fast,cross_bilateral_high,nlmeans,{installed_example}"
    command = (
        f"{BIN / 'run-benchmark'} --data {data} --db {db} --no-report --split all --metrics relmse "
        f"--denoisers {denoisers} --time-size none"
    )
    out = _in_namespace(
        f"mount -t tmpfs -o size=300k none {mount}\n"
        f"{command} 2>&1 | grep -v 'it/s\\|seq/s\\|file/s'; echo rc1=$?\n"
        f"mount -o remount,size=16m {mount}\n"
        f"{command} > /dev/null 2>&1; echo rc2=$?\n"
        f"cp {db} {tmp_path / 'r.sqlite'}"
    )
    (error,) = _lines(out, "error: ")
    assert error.startswith(f"error: no space left on the filesystem of {mount}"), error
    assert "the results store needs" in error and "resume" in error
    assert "rc2=0" in out, out
    import sqlite3

    with sqlite3.connect(tmp_path / "r.sqlite") as conn:
        units = conn.execute(
            "SELECT denoiser, scene, spp, COUNT(*) FROM units GROUP BY denoiser, scene, spp"
        ).fetchall()
        finished = conn.execute("SELECT COUNT(*) FROM runs WHERE finished_at IS NOT NULL").fetchone()[0]
    assert finished == 1 and len(units) == 2 * (len(denoisers.split(",")) + 1)  # noisy too
    assert {count for *_, count in units} == {1}
