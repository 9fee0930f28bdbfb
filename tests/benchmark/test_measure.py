"""Measured floors beside closed-form ones: a heavy-tailed reference that the closed form misses.

A reference of N spp is two independent halves. When the halves found rare bright paths (fireflies)
that the per-pixel variance estimate did not see, the closed-form floor (built on that variance) is far
too low; the floor measured from the halves (the score against each half, extrapolated to the full
reference: metrics.floors.half_reference) catches it. The run keeps the measured floor beside the
closed-form one (``floor_measured.<name>``) and the analysis corrects with the measured one where the
two disagree beyond its uncertainty.
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.analysis.run_index import RunIndex
from denoisebench.benchmark.measure import measure_unit
from denoisebench.dataset.frame import Frame, Sequence
from denoisebench.results.names import FLICKER_PREFIX, MEASURED_FLOOR_PREFIX
from denoisebench.results.records import FrameRow, SequenceRow, UnitRow

SIZE, FRAMES, SIGMA = 24, 4, 0.01
#: A firefly of half a: 25 σ of the light-tailed noise (a rare path), small against the image (0.4–0.7)
SPIKE = 0.25
#: Each half reference has 32 spp (64 in all).
HALF_SPP = 32


class Truth:
    """A perfect denoiser: it returns the noise-free image, so every score left is the reference's noise."""

    name = "truth"
    needs = frozenset({"color"})
    temporal = False

    def __init__(self, truth):
        self.truth = truth

    def reset(self):
        pass

    def denoise(self, frame):
        return self.truth[frame.index].astype(np.float32)


def _heavy_tailed_sequence(seed: int = 3):
    """Frames whose reference halves carry light Gaussian noise (what color_var says) and, each on its
    own 1 % of the pixels, fireflies that the variance does not include (rare paths each half found)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    truth = np.stack([(0.4 + 0.3 * np.sin((xx + t) / 4.0) ** 2)[..., None] * np.ones(3) for t in range(FRAMES)])
    frames = []
    for t in range(FRAMES):
        half_a = truth[t] + rng.normal(0, SIGMA, truth[t].shape)
        half_b = truth[t] + rng.normal(0, SIGMA, truth[t].shape)
        half_a[rng.random((SIZE, SIZE)) < 0.01] += SPIKE
        half_b[rng.random((SIZE, SIZE)) < 0.01] += SPIKE
        full = (half_a + half_b) / 2
        var = np.full(truth[t].shape, SIGMA**2 / 2)  # the closed form's view: the light-tailed part only
        noisy = truth[t] + rng.normal(0, 0.2, truth[t].shape)
        meta = {
            "reference_buffers": {"color_var": var.astype(np.float32), "color_half": half_a.astype(np.float32)},
            "reference_spp": 2 * HALF_SPP,
            "reference_half_spp": [HALF_SPP, HALF_SPP],
        }
        motion = np.zeros((SIZE, SIZE, 2), np.float32)
        frames.append(
            Frame(
                buffers={"color": noisy.astype(np.float32), "motion": motion},
                spp=4,
                scene="heavy",
                index=t,
                reference=full.astype(np.float32),
                meta=meta,
            )
        )
    return Sequence(scene="heavy", spp=4, frames=frames), truth


def test_a_heavy_tailed_reference_is_caught_by_the_measured_floor_and_missed_by_the_closed_form():
    sequence, truth = _heavy_tailed_sequence()
    unit = measure_unit("truth", Truth(truth), sequence, spatial=["mse", "relmse"], temporal=["temporal_relmse"])
    assert unit.status == "ok"
    for record in unit.frames:
        score, closed = record.metrics["mse"], record.floors["mse"]
        # the prediction is perfect: the whole score is the reference's noise
        assert closed < 0.5 * score  # the closed form sees the light-tailed part only
        assert record.metrics[MEASURED_FLOOR_PREFIX + "mse"] == pytest.approx(score, rel=0.2)  # the halves see all
        assert record.ref_se[MEASURED_FLOOR_PREFIX + "mse"] > 0
        # relMSE's denominator holds the reference too (first order only): closer, not exact
        score, closed = record.metrics["relmse"], record.floors["relmse"]
        assert abs(score - record.metrics[MEASURED_FLOOR_PREFIX + "relmse"]) < abs(score - closed)
    for pair in unit.frames[1:]:  # per pair, the flicker score's floor is measured too
        name = FLICKER_PREFIX + "temporal_relmse"
        assert pair.floors[name] < 0.5 * pair.metrics[name]
        assert pair.metrics[MEASURED_FLOOR_PREFIX + name] == pytest.approx(pair.metrics[name], rel=0.2)
    # the analysis corrects with the measured floor there: the perfect prediction's score is then near 0
    index = _index(unit)
    for metric in ("mse", "temporal_relmse"):
        found = index.scene_floors("truth", 4, "heavy", metric=metric)
        assert found.source == "measured" and found.floor == found.measured
        value = index.scene_value("truth", 4, "heavy", metric=metric)
        assert abs(value - found.floor) < 0.2 * value < value - found.closed


def test_where_the_two_floors_agree_the_closed_form_leads():
    from denoisebench.analysis.aggregate import leading_floor

    agree = leading_floor(0.010, 0.001, measured=0.0105, measured_se=0.001)
    assert agree.source == "closed_form" and agree.floor == 0.010
    apart = leading_floor(0.010, 0.001, measured=0.030, measured_se=0.002)
    assert apart.source == "measured" and apart.floor == 0.030 and apart.se == 0.002
    assert leading_floor(None, None, measured=None, measured_se=None).source == "none"


def _index(unit) -> RunIndex:
    frames = [
        FrameRow(
            denoiser=unit.denoiser,
            scene=unit.scene,
            spp=unit.spp,
            frame=r.frame,
            status=r.status,
            error=r.error,
            render_seconds=None,
            denoise_seconds=None,
            total_seconds=None,
            sanitized=0,
            metrics=dict(r.metrics),
            floors=dict(r.floors),
            ref_se=dict(r.ref_se),
        )
        for r in unit.frames
    ]
    row = UnitRow(
        denoiser=unit.denoiser,
        scene=unit.scene,
        spp=unit.spp,
        status=unit.status,
        error=None,
        frames=len(frames),
        frames_ok=len(frames),
        denoise_seconds=None,
        render_seconds=None,
    )
    sequences = [
        SequenceRow(
            denoiser=unit.denoiser,
            scene=unit.scene,
            spp=unit.spp,
            metric=name,
            value=value,
            floor=unit.sequence_floors.get(name),
            ref_se=unit.sequence_ref_se.get(name),
        )
        for name, value in unit.sequence_metrics.items()
    ]
    return RunIndex([row], frames, sequences)
