"""`denoisebench leaderboard`: ranking across runs on one dataset, metric direction, newest run wins."""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.cli import main
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.results.store import ResultsStore


@pytest.fixture(scope="module")
def db(tmp_path_factory):
    root = tmp_path_factory.mktemp("lb")
    data = open_dataset(make_synthetic_dataset(root / "ds", scenes=1, frames=2, height=16, width=16, spp=(1, 4)))
    path = root / "r.sqlite"
    with ResultsStore(path) as store:
        # two runs on one dataset: identity in the first, cross_bilateral_fast in the second
        run_benchmark(
            data, BenchmarkConfig(denoisers=["identity"], spp=[1, 4], metrics=["relmse", "ssim"]), store, progress=False
        )
        run_benchmark(
            data,
            BenchmarkConfig(denoisers=["cross_bilateral_fast"], spp=[1, 4], metrics=["relmse", "ssim"]),
            store,
            progress=False,
        )
        expected = {}
        for run in store.runs():
            for f in store.frames(run.run_id):
                if f.spp == 1:  # the report's corrected score: relmse less its reference-noise floor
                    corrected = f.metrics["relmse"] - f.floors["relmse"]
                    expected.setdefault((run.run_id, f.denoiser), []).append(corrected)
    return path, {key: float(np.mean(v)) for key, v in expected.items()}


def _table(capsys, *args) -> list[str]:
    assert main(["leaderboard", *args]) == 0
    return capsys.readouterr().out.strip().splitlines()


def test_ranks_across_runs_with_means_from_the_store(db, capsys):
    path, expected = db
    assert _table(capsys, "--db", str(path))[0].startswith("leaderboard: relmse_robust (lower is better) at 1 spp")
    lines = _table(capsys, "--db", str(path), "--metric", "relmse")
    assert lines[0].startswith("leaderboard: relmse (lower is better) at 1 spp")
    start = next(i for i, line in enumerate(lines) if line.startswith("-")) + 1  # after the notes and rules
    rows = [line.split() for line in lines[start:]]
    names = [r[1] for r in rows]
    assert names[0] == "cross_bilateral_fast"  # a denoiser beats the 1-spp input
    assert set(names) == {"cross_bilateral_fast", "identity", "noisy"}
    # the value shown is the corrected mean over frames stored for the newest run that measured it, as a
    # share of that run's noisy input at its lowest spp (the lead aggregate, analysis.lead; one scene)
    newest = {}
    for (run_id, label), value in expected.items():
        newest.setdefault(label, []).append((run_id, value / expected[(run_id, "noisy")]))
    for row in rows:
        values = [v for _, v in newest[row[1]]]
        assert any(float(row[2]) == pytest.approx(v, rel=1e-3) for v in values)
    ranked = [float(r[2]) for r in rows]
    assert ranked == sorted(ranked)


def test_higher_is_better_metric_ranks_descending(db, capsys):
    path, _ = db
    lines = _table(capsys, "--db", str(path), "--metric", "ssim", "--spp", "4")
    start = next(i for i, line in enumerate(lines) if line.startswith("-")) + 1
    values = [float(line.split()[2]) for line in lines[start:]]
    assert values == sorted(values, reverse=True) and len(values) == 3


def test_bad_options_are_one_line_errors(db, capsys, tmp_path):
    path, _ = db
    assert main(["leaderboard", "--db", str(path), "--spp", "16"]) == 2
    assert "no results at 16 spp" in capsys.readouterr().err
    assert main(["leaderboard", "--db", str(path), "--metric", "nope"]) == 2
    assert "unknown metric" in capsys.readouterr().err
    assert main(["leaderboard", "--db", str(tmp_path / "missing.sqlite")]) == 2
    assert "no results database" in capsys.readouterr().err
    (tmp_path / "junk.sqlite").write_bytes(b"not a database at all" * 100)
    assert main(["leaderboard", "--db", str(tmp_path / "junk.sqlite")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "junk.sqlite" in err[0]
