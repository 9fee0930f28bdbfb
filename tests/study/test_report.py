"""The study report's paired ratio: a scene's own difficulty cancels, black scenes are left out."""

from __future__ import annotations

import pytest

from denoisebench.study.report import paired_ratio


def _part(per_scene):
    return {"scores": {"relmse_robust": {"per_scene": per_scene}}}


def test_paired_ratio_is_the_geometric_mean_of_per_scene_ratios():
    full = [_part({"a": 0.01, "b": 1.0, "black": 0.0})]
    same = paired_ratio(full, full, "relmse_robust", ["a", "b", "black"])
    assert same["value"] == pytest.approx(1.0) and same["low"] == pytest.approx(1.0) and same["scenes"] == 2
    # twice as bad on an easy scene, 8x on a hard one: geometric mean 4, whatever the scenes' scales
    worse = [_part({"a": 0.02, "b": 8.0, "black": 0.0})]
    ratio = paired_ratio(worse, full, "relmse_robust", ["a", "b", "black"])
    assert ratio["value"] == pytest.approx(4.0) and 2.0 - 1e-9 <= ratio["low"] <= 4.0 <= ratio["high"] <= 8.0 + 1e-9
    # seeds are averaged per scene before the ratio
    seeds = [_part({"a": 0.01, "b": 1.0}), _part({"a": 0.03, "b": 3.0})]
    assert paired_ratio(seeds, full, "relmse_robust", ["a", "b"])["value"] == pytest.approx(2.0)
    assert paired_ratio(full, full, "relmse_robust", ["black"])["value"] is None
