"""Write a folder atomically: fill a hidden sibling folder, then rename it into place.

Notes
-----
``OUT`` must not exist unless ``force`` is given; then the old folder is moved aside and removed
only after the new one is in place. The staging folder is ``.<name>.<pid>.export-tmp`` in ``OUT``'s
parent (same file system, so the rename is atomic); a failure removes it and leaves ``OUT`` as it
was. The checks (:func:`check_target`) run before any work, so a refused export costs nothing.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator
from pathlib import Path

from denoisebench.errors import UserInputError
from denoisebench.outputs import check_writable_dir


def check_target(out: str | os.PathLike, force: bool, dataset_root: Path | None = None) -> Path:
    """``out`` as an absolute path, or UserInputError (exists without ``force``, inside the dataset...)."""
    target = check_writable_dir(out, "OUT")
    if target.exists() and not force:
        raise UserInputError(f"OUT {target} exists; pass --force to replace it")
    if dataset_root is not None:
        root = dataset_root.resolve()
        resolved = target.resolve()
        if resolved == root or root in resolved.parents or resolved in root.parents:
            raise UserInputError(f"OUT {target} overlaps the dataset folder {root}; export somewhere else")
    return target


@contextlib.contextmanager
def staged_folder(target: Path) -> Iterator[Path]:
    """Yield an empty staging folder; on success it becomes ``target`` (replacing an old one)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.parent / f".{target.name}.{os.getpid()}.export-tmp"
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir()
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    old = None
    if target.exists():
        old = target.parent / f".{target.name}.{os.getpid()}.export-old"
        shutil.rmtree(old, ignore_errors=True)
        os.replace(target, old)
    os.replace(staging, target)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
