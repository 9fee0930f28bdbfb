"""How many threads a baseline's numpy work may use (numpy's ufuncs and einsum release the GIL)."""

from __future__ import annotations

import os

MAX_THREADS = 8  # beyond this, memory bandwidth, not cores, bounds the filters here


def available_threads(limit: int = MAX_THREADS) -> int:
    """The CPUs this process may run on (its affinity mask, not the machine's count), at most ``limit``."""
    try:
        available = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        available = os.cpu_count() or 1
    return max(1, min(available, limit))
