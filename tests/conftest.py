"""Fixtures shared by test modules."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def mi():
    """Mitsuba on its LLVM variant; tests that compare against Mitsuba's own integrators need it."""
    from denoisebench.mitsuba_runtime import load_mitsuba

    module = load_mitsuba()
    if not module.variant().startswith("llvm"):
        pytest.skip("needs the LLVM variant (libLLVM >= 16)")
    return module
