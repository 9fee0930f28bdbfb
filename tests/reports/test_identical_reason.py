"""The report's stated reason for oidn = oidn_balanced holds on this installation: with noisy albedo and
normal, OIDN's high and balanced qualities give bit-identical outputs (the same base weights; fast math
is a no-op on a CPU device), and fast (smaller weights) does not. If a pyoidn upgrade changes this, the
reason in reports/identical.py is stale and this test says so."""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.registry import DenoiserUnavailableError
from denoisebench.reports.identical import KNOWN_REASONS


def _oidn(quality: str):
    from denoisebench.baselines.oidn import OIDN

    try:
        return OIDN(quality)
    except DenoiserUnavailableError as error:
        pytest.skip(str(error))


@pytest.mark.parametrize("size", [24, 48])
def test_oidn_high_and_balanced_agree_in_every_bit_and_fast_does_not(size):
    rng = np.random.default_rng(size)
    buffers = {
        "color": rng.exponential(1.0, (size, size, 3)).astype(np.float32),
        "albedo": rng.random((size, size, 3)).astype(np.float32),
        "normal": (rng.random((size, size, 3)) * 2 - 1).astype(np.float32),
    }
    frame = Frame(buffers=buffers, spp=4)
    high, balanced, fast = (_oidn(q).denoise(frame) for q in ("high", "balanced", "fast"))
    assert np.array_equal(high, balanced)
    assert not np.array_equal(high, fast)
    assert "bit-identical" in KNOWN_REASONS[frozenset({"oidn", "oidn_balanced"})]
