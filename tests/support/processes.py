"""Processes below the test process, read from ``/proc`` (Linux): which plugin workers are alive."""

from __future__ import annotations

import os

from tests.support.memory_profile import command_line, tree


def plugin_workers() -> set[int]:
    """Live processes below this one that run a plugin worker (``python -m denoisebench.plugins.worker``,
    sandboxed or not; a sandboxed worker's ``bwrap`` parents count too)."""
    return {
        pid for pid in tree(os.getpid()) if pid != os.getpid() and "denoisebench.plugins.worker" in command_line(pid)
    }
