"""Plugin samplers run sandboxed: a hostile sampler cannot read the dataset's references or write outside.

The sampler's worker decides rounds only; the harness renders them, so the worker needs nothing of the
dataset. The hostile module lies in the dataset's parent folder (a submitter's plugin beside the data):
its own folder is readable in the sandbox, so the dataset is hidden only by ``sandbox.protect``, which
``run-benchmark`` calls for it. The peer check: the same snoop in a plain worker (``process``) does
read the reference, so the containment assertions can fail.
"""

from __future__ import annotations

import hashlib
import os
import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from denoisebench.cli import main
from denoisebench.dataset import open_dataset
from denoisebench.dataset.verify import run_files, verify_files
from denoisebench.plugins import sandbox
from denoisebench.results.store import ResultsStore
from denoisebench.sampling import synthetic
from denoisebench.sampling.harness import run_sampler
from denoisebench.sampling.isolation import IsolatedSampler, load
from denoisebench.sampling.protocol import Budget
from tests.support.hostile_parts import SOURCE

pytestmark = pytest.mark.skipif(
    sandbox.unavailable_reason() is not None, reason=f"no sandbox here: {sandbox.unavailable_reason()}"
)

SIZE = 16

HOSTILE = '''
import glob, os
import numpy as np

REFERENCE = {reference!r}
DATASET = {dataset!r}


def _first_round(rounds):
    """A round before the attack: what was rendered is kept when the sampler then fails."""
    rounds.render(np.ones((rounds.height, rounds.width), dtype=int))


{parts}

class Snoop:
    """Opens every reference EXR it can find, and the one whose path it was told."""

    name = "snoop"

    def sample(self, budget, rounds):
        _first_round(rounds)
        _snoop()


class Vandal:
    """Overwrites a reference EXR and plants a file in the dataset folder."""

    name = "vandal"

    def sample(self, budget, rounds):
        _first_round(rounds)
        _vandalise(
            [
                ("reference", lambda: open(REFERENCE, "r+b").write(b"garbage")),
                ("new file", lambda: open(os.path.join(DATASET, "planted.txt"), "w").write("x")),
            ]
        )


class Honest:
    name = "honest"

    def sample(self, budget, rounds):
        while rounds.remaining_samples() > 0 and not rounds.cut:
            rounds.render(np.ones((rounds.height, rounds.width), dtype=int))
'''


def _digest(path: str) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    """A 16 px Cornell dataset (1 scene, 1 frame) and, beside it, the hostile module that knows its paths."""
    root = tmp_path_factory.mktemp("sampler_sandbox")
    dataset = root / "ds"
    args = ["--families", "cornell", "--scenes", "1", "--frames", "1", "--width", str(SIZE), "--height", str(SIZE)]
    assert (
        main(["generate", "--out", str(dataset), *args, "--spp", "4", "--ref-spp", "16", "--seed", "3", "--quiet"]) == 0
    )
    (reference,) = sorted(dataset.glob("*/reference/frame_0000.exr"))
    (root / "hostile.py").write_text(
        textwrap.dedent(HOSTILE.format(reference=str(reference), dataset=str(dataset), parts=SOURCE))
    )
    return {"root": root, "dataset": dataset, "reference": str(reference), "plugin": str(root / "hostile.py")}


@pytest.fixture
def protected(setting, monkeypatch):
    """The dataset protected as run-benchmark protects it, for this test only."""
    monkeypatch.setattr(sandbox, "_PROTECTED", set())
    sandbox.protect(setting["dataset"])


def test_a_hostile_sampler_reads_no_reference_and_writes_nothing_and_the_next_sampler_runs(setting, protected):
    before = _digest(setting["reference"])
    frame, budget = synthetic.constant(8, 8), Budget(spp=4)
    snoop = run_sampler(load(f"{setting['plugin']}:Snoop"), frame, budget)
    assert snoop.stopped == "error" and "contained: no reference in reach" in snoop.error, snoop.error
    assert snoop.samples == 64 and len(snoop.rounds) == 1  # the round it rendered before the attack is kept
    vandal = run_sampler(load(f"{setting['plugin']}:Vandal"), frame, budget)
    assert vandal.stopped == "error" and "contained: reference: " in vandal.error, vandal.error
    assert "new file: " in vandal.error
    assert _digest(setting["reference"]) == before and not (setting["dataset"] / "planted.txt").exists()
    honest = run_sampler(load(f"{setting['plugin']}:Honest"), frame, budget)  # the same process goes on
    assert honest.error is None and honest.samples == 4 * 64


def test_the_peer_a_plain_worker_does_read_the_reference(setting, protected):
    sampler = load(f"{setting['plugin']}:Snoop", policy="process")
    assert isinstance(sampler, IsolatedSampler) and not sampler.sandboxed
    leaked = run_sampler(sampler, synthetic.constant(8, 8), Budget(spp=4))
    assert leaked.stopped == "error" and "LEAK: read " in leaked.error, leaked.error


def test_where_no_sandbox_starts_a_plugin_sampler_is_refused_in_one_line(setting, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path))  # no bwrap on PATH
    sandbox.unavailable_reason.cache_clear()
    try:
        code = main(["check-plugin", "--sampler", f"{setting['plugin']}:Honest"])
    finally:
        sandbox.unavailable_reason.cache_clear()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "cannot sandbox" in err[-1] and "--isolation process" in err[-1], err


def test_run_benchmark_contains_hostile_samplers_and_scores_the_others(setting):
    """From inside the dataset folder, with the dataset in the environment: every route to it exists."""
    root, dataset = setting["root"], setting["dataset"]
    db = root / "bench.sqlite"
    before = _digest(setting["reference"])
    samplers = ["uniform", f"{setting['plugin']}:Snoop", f"{setting['plugin']}:Vandal"]
    command = [str(Path(sys.executable).with_name("run-benchmark")), "--data", str(dataset), "--db", str(db)]
    command += ["--no-report", "--split", "all", "--spp", "4", "--metrics", "relmse", "--denoisers", "identity"]
    command += ["--samplers", ",".join(samplers), "--time-size", "none"]
    env = {**os.environ, "HOSTILE_DATA": str(dataset)}
    done = subprocess.run(command, cwd=dataset, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 3, done.stderr[-3000:]  # completed with failed units: the hostile samplers' only
    with ResultsStore(db, readonly=True) as store:
        (run,) = store.runs()
        every = store.units(run.run_id)
        units = {u.denoiser: u for u in every}
    failed = {u.denoiser.split("+")[0] for u in every if u.status != "ok"}
    assert failed == set(samplers[1:]), failed
    assert units["uniform"].status == "ok" and units["uniform+identity"].status == "ok"
    snoop, vandal = (units[s] for s in samplers[1:])
    assert snoop.status == "failed" and "contained: no reference in reach" in snoop.error, snoop.error
    assert vandal.status == "failed" and "contained: reference: " in vandal.error, vandal.error
    assert _digest(setting["reference"]) == before and not (dataset / "planted.txt").exists()
    data = open_dataset(dataset)
    verify_files(data, run_files(data, list(data.scenes), [4]), progress=False)
    with sqlite3.connect(db) as conn:
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
