"""Untrusted plugins: worker isolation, limits, copies, no reference.

The plugins below misbehave the ways a probe of the released commands did: ``sys.exit(3)`` and
``os._exit(3)`` (which ended run-benchmark with exit 3, nothing recorded, on every re-run), a
segfault, a 30 s sleep per call (recorded "ok"), a 2 GB allocation, an input made writable and
scaled ×100 in place (the next denoiser then scored relMSE 10005.56 instead of 0.4651), and a
peek at ``frame.meta["reference_file"]`` (relMSE 0).
"""

from __future__ import annotations

import csv
import io
import sqlite3
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from denoisebench import cli
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.denoisers.isolation import IsolatedDenoiser, isolated
from denoisebench.denoisers.registry import UnknownOptionError
from denoisebench.denoisers.runner import PUBLIC_META, run_denoisers, run_sequence, sanitize_frame
from denoisebench.denoisers.synthetic import synthetic_sequence
from denoisebench.plugins import Limits
from denoisebench.results.store import ResultsStore
from tests.support.processes import plugin_workers

PLUGINS = textwrap.dedent(
    '''
    import ctypes, os, sys, time
    import numpy as np

    class _Base:
        needs = frozenset({"color"})
        temporal = False
        def reset(self):
            pass

    class Exits(_Base):
        name = "exits"
        def denoise(self, frame):
            sys.exit(3)

    class HardExit(_Base):
        name = "hard_exit"
        def denoise(self, frame):
            os._exit(3)

    class Segfault(_Base):
        name = "segfault"
        def denoise(self, frame):
            ctypes.string_at(0)

    class Sleeps(_Base):
        name = "sleeps"
        def denoise(self, frame):
            time.sleep(30)
            return np.array(frame.color, np.float32)

    class Hog(_Base):
        name = "hog"
        def denoise(self, frame):
            hoard = np.ones(2 * 2**30, np.uint8)  # 2 GB, touched
            return np.array(frame.color, np.float32) + float(hoard[-1]) * 0

    class Mutator(_Base):
        """Makes its read-only input writable and scales it x100 in place."""
        name = "mutator"
        def denoise(self, frame):
            color = frame.buffers["color"]
            for array in (color.base, color):
                try:
                    array.setflags(write=True)
                except (AttributeError, ValueError):
                    pass  # e.g. in a worker, where the data lies in a bytes object
            if not color.flags.writeable:
                return np.array(color, np.float32) * np.float32(100)
            color *= 100
            return np.array(color, np.float32)

    class Peek(_Base):
        """Fails when anything of the reference is in reach through the frame."""
        name = "peek"
        def denoise(self, frame):
            leaks = [k for k in frame.meta if "reference" in k or "file" in k]
            if frame.reference is not None or leaks:
                raise RuntimeError(f"reference in reach: {leaks}")
            return np.array(frame.color, np.float32)

    class Honest(_Base):
        name = "=HYPERLINK(\\"http://x\\")"
        def __init__(self, gain=1.0):
            self.gain = gain
        def denoise(self, frame):
            return np.array(frame.color, np.float32) * np.float32(self.gain)

    class Counter:
        """Temporal: output = frames seen since reset(), so the state's home is visible."""
        name = "counter"
        needs = frozenset({"color"})
        temporal = True
        def __init__(self):
            self.count = 0
        def reset(self):
            self.count = 0
        def denoise(self, frame):
            self.count += 1
            return np.full(frame.color.shape, self.count, np.float32)

    class Pickler(_Base):
        """Returns an object whose unpickling would run code in the harness."""
        name = "pickler"
        def denoise(self, frame):
            class Evil:
                def __reduce__(self):
                    return (os.system, ("touch /tmp/denoisebench_pwned",))
            return Evil()
    '''
)


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("untrusted")
    (folder / "evil_plugins.py").write_text(PLUGINS)
    return folder


@pytest.fixture()
def on_path(plugin_dir, monkeypatch):
    monkeypatch.syspath_prepend(str(plugin_dir))  # the worker gets this process's sys.path
    return plugin_dir


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return make_synthetic_dataset(
        tmp_path_factory.mktemp("ds") / "ds", scenes=2, frames=2, height=16, width=16, spp=(1,)
    )


def test_policy_isolates_everything_but_builtins():
    assert isolated("evil_plugins:Exits") and isolated("some_entry_point") and not isolated("identity")
    assert isolated("identity", "all") and not isolated("evil_plugins:Exits", "none")


@pytest.mark.parametrize(
    "attr, reason",
    [
        ("Exits", "raised SystemExit: 3"),
        ("HardExit", "worker exited with status 3"),
        ("Segfault", "worker killed by SIGSEGV"),
        ("Sleeps", "exceeded the time limit (1 s per call)"),
        ("Hog", "exceeded the memory limit"),
        ("Pickler", "returned Evil, not a numpy array"),
    ],
)
def test_misbehaving_plugin_fails_with_its_reason_and_the_caller_survives(on_path, attr, reason):
    started = time.monotonic()
    # 1 s for the sleeper; the others get time to show their own failure on a busy machine
    limit = 1.0 if attr == "Sleeps" else 30.0
    denoiser = IsolatedDenoiser(f"evil_plugins:{attr}", limits=Limits(time_limit=limit, memory_limit_mb=400))
    results = run_sequence(denoiser, synthetic_sequence(frames=2, height=8, width=8))
    assert [r.status for r in results] == ["failed", "failed"]
    assert reason in results[0].error, results[0].error
    # a hang costs one time limit per run, not one per frame: the denoiser is disabled after it
    again = run_sequence(denoiser, synthetic_sequence(frames=2, height=8, width=8))
    assert all(r.status == "failed" for r in again)
    assert time.monotonic() - started < (12 if attr == "Sleeps" else 60)
    assert not Path("/tmp/denoisebench_pwned").exists()
    denoiser.close()


def test_crashed_worker_is_replaced_at_the_next_sequence(on_path, tmp_path):
    flag = tmp_path / "crashed_once"
    module = tmp_path / "crash_once.py"
    module.write_text(
        textwrap.dedent(f'''
        import os
        import numpy as np
        class CrashOnce:
            name = "crash_once"
            def denoise(self, frame):
                if not os.path.exists({str(flag)!r}):
                    open({str(flag)!r}, "w").close()
                    os._exit(7)
                return np.array(frame.color, np.float32)
    ''')
    )
    # a plain worker: its flag file must outlive the worker, which the sandbox (test_sandbox.py) forbids
    denoiser = IsolatedDenoiser(f"{module}:CrashOnce", sandboxed=False)
    first = run_sequence(denoiser, synthetic_sequence(frames=2, height=8, width=8))
    assert first[0].error.startswith("worker exited with status 7") and "earlier in this sequence" in first[1].error
    second = run_sequence(denoiser, synthetic_sequence(frames=2, height=8, width=8))
    assert [r.status for r in second] == ["ok", "ok"]
    denoiser.close()


def test_temporal_state_lives_in_the_worker_across_a_sequence(on_path):
    denoiser = IsolatedDenoiser("evil_plugins:Counter")
    assert denoiser.temporal and denoiser.name == "counter" and denoiser.needs == frozenset({"color"})
    for _ in range(2):  # reset() between sequences starts the count again
        results = run_sequence(denoiser, synthetic_sequence(frames=3, height=4, width=4))
        assert [float(r.output[0, 0, 0]) for r in results] == [1.0, 2.0, 3.0]
        assert all(r.seconds is not None and r.seconds < 1 for r in results)  # time inside denoise() only
    denoiser.close()


def test_writable_input_cannot_reach_the_next_denoiser_in_process(on_path):
    import evil_plugins

    sequence = synthetic_sequence(frames=2, height=8, width=8)
    originals = [np.array(f.color) for f in sequence]
    results = run_denoisers({"mutator": evil_plugins.Mutator(), "honest": evil_plugins.Honest()}, [sequence])
    assert all(r.ok for r in results["mutator"])
    for frame, original, honest in zip(sequence, originals, results["honest"]):
        np.testing.assert_array_equal(honest.output, original)  # not x100
        np.testing.assert_array_equal(frame.color, original)


def test_frame_given_to_a_denoiser_holds_nothing_of_the_reference(dataset):
    frame = open_dataset(dataset).frame("synthetic_000", 1, 0)
    assert "reference_file" in frame.meta and frame.reference is not None  # the harness has them...
    safe, _ = sanitize_frame(frame)
    assert safe.reference is None and set(safe.meta) <= set(PUBLIC_META)  # ...the denoiser does not
    assert not any("reference" in k or "file" in k for k in safe.meta)


def test_unknown_option_key_is_bad_input_also_through_a_worker(on_path):
    with pytest.raises(UnknownOptionError, match="no option 'nosuchopt'"):
        IsolatedDenoiser("evil_plugins:Honest", {"nosuchopt": 1})
    assert IsolatedDenoiser("evil_plugins:Honest", {"gain": 2.0}).name.startswith("=HYPERLINK")


def _frames_by_denoiser(db: Path) -> dict:
    with ResultsStore(db, readonly=True) as store:
        (run,) = store.runs()
        out: dict = {}
        for f in store.frames(run.run_id):
            out.setdefault(f.denoiser, []).append(f)
        return out


def test_benchmark_survives_every_misbehaving_plugin_and_a_rerun_completes(dataset, on_path, tmp_path, capsys):
    db, out = tmp_path / "r.sqlite", tmp_path / "report"
    argv = [
        "benchmark",
        "--time-size",
        "64x64",
        "--data",
        str(dataset),
        "--db",
        str(db),
        "--out",
        str(out),
        "--split",
        "all",
        "--metrics",
        "relmse",
        "--denoisers",
        "identity",
        "--time-limit",
        "5",
        "--memory-limit",
        "400",
        *[
            arg
            for attr in ("Exits", "HardExit", "Segfault", "Sleeps", "Hog", "Mutator", "Peek", "Honest")
            for arg in ("--denoiser", f"evil_plugins:{attr}")
        ],
    ]
    workers = plugin_workers()
    started = time.monotonic()
    assert cli.main(argv) == 3  # completed, with failed units: exactly the misbehaving plugins' (below)
    assert time.monotonic() - started < 120
    assert plugin_workers() <= workers  # the run stopped the workers it started
    frames = _frames_by_denoiser(db)
    reasons = {name: frames[name][0].error or "" for name in frames}
    failed = {name for name, rows in frames.items() if any(f.status != "ok" for f in rows)}
    assert failed == {"exits", "hard_exit", "segfault", "sleeps", "hog"}, reasons
    assert "SystemExit: 3" in reasons["exits"] and "status 3" in reasons["hard_exit"]
    assert "SIGSEGV" in reasons["segfault"] and "time limit" in reasons["sleeps"] and "memory limit" in reasons["hog"]
    for name in ("identity", "mutator", "peek", "=HYPERLINK(\"http://x\")"):
        assert all(f.status == "ok" for f in frames[name]), (name, reasons[name])
    # the honest plugin after the mutator scores exactly what the noisy input scores
    noisy = [f.metrics["relmse"] for f in frames["noisy"]]
    assert [f.metrics["relmse"] for f in frames["=HYPERLINK(\"http://x\")"]] == pytest.approx(noisy, rel=1e-6)
    assert [f.metrics["relmse"] for f in frames["peek"]] == pytest.approx(noisy, rel=1e-6)
    # finding 7: the plugin's name reaches results.csv neutralised
    rows = list(csv.reader(io.StringIO((out / "results.csv").read_text())))
    names = {row[1] for row in rows[1:]}
    assert "'=HYPERLINK(\"http://x\")" in names and not any(n.startswith(("=", "+", "-", "@")) for n in names)
    # a re-run resumes and completes; the failed units stay recorded (not measured again), so it exits 3 too
    capsys.readouterr()
    assert cli.main(argv + ["--no-report"]) == 3
    assert "resumed" in capsys.readouterr().out
    with sqlite3.connect(db) as conn:
        assert conn.execute("SELECT COUNT(*) FROM runs WHERE finished_at IS NOT NULL").fetchone()[0] == 1


def test_check_plugin_contains_an_exiting_plugin_and_fails_a_mutating_one(on_path, capsys):
    assert cli.main(["check-plugin", "evil_plugins:HardExit", "--case", "tiny", "--json"]) == 1
    assert "worker exited with status 3" in capsys.readouterr().out
    # x100 of the input: with copies the check compares against the genuine input, and fails it
    assert (
        cli.main(["check-plugin", "evil_plugins:Mutator", "--case", "black_frame", "--case", "fireflies", "--json"])
        == 1
    )
    out = capsys.readouterr().out
    assert '"case": "fireflies"' in out and "robust mean" in out


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["--denoisers", "identity", "--option", "identity:nosuchopt=1"], "has no option 'nosuchopt'"),
        (["--denoisers", "identity", "--option", "nosuchspec:radius=1"], "not among the denoisers run"),
        (["--denoisers", "identity", "--time-limit", "0"], "--time-limit must be > 0"),
    ],
)
def test_unknown_option_or_spec_is_exit_2(dataset, tmp_path, argv, fragment, capsys):
    code = cli.main(["benchmark", "--data", str(dataset), "--db", str(tmp_path / "x.sqlite"), "--no-report", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("error: ") and fragment in err[-1], err
    assert cli.main(["check-plugin", "identity", "--option", "nosuchopt=1"]) == 2
    assert "has no option" in capsys.readouterr().err


def test_pickled_pipe_fallback_keeps_the_contract(on_path, monkeypatch):
    from denoisebench.denoisers import shared_frames

    monkeypatch.setattr(shared_frames, "available", lambda: False)  # as where memfd_create is missing
    denoiser = IsolatedDenoiser("evil_plugins:Counter")
    assert denoiser._channel is None
    results = run_sequence(denoiser, synthetic_sequence(frames=2, height=4, width=4))
    assert [float(r.output[0, 0, 0]) for r in results] == [1.0, 2.0]
    denoiser.close()


def test_output_larger_than_the_frame_is_refused_without_reading_it(tmp_path):
    module = tmp_path / "huge_output.py"
    module.write_text(
        "import numpy as np\nclass Huge:\n    name = 'huge'\n"
        "    def denoise(self, frame):\n        return np.zeros((512, 512, 3), np.float64)\n"
    )
    denoiser = IsolatedDenoiser(f"{module}:Huge")
    (result,) = run_sequence(denoiser, synthetic_sequence(frames=1, height=4, width=4))
    assert result.status == "failed" and "(512, 512, 3)" in result.error
    denoiser.close()
