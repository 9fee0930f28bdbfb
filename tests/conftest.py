"""Fixtures shared by test modules, and what keeps one pytest process small over the whole run.

Memory: each test process (one, or one per pytest-xdist worker) imports torch, Mitsuba and USD and renders in hundreds of tests,
and what a test frees is not returned to the system on its own: Dr.Jit keeps freed arrays in its
allocation cache, glibc keeps freed heap pages, and cyclic garbage (Mitsuba scenes, torch modules)
waits for a full collection. After each test module :func:`release_memory` stops the plugin workers
the module left running, collects garbage, flushes Dr.Jit's allocation cache and trims the heap; objects alive at the end of collection (imported
modules, the collected tests) are frozen out of the collector first, so a full collection costs
milliseconds instead of a tenth of a second. A lean process matters twice: every process a test forks
(torch loader workers, a ``multiprocessing`` child) starts with the parent's resident pages.

Pitfalls: a module-scoped fixture that holds a scene or a dataset lives until its module ends (that
is when it is released), and a session-scoped one until the run ends: keep big objects module-scoped.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import importlib
import site
import sys
import sysconfig

import pytest

from tests.support.editable import editable_install
from tests.support.paths import REPO


@pytest.fixture(scope="session")
def mi():
    """Mitsuba on its LLVM variant; tests that compare against Mitsuba's own integrators need it."""
    from denoisebench.mitsuba_runtime import load_mitsuba

    module = load_mitsuba()
    if not module.variant().startswith("llvm"):
        pytest.skip("needs the LLVM variant (libLLVM >= 16)")
    return module


@pytest.fixture(scope="session")
def installed_example():
    """The example plugin package (examples/denoisebench-example-plugin) installed for the session with
    ``pip install -e`` and removed after it (tests/support/editable.py); its denoiser's name."""
    with editable_install(REPO / "examples" / "denoisebench-example-plugin", "denoisebench-example-plugin"):
        # make it importable in this process too (its .pth is read at start-up), so that tests that
        # list and load every available denoiser after this one find a working entry point
        site.addsitedir(sysconfig.get_paths()["purelib"])
        importlib.invalidate_caches()
        yield "example_median"
    importlib.invalidate_caches()


def _malloc_trim() -> None:
    """Give glibc's free heap pages back to the system (nothing elsewhere)."""
    name = ctypes.util.find_library("c")
    try:
        trim = ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        trim = None
    if trim is not None:
        trim(0)


def release_memory() -> None:
    """Stop plugin workers left running, collect garbage, empty Dr.Jit's allocation cache (when Dr.Jit is
    loaded), trim the heap.

    A plugin proxy a test did not close keeps its worker process (tens of MiB, a sandbox's ``bwrap`` pair)
    until the interpreter exits: :mod:`denoisebench.plugins.process` holds every live worker for its exit
    hook, which is called here instead."""
    process = sys.modules.get("denoisebench.plugins.process")
    if process is not None:
        process._close_all()
    gc.collect()
    drjit = sys.modules.get("drjit")
    if drjit is not None:
        drjit.flush_malloc_cache()
    _malloc_trim()


def pytest_collection_finish(session):
    gc.collect()
    gc.freeze()  # what lives now lives to the end: later full collections skip it


def pytest_unconfigure(config):
    gc.unfreeze()  # the interpreter's shutdown frees them as usual


@pytest.fixture(autouse=True, scope="module")
def _release_memory_after_module():
    yield
    release_memory()
