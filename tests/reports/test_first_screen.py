"""The report's first screen: best spp, equal-time error, equal-quality time and deciding scenes, read
off a planted accuracy panel whose every figure is known in closed form; identical denoisers said once.

The planted noisy input is a pure power law (error 0.5/spp, render seconds 3 + 0.5·spp), so log-log
interpolation between its rungs is exact and each expected figure below is worked out by hand.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from denoisebench.analysis.accuracy import AccuracyTime, NoisyFit, Point
from denoisebench.reports import identical, summary_screen


def _at(points) -> AccuracyTime:
    noisy = [Point(denoiser="noisy", spp=s, seconds=3.0 + 0.5 * s, error=0.5 / s) for s in (1, 4, 16)]
    fit = NoisyFit(
        intercept=math.log(0.5),
        slope=-1.0,
        seconds_per_spp=0.5,
        measured_spp=[1, 4, 16],
        assumed_slope=False,
        time_offset=3.0,
    )
    at = AccuracyTime(
        metric="relmse_robust", points=noisy + points, fit=fit, reference_seconds=None, reference_spp=None, hidden=[]
    )
    at.noisy_curve = {p.spp: p.error for p in noisy}
    return at


def test_best_spp_equal_time_and_equal_quality_match_the_hand_worked_figures():
    at = _at(
        [
            # 1 spp in 4 s: rendering alone reaches 2 spp in 4 s, error 0.25; 0.05/0.25 = 0.2
            Point(denoiser="a", spp=1, seconds=4.0, error=0.05),
            # 4 spp in 6 s: rendering alone reaches 6 spp, error 1/12; 0.03·12 = 0.36
            Point(denoiser="a", spp=4, seconds=6.0, error=0.03),
            # slower than rendering at every spp and no better: ratio above 1
            Point(denoiser="b", spp=1, seconds=9.0, error=0.2),
        ]
    )
    scenes = {"a": {1: {"x": 0.9, "y": 0.05, "z": 0.05}}, "noisy": {1: {"x": 1.0, "y": 1.0, "z": 1.0}}}
    screen = summary_screen.first_screen(at, scenes)
    rows = {r.denoiser: r for r in screen.rows}
    a = rows["a"]
    assert a.best_spp == 1 and a.seconds == 4.0
    assert a.equal_time_error == pytest.approx(0.25) and a.equal_time_ratio == pytest.approx(0.2)
    assert a.equal_time_how == "interpolated"
    # its 0.05 is what rendering alone reaches at 10 spp (between 4 and 16), in 3 + 5 = 8 s: 4/8
    assert a.equal_quality_seconds == pytest.approx(8.0) and a.equal_quality_ratio == pytest.approx(0.5)
    assert a.deciding_scenes == ["x"]  # 0.9 of 1.0
    b = rows["b"]
    # 9 s: rendering alone reaches 12 spp, error 1/24; 0.2·24 = 4.8
    assert b.equal_time_ratio == pytest.approx(4.8) and b.deciding_scenes == []
    assert [r.denoiser for r in screen.rows] == ["a", "b"]  # best first
    assert screen.noisy_deciding == {}  # evenly spread: no scene decides the input's mean
    header, body = summary_screen.screen_rows(screen)
    assert header[0] == "denoiser" and [row[0] for row in body] == ["a", "b"]
    assert body[0][1] == "1" and body[0][-1] == "x" and body[0][4].startswith("0.2×")
    assert summary_screen.screen_lines(screen)[0].startswith("Best at equal time: a at 1 spp")


def test_beyond_the_measured_rungs_the_screen_gives_bounds_never_an_extrapolation():
    # 0.01 lies below the 16-spp rung (0.03125): rendering alone needs more than 16 spp, i.e. more than
    # its 11 s, so 4 s is at most 4/11 of it; and at 4 s rendering alone reaches 2 spp (exact)
    at = _at([Point(denoiser="c", spp=1, seconds=4.0, error=0.01)])
    row = summary_screen.first_screen(at, {}).rows[0]
    assert row.equal_quality_how == "at_most" and row.equal_quality_seconds == pytest.approx(11.0)
    assert row.equal_quality_ratio == pytest.approx(4 / 11)
    # slower than the top rung (30 s > 11 s): rendering alone reaches at most the 16-spp error there,
    # so the error ratio is at least 0.02 / 0.03125
    slow = _at([Point(denoiser="d", spp=16, seconds=30.0, error=0.02)])
    row = summary_screen.first_screen(slow, {}).rows[0]
    assert row.equal_time_how == "at_least" and row.equal_time_ratio == pytest.approx(0.64)
    assert row.equal_time_error == pytest.approx(0.03125)
    header, body = summary_screen.screen_rows(summary_screen.first_screen(slow, {}))
    assert body[0][4].startswith("≥ 0.64×") and "vs ≤ 0.0312" in body[0][4]
    # an error above the lowest rung's: rendering needs at most 1 spp (3.5 s); 30 s is at least 8.6× it
    worse = _at([Point(denoiser="e", spp=16, seconds=30.0, error=0.9)])
    row = summary_screen.first_screen(worse, {}).rows[0]
    assert row.equal_quality_how == "at_least" and row.equal_quality_ratio == pytest.approx(30 / 3.5)
    flat = _at([Point(denoiser="c", spp=1, seconds=4.0, error=0.01)])
    flat.fit = None
    row = summary_screen.first_screen(flat, {}).rows[0]
    assert row.best_spp == 1 and row.equal_time_ratio is None and "no noisy-input curve" in row.note


def test_deciding_scenes_need_more_than_half_of_the_sum():
    assert summary_screen.deciding_scenes({"a": 3.0, "b": 1.0, "c": 1.0}) == ["a"]
    assert summary_screen.deciding_scenes({"a": 1.0, "b": 1.0}) == []  # exactly half does not decide
    assert summary_screen.deciding_scenes({"a": 5.0}) == []  # one scene decides nothing among others
    assert summary_screen.deciding_scenes({"a": float("inf"), "b": 1.0, "c": 0.5}) == ["b"]


def _frame(label, frame, value, status="ok"):
    return SimpleNamespace(denoiser=label, scene="s", spp=1, frame=frame, status=status, metrics={"relmse": value})


def _entry(label, spec=None):
    return SimpleNamespace(label=label, spec=spec or label, load_error=None)


def test_identical_denoisers_are_grouped_with_the_known_reason_and_only_when_pixels_agree():
    frames = [_frame(label, i, 0.1 * (i + 1)) for label in ("oidn", "oidn_balanced", "x") for i in range(2)]
    frames += [_frame("y", 0, 0.1), _frame("y", 1, 0.2000001)]  # one digit off: not identical
    frames += [_frame("noisy", i, 0.1 * (i + 1)) for i in range(2)]  # the input is never grouped
    entries = [_entry(n) for n in ("noisy", "oidn", "oidn_balanced", "x", "y")]
    groups = identical.identical_groups(frames, [], entries, same_pixels=lambda a, b: (2, True))
    assert [g.labels for g in groups] == [["oidn", "oidn_balanced", "x"]]
    assert groups[0].reason is None  # the set includes x: no known reason for it
    two = identical.identical_groups(
        [f for f in frames if f.denoiser != "x"], [], entries, same_pixels=lambda a, b: (2, True)
    )
    assert [g.labels for g in two] == [["oidn", "oidn_balanced"]]
    sentence = two[0].sentence()
    assert (
        "oidn and oidn_balanced are identical" in sentence and "rt_hdr_alb_nrm" in sentence and "2 frame(s)" in sentence
    )
    # different pixels under equal scores: not identical
    assert identical.identical_groups(frames, [], entries, same_pixels=lambda a, b: (1, False)) == []
    # a failed frame: not identical
    failed = [f for f in frames if f.denoiser != "x"] + [_frame("oidn_balanced", 2, None, status="failed")]
    assert identical.identical_groups(failed, [], entries) == []


def test_first_screen_gives_identical_denoisers_one_row():
    at = _at(
        [
            Point(denoiser="oidn", spp=1, seconds=4.0, error=0.05),
            Point(denoiser="oidn_balanced", spp=1, seconds=4.0, error=0.05),
        ]
    )
    group = identical.IdenticalGroup(labels=["oidn", "oidn_balanced"], frames=2, images=1, reason="same weights")
    screen = summary_screen.first_screen(at, {}, [group])
    assert [r.denoiser for r in screen.rows] == ["oidn = oidn_balanced"]
    assert any("same weights" in line for line in summary_screen.screen_lines(screen))


def test_deciding_scenes_come_from_the_aggregates_cells_where_they_name_them():
    from denoisebench.reports.screen_parts import _named_by_cells

    at = _at([Point(denoiser="a", spp=1, seconds=4.0, error=0.05), Point(denoiser="b", spp=1, seconds=4.0, error=0.06)])
    # per-scene values say x decides a's mean; the aggregate's cell (corrected values) says y
    screen = summary_screen.first_screen(at, {"a": {1: {"x": 0.9, "y": 0.05, "z": 0.05}}})
    cell = SimpleNamespace(deciding_scenes=[("y", 0.7)])
    summary = [
        SimpleNamespace(denoiser="a", spp=1, metrics={"relmse_robust": cell}),
        SimpleNamespace(denoiser="b", spp=1, metrics={"relmse_robust": SimpleNamespace()}),  # names none
        SimpleNamespace(
            denoiser="noisy", spp=1, metrics={"relmse_robust": SimpleNamespace(deciding_scenes=[("z", 0.6)])}
        ),
    ]
    named = _named_by_cells(screen, summary, "relmse_robust")
    rows = {r.denoiser: r for r in named.rows}
    assert rows["a"].deciding_scenes == ["y"] and rows["b"].deciding_scenes == []
    assert named.noisy_deciding == {1: ["z"]}
    assert _named_by_cells(screen, None, "relmse_robust") == screen


def test_when_every_denoiser_loses_at_equal_time_the_screen_says_so():
    at = _at([Point(denoiser="b", spp=1, seconds=9.0, error=0.2)])  # 4.8× rendering alone's error
    lines = summary_screen.screen_lines(summary_screen.first_screen(at, {}))
    assert lines[0].startswith("At equal time no denoiser beats rendering alone") and "b at 1 spp, 4.8×" in lines[0]


def test_a_run_of_one_scene_says_that_scene_decides_every_figure():
    at = _at([Point(denoiser="a", spp=1, seconds=4.0, error=0.05)])
    one = summary_screen.first_screen(at, {"a": {1: {"x": 0.05}}, "noisy": {1: {"x": 0.5}}})
    assert one.scenes == ("x",)
    assert summary_screen.screen_lines(one)[0].startswith("This run scores one scene (x)")
    two = summary_screen.first_screen(at, {"a": {1: {"x": 0.05, "y": 0.04}}, "noisy": {1: {"x": 0.5, "y": 0.4}}})
    assert two.scenes == ("x", "y") and not any(
        line.startswith("This run scores one scene") for line in summary_screen.screen_lines(two)
    )
