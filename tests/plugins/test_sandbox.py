"""The plugin sandbox: hostile plugins, each contained, the rest of the run unchanged.

Each plugin below does what a hostile submitter tried on a 32 px Cornell dataset, and
knows the paths it attacks (they are written into its source, as a submitter who read the docs
would guess them), besides looking them up through ``/proc/<ppid>/cmdline``, ``/proc/<ppid>/cwd``
and its environment. ``run-benchmark`` runs them as a subprocess from inside the dataset folder,
with the dataset in an environment variable, so that every route exists for a plain worker
process. The peer check: the same snoop under ``--isolation process`` does reach the reference.
"""

from __future__ import annotations

import os
import socket
import sqlite3
import subprocess
import sys
import textwrap
import threading
import time
import uuid
from pathlib import Path

import pytest

from denoisebench import cli
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.dataset.verify import run_files, verify_files
from denoisebench.denoisers import isolation
from denoisebench.denoisers.isolation import IsolatedDenoiser
from denoisebench.denoisers.runner import run_sequence
from denoisebench.denoisers.synthetic import synthetic_sequence
from denoisebench.plugins import Limits, proxy, sandbox
from denoisebench.reports.build import write_report
from denoisebench.results.records import FrameRow
from denoisebench.results.store import ResultsStore
from tests.support.hostile_parts import SOURCE

pytestmark = pytest.mark.skipif(
    sandbox.unavailable_reason() is not None, reason=f"no sandbox here: {sandbox.unavailable_reason()}"
)

HOSTILE = '''
import glob, os, socket, subprocess, sys, tempfile, time
import numpy as np

REFERENCE = {reference!r}
DATASET = {dataset!r}
DB = {db!r}
PORT = {port}
TOKEN = {token!r}
LATE = {late!r}


class _Base:
    needs = frozenset({{"color"}})
    temporal = False

    def reset(self):
        pass


{parts}

class Snoop(_Base):
    """Reads a reference EXR found through /proc/<ppid>/cmdline, /proc/<ppid>/cwd or $HOSTILE_DATA."""

    name = "snoop"

    def denoise(self, frame):
        _snoop()


class Vandal(_Base):
    """Rewrites a reference EXR, adds a file to the dataset folder, and overwrites the store.

    (Creating a file at the store's path would succeed in the sandbox: the folders above a bound
    path exist in its scratch tmpfs, and what is written there is gone with the worker.)"""

    name = "vandal"

    def denoise(self, frame):
        _vandalise(
            [
                ("reference", lambda: open(REFERENCE, "r+b").write(b"garbage")),
                ("new file", lambda: open(os.path.join(DATASET, "planted.txt"), "w").write("x")),
                ("store", lambda: open(DB, "r+b").write(b"garbage")),
            ]
        )


class Caller(_Base):
    """Connects to the test's TCP listener on 127.0.0.1."""

    name = "caller"

    def denoise(self, frame):
        try:
            socket.create_connection(("127.0.0.1", PORT), timeout=2).sendall(b"score me")
        except OSError as error:
            raise RuntimeError(f"contained: connect refused: {{error}}")
        raise RuntimeError("CONNECTED")


class Lingerer(_Base):
    """Leaves a grandchild (own session) that sleeps, then writes a file."""

    name = "lingerer"

    def denoise(self, frame):
        code = f"import time; time.sleep(4); open({{LATE!r}}, 'w').write('late')  # {{TOKEN}}"
        subprocess.Popen([sys.executable, "-c", code], start_new_session=True, close_fds=True)
        return np.array(frame.color, np.float32)


class ForkBomb(_Base):
    """Forks 900 sleeping children (bounded, so that a failed containment cannot take the machine)."""

    name = "fork_bomb"

    def denoise(self, frame):
        for _ in range(900):
            if os.fork() == 0:
                time.sleep(60)
                os._exit(0)
        return np.array(frame.color, np.float32)


class LateBomb(_Base):
    """Returns at once, and forks 200 sleeping children from a thread afterwards (between calls)."""

    name = "late_bomb"

    def denoise(self, frame):
        import threading

        def bomb():
            time.sleep(0.3)
            for _ in range(200):
                if os.fork() == 0:
                    time.sleep(60)
                    os._exit(0)

        threading.Thread(target=bomb, daemon=True).start()
        return np.array(frame.color, np.float32)


class Filler(_Base):
    """Writes one file into its scratch folder until something stops it."""

    name = "filler"

    def denoise(self, frame):
        block = b"\\0" * (1 << 20)
        with open(os.path.join(tempfile.gettempdir(), "fill.bin"), "wb") as handle:
            while True:
                handle.write(block)


class Honest(_Base):
    name = "honest"

    def denoise(self, frame):
        return np.array(frame.color, np.float32) * np.float32(0.5)
'''

ATTACKERS = ("Snoop", "Vandal", "Caller", "Lingerer", "ForkBomb", "Filler")


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    """The dataset (1 scene, 2 frames, 16 px), a listener, and the hostile module that knows both."""
    root = tmp_path_factory.mktemp("sandbox")
    dataset = make_synthetic_dataset(root / "ds", scenes=1, frames=2, height=16, width=16, spp=(1,))
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(8)
    accepted: list[bytes] = []

    def serve():
        while True:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            accepted.append(conn.recv(64) or b"(connected)")
            conn.close()

    threading.Thread(target=serve, daemon=True).start()
    token = f"denoisebench-lingerer-{uuid.uuid4().hex}"
    paths = {
        "reference": str(dataset / "synthetic_000" / "reference" / "frame_0000.exr"),
        "dataset": str(dataset),
        "db": str(root / "hostile.sqlite"),
        "late": str(root / "late.txt"),
    }
    assert Path(paths["reference"]).is_file()
    plugins = root / "plugins"
    plugins.mkdir()
    (plugins / "hostile.py").write_text(
        HOSTILE.format(port=listener.getsockname()[1], token=token, parts=SOURCE, **paths)
    )
    yield {**paths, "root": root, "dataset": dataset, "plugins": plugins, "accepted": accepted, "token": token}
    listener.close()


def _lingering(token: str) -> list[int]:
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                if token.encode() in Path(f"/proc/{entry}/cmdline").read_bytes():
                    found.append(int(entry))
            except OSError:
                continue
    return found


def _no_timing_probe() -> list[str]:
    """Skip the post-run timing at a larger size where the command has it (it would call every
    hostile plugin once more on a large frame: slow, and nothing to do with containment)."""
    import argparse

    from denoisebench.commands import benchmark

    parser = argparse.ArgumentParser()
    benchmark.add_arguments(parser)
    return ["--time-size", "none"] if "--time-size" in parser._option_string_actions else []


def _benchmark_argv(setting, db: Path, out: Path, plugins: tuple[str, ...], extra=()) -> list[str]:
    argv = ["--data", str(setting["dataset"]), "--db", str(db), "--out", str(out), "--split", "all"]
    argv += ["--metrics", "relmse", "--denoisers", "identity", "--time-limit", "30", *_no_timing_probe(), *extra]
    for attr in plugins:
        argv += ["--denoiser", f"{setting['plugins'] / 'hostile.py'}:{attr}"]
    return argv


def _frames(db: Path) -> dict[str, list[FrameRow]]:
    with ResultsStore(db, readonly=True) as store:
        (run,) = store.runs()
        out: dict[str, list[FrameRow]] = {}
        for frame in store.frames(run.run_id):
            out.setdefault(frame.denoiser, []).append(frame)
        return out


def test_hostile_plugins_are_contained_and_the_rest_of_the_run_is_bit_identical(setting):
    setting["accepted"].clear()
    db, out = Path(setting["db"]), setting["root"] / "report"
    env = {**os.environ, "HOSTILE_DATA": str(setting["dataset"])}
    bench = Path(sys.executable).with_name("run-benchmark")
    command = [str(bench)] + _benchmark_argv(setting, db, out, (*ATTACKERS, "Honest"), ["--no-report"])
    done = subprocess.run(command, cwd=setting["dataset"], env=env, capture_output=True, text=True, timeout=240)
    assert done.returncode == 3, done.stderr[-3000:]  # completed, some units failed: the attackers' (below)
    frames = _frames(db)
    reasons = {name: {f.error or "" for f in rows} for name, rows in frames.items()}
    failed = {name for name, rows in frames.items() if any(f.status != "ok" for f in rows)}
    assert failed == {"snoop", "vandal", "caller", "fork_bomb", "filler"}, reasons
    # each attacker: failed with its reason, or contained (lingerer: its grandchild died with the worker)
    assert all(r.startswith("raised RuntimeError: contained: no reference") for r in reasons["snoop"]), reasons
    assert all("contained: reference: " in r for r in reasons["vandal"]), reasons["vandal"]
    assert all("new file: " in r and "store: " in r for r in reasons["vandal"])
    assert all("contained: connect refused" in r for r in reasons["caller"]), reasons["caller"]
    assert {f.status for f in frames["lingerer"]} == {"ok"}
    assert all("process limit" in r or "BlockingIOError" in r for r in reasons["fork_bomb"]), reasons["fork_bomb"]
    assert all("No space left" in r or "File too large" in r for r in reasons["filler"]), reasons["filler"]
    assert not setting["accepted"], "a sandboxed plugin reached the host's 127.0.0.1"
    assert not _lingering(setting["token"]) and not Path(setting["late"]).exists()
    # the dataset still matches its manifest, and nothing was planted in it
    dataset = open_dataset(setting["dataset"])
    verify_files(dataset, run_files(dataset, list(dataset.scenes), [1]), progress=False)
    assert not (setting["dataset"] / "planted.txt").exists()
    with sqlite3.connect(db) as conn:
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    # the run records the sandbox and its report says so (written here without the plugins: the
    # report's hard-case section would run every attacker once more, which tells nothing new)
    with ResultsStore(db, readonly=True) as store:
        (run,) = store.runs()
        assert run.versions["bubblewrap"] == sandbox.version().split()[-1]
        write_report(store, run.run_id, dataset, out)
    assert "plugins (every non-built-in) ran sandboxed (bubblewrap" in (out / "report.md").read_text()
    assert "ran sandboxed (bubblewrap" in (out / "index.html").read_text()
    # every other denoiser: bit for bit what a run without the attackers scores
    clean_db = setting["root"] / "clean.sqlite"
    argv = _benchmark_argv(setting, clean_db, setting["root"] / "r2", ("Honest",), ["--no-report"])
    assert cli.main(["benchmark", *argv]) == 0
    clean = _frames(clean_db)
    for name in ("noisy", "identity", "honest"):
        assert [f.metrics for f in frames[name]] == [f.metrics for f in clean[name]], name
        assert {f.status for f in frames[name]} == {"ok"}


def test_in_a_plain_worker_the_attacks_succeed(setting, tmp_path, monkeypatch):
    """The peer check of the test above: without the sandbox the snoop reaches the reference through
    its parent's cwd and the environment, the caller reaches the listener, the grandchild lives on."""
    monkeypatch.chdir(setting["dataset"])  # /proc/<ppid>/cwd
    monkeypatch.setenv("HOSTILE_DATA", str(setting["dataset"]))
    spec = f"{setting['plugins'] / 'hostile.py'}"
    results = {}
    for attr in ("Snoop", "Caller", "Lingerer"):
        denoiser = IsolatedDenoiser(f"{spec}:{attr}", sandboxed=False)
        (results[attr],) = run_sequence(denoiser, synthetic_sequence(frames=1, height=4, width=4))
        denoiser.close()
    assert "LEAK: read " in results["Snoop"].error, results["Snoop"].error
    assert "CONNECTED" in results["Caller"].error, results["Caller"].error
    left = _lingering(setting["token"])
    for pid in left:
        os.kill(pid, 9)
    assert left, "the plain worker's grandchild should have outlived it"
    setting["accepted"].clear()


def test_sandboxed_worker_sees_no_host_path_and_keeps_its_frames(setting, tmp_path):
    """Inside: scratch is the working folder, HOME and TMPDIR; no host path in the environment;
    the frames still arrive through the shared memory file; the dataset is invisible."""
    probe = tmp_path / "probe.py"
    probe.write_text(
        textwrap.dedent(f"""
        import json, os
        import numpy as np
        class Probe:
            name = "probe"
            def denoise(self, frame):
                seen = {{
                    "cwd": os.getcwd(), "env": dict(os.environ), "ppid": os.getppid(),
                    "dataset": os.path.exists({str(setting["dataset"])!r}),
                    "parent_cmdline": open("/proc/%d/cmdline" % os.getppid(), "rb").read().decode(errors="replace"),
                }}
                raise RuntimeError(json.dumps(seen))
    """)
    )
    import json

    denoiser = IsolatedDenoiser(f"{probe}:Probe")
    assert denoiser._channel is not None  # frames go through the shared memory file, as unsandboxed
    (result,) = run_sequence(denoiser, synthetic_sequence(frames=1, height=4, width=4))
    denoiser.close()
    seen = json.loads(result.error.removeprefix("raised RuntimeError: "))
    assert seen["cwd"] == sandbox.SCRATCH and seen["env"]["HOME"] == sandbox.SCRATCH and seen["ppid"] == 1
    assert not seen["dataset"] and str(setting["dataset"]) not in seen["parent_cmdline"]
    assert set(seen["env"]) <= {"PATH", "HOME", "TMPDIR", "PWD", *sandbox.ENV_KEEP}  # PWD: bwrap's, the scratch
    assert seen["env"].get("PWD", sandbox.SCRATCH) == sandbox.SCRATCH


def test_only_the_scratch_folders_are_writable(tmp_path):
    """The root bwrap builds and /dev are read-only (else they would be memory without a limit);
    /tmp and /dev/shm are tmpfs of the scratch size."""
    probe = tmp_path / "writer.py"
    probe.write_text(
        textwrap.dedent(f"""
        import json, os
        class Writer:
            name = "writer"
            def denoise(self, frame):
                places = ["/x", "/dev/x", "/usr/x", {str(tmp_path / "x")!r}, "/tmp/x", "/dev/shm/x"]
                written = []
                for path in places:
                    try:
                        open(path, "w").close()
                        written.append(path)
                    except OSError:
                        pass
                sizes = {{p: os.statvfs(p).f_blocks * os.statvfs(p).f_frsize for p in ("/tmp", "/dev/shm")}}
                raise RuntimeError(json.dumps([written, sizes]))
    """)
    )
    import json

    denoiser = IsolatedDenoiser(f"{probe}:Writer", limits=Limits(scratch_mb=8))
    (result,) = run_sequence(denoiser, synthetic_sequence(frames=1, height=4, width=4))
    denoiser.close()
    written, sizes = json.loads(result.error.removeprefix("raised RuntimeError: "))
    assert written == ["/tmp/x", "/dev/shm/x"] and sizes == {"/tmp": 8 << 20, "/dev/shm": 8 << 20}
    assert not (tmp_path / "x").exists()


def test_protected_path_under_a_bound_folder_is_covered(setting, tmp_path, monkeypatch):
    """A sys.path entry above the dataset would expose it: protect() covers it with an empty tmpfs."""
    monkeypatch.syspath_prepend(str(setting["root"]))  # the folder holding the dataset and the plugins
    monkeypatch.setattr(sandbox, "_PROTECTED", set())
    spec = f"{setting['plugins'] / 'hostile.py'}:Snoop"
    exposed = IsolatedDenoiser(spec)
    (before,) = run_sequence(exposed, synthetic_sequence(frames=1, height=4, width=4))
    exposed.close()
    assert "LEAK: read " in before.error  # read-only, but readable: the peer of the covered case
    sandbox.protect(setting["dataset"])
    covered = IsolatedDenoiser(spec)
    (after,) = run_sequence(covered, synthetic_sequence(frames=1, height=4, width=4))
    covered.close()
    assert "contained: no reference in reach" in after.error, after.error


def test_small_limits_are_the_kernel_s(setting, tmp_path):
    """Scratch size and file size (RLIMIT_FSIZE) and the task count bound a worker as asked."""
    spec = f"{setting['plugins'] / 'hostile.py'}"
    filler = IsolatedDenoiser(f"{spec}:Filler", limits=Limits(scratch_mb=8))
    (filled,) = run_sequence(filler, synthetic_sequence(frames=1, height=4, width=4))
    filler.close()
    assert "No space left on device" in filled.error or "File too large" in filled.error, filled.error
    bomb = IsolatedDenoiser(f"{spec}:ForkBomb", limits=Limits(processes=64))
    (bombed,) = run_sequence(bomb, synthetic_sequence(frames=1, height=4, width=4))
    bomb.close()
    assert "process limit" in bombed.error or "BlockingIOError" in bombed.error, bombed.error
    # forks between calls are counted too: the sandbox is killed, and the next call says why
    late = IsolatedDenoiser(f"{spec}:LateBomb", limits=Limits(processes=64))
    (first,) = run_sequence(late, synthetic_sequence(frames=1, height=4, width=4))
    proc = late._worker.proc
    for _ in range(100):
        if proc.poll() is not None:
            break
        time.sleep(0.05)
    again = run_sequence(late, synthetic_sequence(frames=1, height=4, width=4))
    late.close()
    assert first.status == "ok" and proc.poll() is not None
    assert "process limit" in again[0].error or "BlockingIOError" in again[0].error, again[0].error


def test_untrusted_plugin_is_refused_where_no_sandbox_starts(setting, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path))  # no bwrap on PATH: the sandbox cannot start
    sandbox.unavailable_reason.cache_clear()
    try:
        argv = _benchmark_argv(setting, tmp_path / "r.sqlite", tmp_path / "out", ("Honest",), ["--no-report"])
        assert cli.main(["benchmark", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()[-1]
        assert "bubblewrap (bwrap) is not installed" in err and "--isolation process" in err, err
        assert not (tmp_path / "r.sqlite").exists() or not _frames_or_none(tmp_path / "r.sqlite")
        # accepted explicitly: the run goes on in plain workers and records it
        assert cli.main(["benchmark", *argv, "--isolation", "process"]) == 0
        with ResultsStore(tmp_path / "r.sqlite", readonly=True) as store:
            (run,) = store.runs()
            assert run.config["isolation"] == "process"
        with ResultsStore(tmp_path / "r.sqlite", readonly=True) as store:
            (run,) = store.runs()
            write_report(store, run.run_id, open_dataset(setting["dataset"]), tmp_path / "out")
        assert "not sandboxed (--isolation process)" in (tmp_path / "out" / "report.md").read_text()
    finally:
        sandbox.unavailable_reason.cache_clear()


def _frames_or_none(db: Path):
    try:
        return _frames(db)
    except ValueError:
        return None


def test_policies():
    assert proxy.sandboxed("plugins") and proxy.sandboxed("all")
    assert not proxy.sandboxed("process") and not proxy.sandboxed("none")
    assert isolation.isolated("x.py:A", "process") and not isolation.isolated("identity", "process")
