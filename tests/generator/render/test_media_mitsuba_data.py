"""Mitsuba's own participating-media render tests (mitsuba-data ``tests/scenes/participating_media``).

Each scene loads through ``generate-dataset --mitsuba``'s loader (:func:`load_mitsuba_xml`: its
sensor, its ``max_depth``, its media) and our reference render is held against the shipped RGB
reference with Mitsuba's own criterion (``src/render/tests/test_renders.py``): spp = 2e6 / pixels,
per pixel-channel z = |ours - ref| * sqrt(spp / max(ref_var, 1e-4)) in XYZ, two-sided p-values,
Sidak-corrected significance 1 %, and at least 99.75 % of pixel-channels accepted.

Needs the data: ``MITSUBA_DATA`` names a checkout (or extract) of github.com/mitsuba-renderer/mitsuba-data;
skipped without it (never vendored).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(os.environ.get("MITSUBA_DATA", "/nonexistent")) / "tests" / "scenes" / "participating_media"
SCENES = sorted(p.name for p in ROOT.glob("*.xml")) if ROOT.is_dir() else ["(MITSUBA_DATA unset)"]


def _xyz(mi, rgb: np.ndarray) -> np.ndarray:
    bitmap = mi.Bitmap(np.ascontiguousarray(rgb, dtype=np.float32), mi.Bitmap.PixelFormat.RGB)
    return np.array(bitmap.convert(mi.Bitmap.PixelFormat.XYZ, mi.Struct.Type.Float32, False))


def mitsuba_z_test(mi, ours_rgb, ref_rgb, ref_var_rgb, spp: int) -> tuple[float, bool]:
    """(fraction of pixel-channels accepted, passed) by Mitsuba's test_renders.py criterion."""
    ours, ref, var = (_xyz(mi, a) for a in (ours_rgb, ref_rgb, ref_var_rgb))
    var = np.maximum(var, 1e-4)
    z = np.abs(ours - ref) * np.sqrt(spp / var)
    p = np.vectorize(lambda v: math.erfc(v / math.sqrt(2.0)))(z.astype(np.float64))
    pixels = ref.shape[0] * ref.shape[1]
    alpha = 1.0 - (1.0 - 0.01) ** (1.0 / pixels)
    accepted = np.count_nonzero(p > alpha) / 3
    return accepted / pixels, accepted >= 0.9975 * pixels


@pytest.mark.skipif(not ROOT.is_dir(), reason="MITSUBA_DATA (a mitsuba-data checkout) is not set")
@pytest.mark.parametrize("name", SCENES)
def test_participating_media_scene_passes_mitsubas_z_test(mi, name):
    from denoisebench.generator.contract.render_plan import make_render_plan
    from denoisebench.generator.mitsuba_xml import load_mitsuba_xml
    from denoisebench.generator.render.frame import render_frame

    stem = name.rsplit("_", 1)[0]
    ref_path = ROOT / "refs" / f"{stem}_ref_rgb.exr"
    if not ref_path.is_file():
        pytest.skip(f"no RGB reference for {name}")
    ref = np.array(mi.Bitmap(str(ref_path)))[..., :3]
    ref_var = np.array(mi.Bitmap(str(ref_path).replace(".exr", "_var.exr")))[..., :3]
    height, width = ref.shape[:2]
    spp = int(2e6) // (width * height)
    translated, scene = load_mitsuba_xml(ROOT / name, frames=1)
    plan = make_render_plan(translated.effects_inferred, stage_max_depth=translated.max_depth)
    frame = render_frame(scene, translated.camera, 0, plan, width=width, height=height, spp=spp, seed=0, reference=True)
    fraction, passed = mitsuba_z_test(mi, frame.buffers["color"], ref, ref_var, spp)
    print(f"{name}: {fraction:.4%} of pixel-channels accepted")
    assert passed, f"{name}: {fraction:.4%} of pixel-channels accepted (Mitsuba asks 99.75 %)"
