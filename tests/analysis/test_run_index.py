"""Scores no single frame decides: a scene's value is the trimmed mean of its frames.

A blown-up frame (OIDN smearing a small bright emitter on one frame of a glossy_fireflies sequence
gave relmse_robust 368 there against ~0.01 elsewhere, and the scene 61.6) must move its scene's lead
score by a bounded amount, however large it is; the report names such frames.
"""

from __future__ import annotations

import math

import pytest

from denoisebench.analysis.run_index import FRAME_TRIM, RunIndex, kept_frames
from denoisebench.results.records import FrameRow, UnitRow


def _index(values: list[float], floor: float = 0.001, se: float = 1e-4) -> RunIndex:
    frames = [
        FrameRow(
            "oidn",
            "s",
            16,
            i,
            "ok",
            None,
            1.0,
            0.1,
            1.1,
            0,
            {"relmse_robust": v},
            {"relmse_robust": floor},
            {"relmse_robust": se},
        )
        for i, v in enumerate(values)
    ]
    unit = UnitRow("oidn", "s", 16, "ok", None, len(values), len(values), 0.8, 8.0)
    return RunIndex([unit], frames, [])


BASE = [0.0126, 0.0131, 0.0119, 0.0140, 0.0122, 0.0135, 0.0128, 0.0133]


@pytest.mark.parametrize("blown", [1.0, 368.0, 1e12])
def test_one_blown_up_frame_of_eight_moves_the_scene_by_a_bounded_amount(blown):
    clean = _index(BASE).scene_value("oidn", 16, "s", "relmse_robust")
    values = list(BASE)
    values[5] = blown
    moved = _index(values).scene_value("oidn", 16, "s", "relmse_robust")
    kept = sorted(BASE)[1:-1]
    bound = (max(BASE) - min(BASE)) / len(kept)  # at most one kept value replaced by a neighbour
    assert abs(moved - clean) <= bound + 1e-15, (blown, moved, clean)
    assert math.isfinite(moved) and moved < 0.015  # the plain mean with 368 in it would be 46


def test_the_trim_drops_one_frame_of_eight_at_each_end_and_the_floor_follows_the_kept_frames():
    frames = _index(BASE).ok_frames("oidn", 16, "s")
    kept = kept_frames(frames, "relmse_robust")
    assert len(kept) == 8 - 2 * math.ceil(FRAME_TRIM * 8) == 6
    assert [f.metrics["relmse_robust"] for f in kept] == sorted(BASE)[1:-1]
    assert len(kept_frames(frames[:2], "relmse_robust")) == 2  # two frames: their mean
    three = kept_frames(frames[:3], "relmse_robust")
    assert [f.metrics["relmse_robust"] for f in three] == [0.0126]  # three: the median
    floor, se = _index(BASE).scene_floor("oidn", 16, "s", "relmse_robust")
    assert floor == pytest.approx(0.001) and se == pytest.approx(math.sqrt(6) * 1e-4 / 6)


def test_frames_that_would_decide_a_plain_mean_are_named():
    values = list(BASE)
    values[5] = 368.0
    (found,) = _index(values).deciding_frames("oidn", 16, "s", "relmse_robust")
    assert found[0] == 5 and found[1] == 368.0 and found[2] == pytest.approx(0.013, rel=0.05)
    assert _index(BASE).deciding_frames("oidn", 16, "s", "relmse_robust") == []
