"""Example packages installed for real for a test session, and removed after it.

``pip install -e`` of an example package writes into the environment the suite runs in (the
project's .venv). Left there, it changed what the next command in that checkout saw: ``make demo``
after ``make test`` benchmarked 13 denoisers (example_median too), after set-up alone 12. So a
fixture that installs one uninstalls it again, unless it was installed before the session began.
"""

from __future__ import annotations

import importlib.metadata
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

PIP = [sys.executable, "-m", "pip"]


def _installed(distribution: str) -> bool:
    try:
        importlib.metadata.distribution(distribution)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


@contextmanager
def editable_install(path: Path, distribution: str) -> Iterator[None]:
    """``pip install --no-deps --no-build-isolation --no-index -e path`` for the block; uninstalled after it
    when this call installed it (an install the user made stays)."""
    had = _installed(distribution)
    done = subprocess.run(
        [*PIP, "install", "--quiet", "--no-deps", "--no-build-isolation", "--no-index", "-e", str(path)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    try:
        yield
    finally:
        if not had:
            subprocess.run([*PIP, "uninstall", "--quiet", "--yes", distribution], capture_output=True, text=True)
