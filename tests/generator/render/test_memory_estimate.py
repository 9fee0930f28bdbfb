"""The dataset's memory estimate (dataset/bounds.py) against what rendering a frame allocates.

Peer: a frame job rendered as generate-dataset renders it (render_ladder, then the reference
while the rungs are held), its host peak measured with ``tracemalloc`` (NumPy reports its buffers
there) and its device peak with Dr.Jit's allocation watermark. Small frames of both lane layouts
(several lanes per pixel at 48x32, one at 160x128), with and without per-sample data.
"""

from __future__ import annotations

import tracemalloc

import pytest

from denoisebench.dataset import bounds
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render import frame as feature_renderer
from denoisebench.generator.render.scene import build_mitsuba_scene
from denoisebench.generator.usd.translate import translate_usd
from denoisebench.scenes import get_family

RUNGS = (1, 2, 4, 16)
REF_SPP = 8
#: measured / estimated peak stays within this range (the estimate leaves out the scene, the
#: interpreter and small arrays; the host and device peaks are measured apart, so their sum can
#: exceed the joint peak).
FACTOR = (0.8, 1.3)


def test_renderer_constants_are_the_estimates():
    assert bounds.MAX_PATHS_PER_PASS == feature_renderer.MAX_PATHS_PER_PASS
    assert bounds.TARGET_LANES == feature_renderer.TARGET_LANES
    every = sum(feature_renderer.FEATURE_CHANNELS.values()) + 9  # color, diffuse, specular
    assert bounds.NOISY_CHANNELS == every
    per_sample = sum(feature_renderer.SAMPLE_BUFFERS.values()) + feature_renderer.RANDOM_PARAMETER_CHANNELS["pixel"]
    assert bounds.SAMPLE_BYTES_PER_SAMPLE == per_sample * 4


@pytest.mark.parametrize("width, height", [(48, 32), (160, 128)])
@pytest.mark.parametrize("samples", [False, True])
def test_estimate_matches_the_measured_peak(mi, tmp_path, width, height, samples):
    import drjit as dr

    translated = translate_usd(get_family("cornell").author(tmp_path, seed=0, frames=2, width=width, height=height))
    scene = build_mitsuba_scene(translated)
    plan = make_render_plan(translated.effects, RenderOptions(per_sample=samples), stage_max_depth=translated.max_depth)
    kw = dict(width=width, height=height, seed=1)

    def job():
        rungs = feature_renderer.render_ladder(scene, translated.camera, 1, plan, rungs=RUNGS, **kw)
        reference = feature_renderer.render_frame(scene, translated.camera, 1, plan, spp=REF_SPP, reference=True, **kw)
        return rungs, reference

    job()  # compile and record the passes first (their recordings are not a frame's memory)
    dr.flush_malloc_cache()
    dr.detail.malloc_clear_statistics()
    device_before = dr.detail.malloc_watermark(dr.JitBackend.LLVM)
    tracemalloc.start()
    try:
        rungs, reference = job()
        host = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    device = dr.detail.malloc_watermark(dr.JitBackend.LLVM) - device_before
    assert len(rungs) == len(RUNGS) and (rungs[-1].samples is not None) == samples
    estimate = bounds.frame_memory_bytes(width, height, RUNGS, REF_SPP, samples)
    ratio = (host + device) / estimate
    assert FACTOR[0] <= ratio <= FACTOR[1], (host, device, estimate, ratio)
