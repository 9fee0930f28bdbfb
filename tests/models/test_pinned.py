"""Checkpoints written before the paper recipes still load and score as they did: the dpcn/kpcn/rae
weights shipped at commit 0d282b3 (kept in ``tests/data/legacy_weights/``; dpcn's branch of 3×3
layers, kpcn without the log depth variance, rae with per-frame exposure) give, through today's
code, the outputs the code of 0d282b3 gave.

Provenance: ``tests/data/shipped_models_input.npz`` holds two frames of
``synthetic_sequence("shapes", width=24, height=20, spp=4, frames=2, seed=11)`` (stored, so a
change to the synthetic generator cannot move this test); ``shipped_models_expected.npz`` is what
``load_denoiser(name).denoise`` returned for them with ``git archive 0d282b3`` on the path (one
torch thread; rae: reset, then both frames in order), when those weights were the shipped ones.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.registry import load_denoiser
from tests.support.paths import DATA  # noqa: E402

LEGACY = DATA / "legacy_weights"


def _frames() -> list[Frame]:
    data = np.load(DATA / "shipped_models_input.npz")
    frames = []
    for t in range(2):
        buffers = {k.split("/", 1)[1]: data[k] for k in data.files if k.startswith(f"{t}/")}
        frames.append(Frame(buffers=buffers, spp=4, scene="pinned", index=t))
    return frames


@pytest.mark.parametrize("name", ["dpcn", "kpcn", "rae"])
def test_legacy_checkpoints_give_the_outputs_they_gave_before(name):
    torch.set_num_threads(1)
    expected = np.load(DATA / "shipped_models_expected.npz")
    denoiser = load_denoiser(name, checkpoint=str(LEGACY / f"{name}_small_0d282b3.pt"))
    denoiser.reset()
    frames = _frames() if name == "rae" else _frames()[:1]
    for t, frame in enumerate(frames):
        np.testing.assert_allclose(denoiser.denoise(frame), expected[f"{name}/{t}"], rtol=1e-5, atol=1e-6)
