"""The fur_field family: curves, instances and MaterialX materials, as the translator sees them."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("pxr")

from denoisebench.generator.contract.scene_parts import CurvesShape  # noqa: E402
from denoisebench.generator.usd.translate import translate_usd  # noqa: E402
from denoisebench.scenes import get_family  # noqa: E402
from denoisebench.scenes.families import fur_field  # noqa: E402


def _seed(pool: str) -> int:
    return next(seed for seed in range(200) if fur_field.variant_pool(seed) == pool)


@pytest.mark.parametrize("pool", ["train", "held_out"])
def test_stage_translates_curves_instances_and_materialx_without_fallbacks(tmp_path, pool):
    seed = _seed(pool)
    translated = translate_usd(get_family("fur_field").author(tmp_path, seed=seed, frames=2, width=32, height=32))
    assert translated.warnings == []
    assert translated.effects_mismatch == {}
    assert translated.variants["pool"] == pool
    assert translated.variants["prototypes"][1] == ("crystal" if pool == "held_out" else "mushroom")

    curves = [s for s in translated.shapes if isinstance(s, CurvesShape)]
    assert len(curves) == 2 and sum(len(c.counts) for c in curves) >= fur_field.GRASS[0] + fur_field.FUR[0]
    assert all(np.isfinite(c.points).all() and (c.points[:, 3] > 0).all() for c in curves)

    summary = translated.summary()
    low, high = fur_field.INSTANCES
    assert low - 3 <= summary["instances"] <= high - 3  # three invisible ids
    kinds = {m["kind"] for m in summary["materials"]}
    assert kinds == {"MaterialX network in USD", "denoisebench hair"}
    surfaces = {m.get("surface") for m in summary["materials"]}
    assert {"ND_standard_surface_surfaceshader", "ND_open_pbr_surface_surfaceshader"} <= surfaces
    assert all(not m.get("fallbacks") for m in summary["materials"])
    hair = [b for b in translated.bsdfs.values() if b["type"] == "hair"]
    assert len(hair) == 1
    if pool == "held_out":
        assert hair[0]["pheomelanin"] > 1.0
