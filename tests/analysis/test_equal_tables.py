"""Equal-time and equal-quality tables on constructed curves with known answers, and in the report files.

The curves follow the Monte Carlo law error = c / spp exactly, so that log-log interpolation between
rungs is exact and every expected spp and second is computed by hand."""

from __future__ import annotations

import json

import pytest

from denoisebench.analysis import equal_tables as et
from denoisebench.analysis.summary import Cell, SummaryRow
from denoisebench.results.names import NOISY

RUNGS = [1, 2, 4, 8, 16]


class _Model:
    """Render 1 + 0.5 · spp seconds per frame; denoise seconds per label."""

    time_at, projected = (1920, 1080), True

    def __init__(self, denoise):
        self.denoise = denoise

    def render_seconds(self, spp):
        return 1.0 + 0.5 * spp

    def total_seconds(self, label, spp):
        return self.render_seconds(spp) + (0.0 if label == NOISY else self.denoise[label])


def _row(label, spp, error, low=None, high=None):
    return SummaryRow(
        denoiser=label,
        spp=spp,
        metrics={"relmse": Cell(value=error, low=low, high=high, scenes=4)},
        denoise_seconds=None,
        total_seconds=None,
        render_seconds=None,
        frames=8,
        failed_units=0,
    )


def _summary():
    rows = [_row(NOISY, s, 1.0 / s, 0.9 / s, 1.1 / s) for s in RUNGS]
    rows += [_row("good", s, 0.05 / s, 0.04 / s, 0.06 / s) for s in RUNGS]  # 20× lower error, 2 s per frame
    rows += [_row("cheap", s, 0.5 / s) for s in RUNGS]  # 2× lower error, 0.1 s per frame
    return rows


def test_interpolation_is_log_log_between_rungs_and_marked_outside():
    curve = {s: 1.0 / s for s in RUNGS}
    inside = et.error_at(curve, 6)
    assert inside.how == "interpolated" and inside.value == pytest.approx(1 / 6)
    assert et.error_at(curve, 8).how == "measured"
    outside = et.error_at(curve, 64)
    assert outside.how == "extrapolated" and outside.value == pytest.approx(1 / 64)
    assert et.spp_for(curve, 1 / 6).value == pytest.approx(6) and et.spp_for(curve, 1 / 6).how == "interpolated"
    assert et.spp_for(curve, 2.0).how == "at_most"  # met at the lowest rung
    beyond = et.spp_for(curve, 1 / 100)
    assert beyond.how == "extrapolated" and beyond.value == pytest.approx(100)
    assert et.spp_for({1: 0.5, 2: 0.5}, 0.1) is None  # a flat curve never reaches it
    # a nearly flat last segment would need ~10^10 spp: not given
    assert et.spp_for({1: 1.0, 2: 0.95}, 0.1) is None and et.EXTRAPOLATION_LIMIT == 64


def test_equal_time_picks_the_best_configuration_that_fits_each_budget():
    model = _Model({"good": 2.0, "cheap": 0.1})
    rows = et.equal_time(et.Curves.from_summary(_summary(), "relmse"), model, RUNGS)
    by_budget = {r.budget_spp: r for r in rows}
    # budget of 1 spp (1.5 s): nothing denoised fits (cheap at 1 spp takes 1.6 s)
    assert by_budget[1].best is None
    # 2 spp (2 s): cheap at 1 spp (1.6 s) fits but only ties rendering 2 spp (0.5 both): rendering alone
    assert by_budget[2].best is None and by_budget[2].candidates == 1
    # 8 spp (5 s): good at 4 spp (3 + 2 = 5 s) fits: 0.0125 against 0.125
    assert (by_budget[8].best, by_budget[8].best_spp) == ("good", 4)
    assert by_budget[8].ratio == pytest.approx(0.1)
    assert by_budget[8].best_error.low == pytest.approx(0.01)  # the interval travels with it


def test_equal_quality_reads_each_denoisers_time_off_its_own_rungs():
    model = _Model({"good": 2.0, "cheap": 0.1})
    rows = et.equal_quality(et.Curves.from_summary(_summary(), "relmse"), model, RUNGS)
    targets = [r.target_spp for r in rows]
    assert targets == [1, 2, 4, 8, 16, 64, 256]  # the rungs, then 4× and 16× the top rung
    at8 = next(r for r in rows if r.target_spp == 8)
    spp, seconds = at8.needs["cheap"]
    assert spp.how == "measured" and spp.value == pytest.approx(4)  # 0.5/4 = 1/8
    assert seconds.value == pytest.approx(1 + 0.5 * 4 + 0.1)
    spp, _ = at8.needs["good"]
    assert spp.how == "at_most" and spp.value == 1  # 0.05 ≤ 1/8 at its lowest rung
    at4 = next(r for r in rows if r.target_spp == 4)
    spp, _ = at4.needs["cheap"]
    assert spp.how == "measured" and spp.value == pytest.approx(2)
    deep = rows[-1]
    assert deep.render_how == "extrapolated" and deep.target == pytest.approx(1 / 256)
    spp, _ = deep.needs["cheap"]
    assert spp.how == "extrapolated" and spp.value == pytest.approx(128)


def test_verdicts_never_rest_on_an_extrapolated_figure():
    model = _Model({"good": 2.0, "cheap": 0.1})
    tables = et.build_tables(_summary(), model, RUNGS, "relmse")
    text = et.verdicts(tables)
    assert any(t.startswith("Equal time (relmse)") and "good at 8 spp" in t for t in text)  # budget 16 spp: 9 s
    quality = [t for t in text if t.startswith("Equal quality")]
    assert quality and not any("64-spp" in t or "256-spp" in t for t in quality)
    # a denoiser that beats rendering only beyond the rungs gets no equal-quality verdict at all
    only_far = [_row(NOISY, s, 1.0 / s) for s in (1, 2)] + [_row("far", s, 0.001 / s) for s in (1, 2)]
    far = et.build_tables(only_far, _Model({"far": 100.0}), [1, 2], "relmse")
    assert not [t for t in et.verdicts(far) if "far reaches" in t and "at most" not in t]
    rows = far.equal_quality
    assert all(r.render_how == "extrapolated" for r in rows[2:])


def test_lead_metric_is_the_robust_relmse_when_measured():
    assert et.lead_metrics(["relmse", "relmse_robust", "flip"]) == ["relmse_robust", "flip"]
    assert et.lead_metrics(["relmse", "flip"]) == ["relmse", "flip"]


def test_tables_are_in_report_md_index_html_and_results_json(tmp_path):
    from denoisebench.cli import main
    from denoisebench.dataset.synthetic import make_synthetic_dataset

    data = make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=16, width=16, spp=(1, 2, 4))
    code = main(
        [
            "benchmark",
            "--data",
            str(data),
            "--db",
            str(tmp_path / "db.sqlite"),
            "--out",
            str(tmp_path / "r"),
            "--denoisers",
            "cross_bilateral_fast",
            "--split",
            "all",
            "--metrics",
            "relmse",
            "--time-size",
            "64x64",
        ]
    )
    assert code == 0
    results = json.loads((tmp_path / "r" / "results.json").read_text())
    tables = {t["metric"]: t for t in results["equal_tables"]}
    assert set(tables) == {"relmse_robust", "flip"}
    assert [r["budget_spp"] for r in tables["relmse_robust"]["equal_time"]] == [1, 2, 4]
    assert results["time_model"]["time_at"] == [1920, 1080] and results["time_model"]["projected"]
    md = (tmp_path / "r" / "report.md").read_text()
    assert "### Equal time: relmse\\_robust" in md and "### Equal quality: flip" in md
    html = (tmp_path / "r" / "index.html").read_text()
    assert "Equal quality: relmse_robust" in html and "Equal time: flip" in html
