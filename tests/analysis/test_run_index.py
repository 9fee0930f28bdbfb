"""Scores no single frame decides: a scene's value is the trimmed mean of its frames (or frame pairs).

A blown-up frame (OIDN smearing a small bright emitter on one frame of a glossy_fireflies sequence
gave relmse_robust 368 there against ~0.01 elsewhere, and the scene 61.6) must move its scene's lead
score by a bounded amount, however large it is; the report names such frames.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from denoisebench.analysis.run_index import FRAME_TRIM, RunIndex, kept_frames
from denoisebench.benchmark.measure import measure_unit
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.results.names import FLICKER_PREFIX
from denoisebench.results.records import FrameRow, SequenceRow, UnitRow


def _index(values: list[float], floor: float = 0.001, se: float = 1e-4) -> RunIndex:
    frames = [
        FrameRow(
            denoiser="oidn",
            scene="s",
            spp=16,
            frame=i,
            status="ok",
            error=None,
            render_seconds=1.0,
            denoise_seconds=0.1,
            total_seconds=1.1,
            sanitized=0,
            metrics={"relmse_robust": v},
            floors={"relmse_robust": floor},
            ref_se={"relmse_robust": se},
        )
        for i, v in enumerate(values)
    ]
    unit = UnitRow(
        denoiser="oidn",
        scene="s",
        spp=16,
        status="ok",
        error=None,
        frames=len(values),
        frames_ok=len(values),
        denoise_seconds=0.8,
        render_seconds=8.0,
    )
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


class _BlowsOneFrame:
    """The noisy input as it is, but frame ``index`` multiplied by ``factor`` (a denoiser that smears one emitter)."""

    def __init__(self, index: int | None, factor: float = 1e4):
        self.index, self.factor = index, factor

    def denoise(self, frame):
        out = np.array(frame.color, dtype=np.float32)
        return out * self.factor if frame.index == self.index else out


def _flicker_index(tmp_path, blown: int | None) -> RunIndex:
    data = open_dataset(make_synthetic_dataset(tmp_path / "data", scenes=1, frames=8, spp=(4,), ref_spp=64))
    sequence = data.sequence("synthetic_000", 4)
    unit = measure_unit("d", _BlowsOneFrame(blown), sequence, spatial=[], temporal=["temporal_relmse_robust"])
    assert unit.status == "ok", unit.error
    rows = [
        FrameRow(
            denoiser="d",
            scene=unit.scene,
            spp=4,
            frame=r.frame,
            status=r.status,
            error=r.error,
            render_seconds=None,
            denoise_seconds=None,
            total_seconds=None,
            sanitized=0,
            metrics=r.metrics,
            floors=r.floors,
            ref_se=r.ref_se,
        )
        for r in unit.frames
    ]
    sequences = [
        SequenceRow(
            denoiser="d",
            scene=unit.scene,
            spp=4,
            metric=m,
            value=v,
            floor=unit.sequence_floors.get(m),
            ref_se=unit.sequence_ref_se.get(m),
        )
        for m, v in unit.sequence_metrics.items()
    ]
    return RunIndex(
        [
            UnitRow(
                denoiser="d",
                scene=unit.scene,
                spp=4,
                status="ok",
                error=None,
                frames=8,
                frames_ok=8,
                denoise_seconds=None,
                render_seconds=None,
            )
        ],
        rows,
        sequences,
    )


def test_one_blown_up_frame_of_eight_moves_the_flicker_score_by_a_bounded_amount(tmp_path):
    """The temporal lead score is the trimmed mean of its consecutive pairs, which a blown frame enters
    twice: both pairs are dropped, the pooled sequence value (kept beside it) is decided by that frame."""
    name = "temporal_relmse_robust"
    clean = _flicker_index(tmp_path / "clean", None)
    blown = _flicker_index(tmp_path / "blown", 5)
    pairs = sorted(f.metrics[FLICKER_PREFIX + name] for f in clean.ok_frames("d", 4, "synthetic_000")[1:])
    assert len(pairs) == 7
    before, after = (ix.scene_value("d", 4, "synthetic_000", name) for ix in (clean, blown))
    # two of seven pairs replaced: the kept middle three move by at most the clean pairs' spread
    assert abs(after - before) <= pairs[-1] - pairs[0], (before, after)
    pooled = blown.sequence_rows[0].value
    assert pooled > 100 * after  # the sequence's pooled value is what one frame decides
    floor, se = blown.scene_floor("d", 4, "synthetic_000", name)
    assert floor is not None and 0 < floor < after and se is not None and se > 0
    decided = {frame for frame, _, _ in blown.deciding_frames("d", 4, "synthetic_000", name)}
    assert decided == {5, 6}  # pairs (4, 5) and (5, 6), named by their later frame
