"""The report's analyses on constructed inputs with known answers: Pareto front, equivalent spp, bootstrap, worst regions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from denoisebench.analysis import accuracy
from denoisebench.analysis.summary import bootstrap_interval, effect_breakdown
from denoisebench.reports import images
from denoisebench.results import crops
from denoisebench.results.names import NOISY


def _curve(seconds_per_spp=0.01, spps=(1, 4, 16), c=0.5):
    """Noisy points with relMSE = c/spp exactly (the Monte Carlo rate) and time = spp × seconds per spp."""
    return [accuracy.Point(denoiser=NOISY, spp=s, seconds=s * seconds_per_spp, error=c / s) for s in spps]


def test_pareto_front_marks_exactly_the_undominated_points():
    points = _curve() + [
        accuracy.Point(denoiser="fast_good", spp=1, seconds=0.02, error=0.01),  # dominates noisy@4 and noisy@16
        accuracy.Point(
            denoiser="slow_bad", spp=4, seconds=1.0, error=0.2
        ),  # dominated by everything cheaper and better
        accuracy.Point(denoiser="best", spp=16, seconds=0.5, error=0.001),
    ]
    accuracy.pareto_front(points)
    front = {(p.denoiser, p.spp) for p in points if p.pareto}
    assert front == {(NOISY, 1), ("fast_good", 1), ("best", 16)}


def test_equivalent_spp_and_time_ratio_follow_the_noisy_curve():
    points = _curve() + [
        accuracy.Point(denoiser="den", spp=4, seconds=0.05, error=0.5 / 8)
    ]  # the error of 8-spp rendering
    fit = accuracy.fit_noisy(points, [(s, 0.01 * s) for s in (1, 4, 16)], "relmse")
    assert fit.slope == pytest.approx(-1.0) and not fit.assumed_slope
    assert fit.spp_for(0.005) == pytest.approx(100.0)
    at = accuracy.AccuracyTime(
        metric="relmse", points=points, fit=fit, reference_seconds=10.24, reference_spp=1024, hidden=[]
    )
    accuracy.pareto_front(points)
    text = accuracy.readings(at)[0]
    # 8 spp (between the measured 4 and 16) take 0.08 s; the denoiser takes 0.05 s: 62 % of the time
    assert text.startswith("den at 4 spp matches 8-spp rendering") and "62 % of its time" in text
    assert "extrapolated" not in text


def test_no_verdict_rests_on_an_extrapolation_beyond_the_measured_rungs():
    points = _curve() + [
        accuracy.Point(denoiser="den", spp=4, seconds=0.05, error=0.5 / 100)
    ]  # the error of 100-spp rendering
    fit = accuracy.fit_noisy(points, [(s, 0.01 * s) for s in (1, 4, 16)], "relmse")
    at = accuracy.AccuracyTime(
        metric="relmse", points=points, fit=fit, reference_seconds=10.24, reference_spp=1024, hidden=[]
    )
    text = accuracy.readings(at)[0]
    assert text.startswith("den at 4 spp (relmse 0.005) is below the error of rendering alone at every measured")
    assert "no verdict" in text and "matches" not in text and "cheaper" not in text
    # one measured rung: every comparison would extrapolate along an assumed slope
    one = accuracy.fit_noisy(
        _curve(spps=(4,)) + [accuracy.Point(denoiser="den", spp=4, seconds=0.05, error=0.01)], [(4, 0.04)], "relmse"
    )
    single = accuracy.AccuracyTime(
        metric="relmse",
        points=_curve(spps=(4,)) + [accuracy.Point(denoiser="den", spp=4, seconds=0.05, error=0.01)],
        fit=one,
        reference_seconds=None,
        reference_spp=None,
        hidden=[],
    )
    assert "no verdict" in accuracy.readings(single)[0]


def test_readings_say_when_rendering_is_cheaper_or_the_input_is_not_improved():
    points = _curve() + [
        accuracy.Point(denoiser="slow", spp=1, seconds=0.5, error=0.5 / 8),
        accuracy.Point(denoiser="worse", spp=4, seconds=0.05, error=0.2),
    ]
    fit = accuracy.fit_noisy(points, [(s, 0.01 * s) for s in (1, 4, 16)], "relmse")
    texts = accuracy.readings(
        accuracy.AccuracyTime(
            metric="relmse", points=points, fit=fit, reference_seconds=None, reference_spp=256, hidden=[]
        )
    )
    slow = next(t for t in texts if t.startswith("slow"))
    assert "8-spp rendering" in slow and "(0.5 s vs 0.08 s per frame)" in slow  # 8 spp take 0.08 s
    assert "× as long" in slow and "rendering more samples is cheaper" in slow
    worse = next(t for t in texts if t.startswith("worse"))
    assert "does not improve on its own input" in worse


def test_single_spp_assumes_the_monte_carlo_slope_and_a_flat_curve_gives_no_fit():
    fit = accuracy.fit_noisy(_curve(spps=(4,)), [(4, 0.04)], "relmse")
    assert fit.assumed_slope and fit.slope == -1.0 and fit.spp_for(0.5 / 32) == pytest.approx(32.0)
    flat = [accuracy.Point(denoiser=NOISY, spp=s, seconds=s * 0.01, error=0.1) for s in (1, 4)]
    assert accuracy.fit_noisy(flat, [(1, 0.01), (4, 0.04)], "relmse") is None
    assert (
        "does not fall"
        in accuracy.readings(
            accuracy.AccuracyTime(
                metric="relmse", points=flat, fit=None, reference_seconds=None, reference_spp=None, hidden=[]
            )
        )[0]
    )


def test_bootstrap_interval_brackets_the_mean_and_needs_two_scenes():
    rng = np.random.default_rng(3)
    values = rng.normal(1.0, 0.2, 12)
    low, high = bootstrap_interval(values)
    assert low < values.mean() < high
    # the percentile interval of the mean is about ±1.96·s/√n wide
    half = 1.96 * values.std(ddof=1) / math.sqrt(values.size)
    assert (high - low) / 2 == pytest.approx(half, rel=0.3)
    assert bootstrap_interval([0.5]) == (None, None)
    assert bootstrap_interval([0.5, 0.5, 0.5]) == (0.5, 0.5)
    assert bootstrap_interval([1.0, math.nan, 3.0]) != (None, None)  # NaN dropped, two left


def test_worst_windows_find_planted_errors_without_overlap():
    error = np.zeros((32, 40))
    error[20:24, 30:34] = 5.0  # the worst
    error[2:6, 3:7] = 2.0  # the second
    found = crops.worst_windows(error, 4, count=2)
    assert found == [(20, 30), (2, 3)]
    # a window at the border stays inside the image
    edge = np.zeros((16, 16))
    edge[-1, -1] = 1.0
    ((top, left),) = crops.worst_windows(edge, 4, count=1)
    assert 0 <= top <= 12 and 0 <= left <= 12 and top + 4 == 16 and left + 4 == 16


def test_png_of_hdr_and_black_images_is_valid_and_sized():
    from io import BytesIO

    from PIL import Image

    hdr = np.full((5, 7, 3), 1e6, np.float32)
    hdr[0, 0] = 0.0
    image = Image.open(BytesIO(images.to_png(hdr, scale=3)))
    assert image.size == (21, 15)
    pixels = np.asarray(image)
    assert pixels[0, 0].tolist() == [0, 0, 0] and pixels[-1, -1].min() >= 254


def test_render_time_line_keeps_the_fixed_cost_out_of_the_per_sample_cost():
    # 0.9 s per frame whatever the spp, plus 0.02 s per sample: 1, 4 and 256 spp measured
    offset, per_spp = accuracy.fit_render_time([(1, 0.92), (4, 0.98), (256, 6.02)])
    assert offset == pytest.approx(0.9) and per_spp == pytest.approx(0.02)
    points = _curve(spps=(1, 4)) + [accuracy.Point(denoiser="den", spp=4, seconds=1.2, error=0.5 / 100)]
    fit = accuracy.fit_noisy(points, [(1, 0.92), (4, 0.98), (256, 6.02)], "relmse")
    assert fit.seconds_at(100) == pytest.approx(2.9)  # not 100 × 0.92
    assert accuracy.fit_render_time([(4, 0.4)]) == (0.0, pytest.approx(0.1))


class _EffectRun:
    """What effect_breakdown reads of a run: labels, scenes, spp, per-scene values, unit status."""

    def __init__(self, values):
        self.values = values  # {(label, scene): value} at 4 spp
        self.labels = sorted({label for label, _ in values})
        self.scenes = sorted({scene for _, scene in values})
        self.spp = [4]

    def scene_value(self, label, spp, scene, metric):
        return self.values.get((label, scene))

    def unit_ok(self, label, spp, scene):
        return True


def test_effects_exercised_by_the_same_scenes_are_one_column_and_the_others_stay_apart():
    values = {(NOISY, s): 1.0 for s in "abc"} | {("d", "a"): 0.5, ("d", "b"): 0.2, ("d", "c"): 0.1}
    scene_effects = {
        "a": ["glossy", "specular", "transmission"],
        "b": ["environment", "specular", "transmission"],
        "c": ["glossy", "environment"],
    }
    out = effect_breakdown(_EffectRun(values), scene_effects)
    assert out.effects == ["environment", "glossy", "specular + transmission"]
    row = out.table["d"]
    assert row["specular + transmission"] == pytest.approx(math.sqrt(0.5 * 0.2))
    assert row["glossy"] == pytest.approx(math.sqrt(0.5 * 0.1)) and row["environment"] == pytest.approx(
        math.sqrt(0.2 * 0.1)
    )
    assert len({row[e] for e in out.effects}) == len(out.effects)  # no two columns alike
