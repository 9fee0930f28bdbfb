"""One story from report to leaderboard: for one run, `denoisebench leaderboard`
shows the numbers the run's report shows: the same scenes (those the report sets apart left out),
the corrected scores, the seconds on the report's time basis, and equal scores share a rank."""

from __future__ import annotations

import json

import pytest

from denoisebench.analysis import aggregate as agg
from denoisebench.analysis import ranking as table
from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.reports.build import write_report
from denoisebench.reports.leaderboard import leaderboard
from denoisebench.results.store import ResultsStore


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("agree")
    data = open_dataset(make_synthetic_dataset(root / "ds", scenes=3, frames=3, height=16, width=16, spp=(1, 4)))
    config = BenchmarkConfig(
        denoisers=["identity", "cross_bilateral_fast"], spp=[1, 4], split="all", metrics=["relmse", "flip"]
    )
    with ResultsStore(root / "r.sqlite") as store:
        plan = run_benchmark(data, config, store, progress=False)
        write_report(store, plan.run_id, data, root / "report")
    return root, data, plan.run_id


def test_the_leaderboard_equals_the_report_for_its_run(run):
    root, _, run_id = run
    results = json.loads((root / "report" / "results.json").read_text())
    with ResultsStore(root / "r.sqlite", readonly=True) as store:
        for metric in ("relmse_robust", "relmse", "flip"):
            for spp in (1, 4):
                ranking = leaderboard(store, metric, spp, run=run_id[:8], split="all")
                report = {r["denoiser"]: r["metrics"][metric] for r in results["summary"] if r["spp"] == spp}
                points = {
                    p["denoiser"]: p["seconds"]
                    for panel in results["accuracy_time"]
                    if panel["metric"] == metric
                    for p in panel["points"]
                    if p["spp"] == spp
                }
                assert {e.denoiser for e in ranking.entries} == set(report)
                for e in ranking.entries:
                    assert e.value == pytest.approx(report[e.denoiser]["mean"], rel=1e-12), (metric, e.denoiser)
                    if e.denoiser in points:
                        assert e.total_seconds == pytest.approx(points[e.denoiser], rel=1e-12)
                if metric != "flip":
                    assert report["noisy"]["corrected"] is True  # the leaderboard ranks the corrected score
        with pytest.raises(Exception, match="no run on split"):
            leaderboard(store, "relmse", 1, split="test")
        with pytest.raises(Exception, match="no run"):
            leaderboard(store, "relmse", 1, run="ffffffff")


def test_scenes_the_report_sets_apart_are_left_out_of_the_leaderboard(run, monkeypatch):
    root, data, run_id = run
    scene = sorted(data.scenes)[0]
    real = agg.reference_states

    def states(records):
        out = real(records)
        out[scene] = {"spp": 64, "floor_growth": 2.0}  # as if its floor were still growing
        return out

    monkeypatch.setattr(agg, "reference_states", states)
    with ResultsStore(root / "r.sqlite", readonly=True) as store:
        ranking = leaderboard(store, "relmse", 1, run=run_id)
        kept = leaderboard(store, "relmse", 1, run=run_id, include_unresolved=True)
    assert any(scene in note and "floor_growing" in note for note in ranking.notes)
    assert all(e.frames == 6 for e in ranking.entries) and all(e.frames == 9 for e in kept.entries)
    assert scene in ranking.text()


def test_equal_scores_share_a_rank():
    entries = [
        table.Entry(
            denoiser=name,
            value=value,
            frames=1,
            failed_units=0,
            denoise_seconds=None,
            total_seconds=None,
            run_id="r",
            created_at="d",
        )
        for name, value in (("a", 0.1), ("b", 0.1), ("c", 0.2), ("d", None))
    ]
    assert table.ranks(entries) == [1, 1, 3, None]
    text = table.format_leaderboard(
        type("M", (), {"name": "relmse", "higher_is_better": False, "aggregate": "mean"}), 1, "abc", entries
    )
    assert [line.split()[0] for line in text.splitlines()[3:]] == ["1", "1", "3", "-"]  # no notes given
