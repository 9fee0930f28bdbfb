"""An aggregate no single scene decides: the lead scores' cells lead with the anchored trimmed geometric
mean (:mod:`denoisebench.analysis.lead`), the arithmetic mean beside it, and the scenes that carry more
than half of that mean are named.

The planted values are the demo's own (main 3a0b9b0, seed 915, robust relMSE at 4 spp): oidn 0.003–0.03
on four scenes and 703 on glossy_fireflies (OIDN spreading small emitters of radiance ~1e4 into their
black surroundings), the noisy input 0.04–0.7 on all five.
"""

from __future__ import annotations

import math

import pytest

from denoisebench.analysis import lead
from denoisebench.analysis.run_index import RunIndex
from denoisebench.analysis.summary import metric_cell
from denoisebench.results.names import NOISY
from denoisebench.results.records import FrameRow, UnitRow

SCENES = ("cluttered", "depth_of_field", "glass_env", "motion_blur", "glossy_fireflies")
#: {label: {spp: [value per scene in SCENES order]}}: relmse_robust, the last scene wild for oidn only
PLANTED = {
    NOISY: {1: [0.16, 2.9, 0.48, 0.30, 1.9], 4: [0.040, 0.73, 0.12, 0.075, 0.52]},
    "oidn": {1: [0.012, 0.13, 0.030, 0.030, 2400.0], 4: [0.0032, 0.033, 0.0072, 0.0075, 703.0]},
}


class _Data(RunIndex):
    """A run of planted per-frame values (three frames per unit, all equal: the scene's value)."""

    def __init__(self, planted: dict, scenes=SCENES, metric: str = "relmse_robust"):
        units, frames = [], []
        for label, by_spp in planted.items():
            for spp, values in by_spp.items():
                for scene, value in zip(scenes, values):
                    units.append(
                        UnitRow(
                            denoiser=label,
                            scene=scene,
                            spp=spp,
                            status="ok",
                            error=None,
                            frames=3,
                            frames_ok=3,
                            denoise_seconds=0.0,
                            render_seconds=1.0,
                        )
                    )
                    for i in range(3):
                        frames.append(
                            FrameRow(
                                denoiser=label,
                                scene=scene,
                                spp=spp,
                                frame=i,
                                status="ok",
                                error=None,
                                render_seconds=1.0,
                                denoise_seconds=0.0,
                                total_seconds=1.0,
                                sanitized=0,
                                metrics={metric: value},
                                floors={},
                                ref_se={},
                            )
                        )
        super().__init__(units, frames, [])
        self.labels = list(planted)


def _cell(data, label, spp, scenes=SCENES):
    return metric_cell(data, label, spp, metric="relmse_robust", scenes=list(scenes))


def test_one_wild_scene_moves_the_lead_aggregate_less_than_twofold_and_the_arithmetic_mean_by_orders():
    data = _Data(PLANTED)
    tame = [s for s in SCENES if s != "glossy_fireflies"]
    for spp in (1, 4):
        full, without = _cell(data, "oidn", spp), _cell(data, "oidn", spp, tame)
        assert full.rule == lead.LEAD_RULE
        moved = max(full.value / without.value, without.value / full.value)
        assert moved < 2.0
        assert full.arithmetic / without.arithmetic > 1e3  # the plain mean is that one scene
        # the plain geometric mean of the ratios to the input moves far more than twofold
        ratios = [v / n for v, n in zip(PLANTED["oidn"][spp], PLANTED[NOISY][spp])]
        plain_all = math.exp(sum(map(math.log, ratios)) / 5)
        plain_tame = math.exp(sum(map(math.log, ratios[:4])) / 4)
        assert plain_all / plain_tame > 2.0


def test_the_lead_aggregate_ranks_the_denoiser_below_the_input_and_the_input_falls_with_spp():
    data = _Data(PLANTED)
    for spp in (1, 4):
        assert _cell(data, "oidn", spp).value < _cell(data, NOISY, spp).value
    assert _cell(data, NOISY, 4).value < _cell(data, NOISY, 1).value
    # the arithmetic mean puts oidn far above the input: the scene decides it, and is named
    cell = _cell(data, "oidn", 4)
    assert cell.arithmetic > _cell(data, NOISY, 4).arithmetic
    assert [s for s, _ in cell.deciding_scenes] == ["glossy_fireflies"]
    assert cell.deciding_scenes[0][1] == pytest.approx(703.0 / sum(PLANTED["oidn"][4]))


def test_without_trimming_the_lead_aggregate_is_the_geometric_mean_of_the_shares():
    values = {"a": 0.1, "b": 0.4}
    anchors = {"a": 1.0, "b": 3.0}
    value, low, high, count = lead.lead_aggregate(values, anchors)
    assert count == 2 and value == pytest.approx(math.sqrt(0.1 / 1.0 * 0.4 / 3.0))
    assert low <= value <= high


def test_a_scene_moves_the_trimmed_aggregate_by_at_most_the_spread_of_the_others():
    tame = {"a": 0.01, "b": 0.02, "c": 0.015, "d": 0.03}
    anchors = {s: 1.0 for s in [*tame, "wild"]}
    base = lead.lead_aggregate(tame, anchors)[0]
    for wild in (1e-12, 1.0, 1e12):
        moved = lead.lead_aggregate({**tame, "wild": wild}, anchors)[0]
        assert min(tame.values()) <= moved <= max(tame.values())
        assert max(moved / base, base / moved) < 2.0
    assert lead.drop_one_factor({**tame, "wild": 1e12}, anchors) < 2.0
