"""The report's figures can be read: axes span what was measured, colours differ, names do not collide,
the noisy curve is on top, and the per-scene small multiples frame each scene's winner.

Values are read back from the matplotlib objects the report draws (limits, artists, text extents).
"""

from __future__ import annotations

import itertools
import math

import matplotlib.text as mtext
import numpy as np
import pytest

from denoisebench.analysis.accuracy import AccuracyTime, NoisyFit, Point, pareto_front
from denoisebench.reports import figures_accuracy as fa
from denoisebench.reports import figures_scenes as fs

LABELS = [
    "cross_bilateral",
    "cross_bilateral_fast",
    "cross_bilateral_high",
    "rpf_fast",
    "lightfield",
    "nlmeans",
    "oidn",
    "oidn_balanced",
    "oidn_fast",
    "kpcn",
    "dpcn",
    "rae",
    "lbf",
    "mdas",
]


def _panel(seed: int = 3) -> AccuracyTime:
    """The demo's shape: points between 3 and 30 s, a 2048-spp reference at 5000 s, a fitted noisy curve."""
    rng = np.random.default_rng(seed)
    points = [Point(denoiser="noisy", spp=s, seconds=3.0 + 0.5 * s, error=0.5 / s) for s in (1, 4, 16)]
    for label in LABELS:
        for s in (1, 4, 16):
            points.append(
                Point(denoiser=label, spp=s, seconds=3.2 + 0.5 * s + 12 * rng.random(), error=0.05 * rng.random() / s)
            )
    pareto_front(points)
    fit = NoisyFit(
        intercept=math.log(0.5),
        slope=-1.0,
        seconds_per_spp=0.5,
        measured_spp=[1, 4, 16],
        assumed_slope=False,
        time_offset=3.0,
    )
    at = AccuracyTime(
        metric="relmse_robust", points=points, fit=fit, reference_seconds=5000.0, reference_spp=2048, hidden=[]
    )
    at.noisy_curve = {p.spp: p.error for p in points if p.denoiser == "noisy"}
    return at


@pytest.fixture(scope="module")
def drawn():
    at = _panel()
    fig = fa.draw_accuracy([at], fa.colors(["noisy", *LABELS]))
    fig.canvas.draw()
    yield at, fig
    fa.pyplot().close(fig)


def _decades(a: float, b: float) -> float:
    return abs(math.log10(a) - math.log10(b))


def test_axes_span_the_measured_points_with_a_margin_not_the_reference_or_the_extrapolation(drawn):
    at, fig = drawn
    ax = fig.axes[0]
    seconds = [p.seconds for p in at.points]
    errors = [p.error for p in at.points]
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    # every measured point inside, with a margin of at most a tenth of the points' span (+0.1 decade)
    assert x0 < min(seconds) and x1 > max(seconds) and y0 < min(errors) and y1 > max(errors)
    for lo, hi, values in ((x0, x1, seconds), (y0, y1, errors)):
        span = _decades(min(values), max(values))
        for edge, point in ((lo, min(values)), (hi, max(values))):
            assert 0.05 <= _decades(edge, point) <= 0.1 * span + 0.1, (edge, point, span)
    # the 5000 s reference is named at the edge, not drawn at its place (no vertical line out there)
    assert x1 < 100 and any("off this axis" in t.get_text() and "5e+03" in t.get_text() for t in ax.texts)
    # the extrapolated stub stays inside the axes and within STUB_FACTOR x the top rung
    stub = [line for line in ax.get_lines() if line.get_label().startswith("noisy, extrapolated")]
    assert stub, [line.get_label() for line in ax.get_lines()]
    xs = stub[0].get_xdata()
    assert max(xs) <= x1 and max(xs) <= at.fit.seconds_at(16 * fa.STUB_FACTOR) + 1e-9
    assert min(stub[0].get_ydata()) > y0  # the y axis is not stretched for it


def test_the_noisy_curve_is_drawn_on_top_of_every_denoiser(drawn):
    _, fig = drawn
    ax = fig.axes[0]
    noisy = [line for line in ax.get_lines() if line.get_label().startswith("noisy input")]
    others = [line for line in ax.get_lines() if line.get_color() != fa.NOISY_COLOR]
    assert noisy and others
    assert noisy[0].get_zorder() > max(line.get_zorder() for line in others)


def test_denoiser_names_label_their_curves_without_overlapping(drawn):
    _, fig = drawn
    ax = fig.axes[0]
    renderer = fig.canvas.get_renderer()
    names = [t for t in ax.texts if t.get_text() in LABELS]
    assert sorted(t.get_text() for t in names) == sorted(LABELS)
    boxes = [mtext.Text.get_window_extent(t, renderer) for t in names]  # the text, not its leader line
    for (a, ta), (b, tb) in itertools.combinations(zip(boxes, names), 2):
        assert not a.overlaps(b), (ta.get_text(), tb.get_text())
    # each name has its curve's colour
    palette = fa.colors(["noisy", *LABELS])
    assert all(t.get_color() == palette[t.get_text()] for t in names)


def test_fourteen_denoisers_get_colours_far_apart_and_distinct_markers():
    from skimage.color import rgb2lab

    palette = fa.colors(["noisy", *LABELS])
    assert len(set(palette.values())) == len(LABELS) + 1

    def lab(colour: str) -> np.ndarray:
        rgb = [int(colour[i : i + 2], 16) / 255 for i in (1, 3, 5)]
        return rgb2lab(np.array([[rgb]]))[0, 0]

    # CIE76 distance: 25 is far beyond "just noticeable" (2.3); tab20's pairs come down to ~10
    values = {label: lab(c) for label, c in palette.items()}
    closest = min(np.linalg.norm(values[a] - values[b]) for a, b in itertools.combinations(values, 2))
    assert closest >= 25, closest
    assert len({fa.marker_of(label, palette) for label in LABELS}) == len(LABELS)


def test_spread_keeps_order_and_gaps_within_the_axis():
    placed = fa.spread([0.5, 0.5, 0.5, 0.98, 0.99, 0.0], 0.05)
    ordered = sorted(placed)
    assert all(b - a >= 0.05 - 1e-12 for a, b in zip(ordered, ordered[1:]))
    assert 0.0 <= min(placed) and max(placed) <= 1.0
    assert placed[5] == min(placed) and placed[4] == max(placed)  # the order of the inputs is kept


def test_small_multiples_frame_each_scenes_winner_per_spp():
    values = {
        "noisy": {1: 1.0, 4: 0.25},
        "a": {1: 0.1, 4: 0.2},
        "b": {1: 0.5, 4: 0.05},
        "c": {1: 2.0},  # no value at 4 spp: blank, never a winner
    }
    grid = fs.scene_grid("s", values, [1, 4])
    assert grid.winners == {1: ["a"], 4: ["b"]}
    assert grid.ratios[2] == [2.0, None]
    fig = fs.draw_scenes([grid, fs.scene_grid("t", {**values, "a": {1: 0.5, 4: 0.05}}, [1, 4])], "relmse_robust")
    framed = sorted(p.get_gid() for ax in fig.axes for p in ax.patches if (p.get_gid() or "").startswith("winner:"))
    # the tie in scene t at 1 spp (a and b both 0.5) and at 4 spp (both 0.05) frames both
    assert framed == sorted(["winner:a:1", "winner:b:4", "winner:a:1", "winner:b:1", "winner:a:4", "winner:b:4"])
    fa.pyplot().close(fig)
    # a scene where the input scores 0 (a black frame): no ratio anywhere, and the panel says why
    black = fs.scene_grid("black", {"noisy": {1: 0.0, 4: 0.0}, "a": {1: 1e-9, 4: 1e-10}}, [1, 4])
    assert black.winners == {} and black.ratios == [[None, None]]
    fig = fs.draw_scenes([black], "relmse_robust")
    assert any("no ratio" in t.get_text() for t in fig.axes[0].texts)
    fa.pyplot().close(fig)
