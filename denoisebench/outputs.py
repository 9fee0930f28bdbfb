"""Check that an output folder or file can be written, before any work is done.

A command that measures for minutes and then fails to write its report (``--out`` under a
regular file, under ``/proc``, on a read-only mount) wastes the run. These checks create nothing
the command would not create anyway: they find the deepest existing ancestor of the target, require
it to be a folder, and create and delete one probe file there (``tempfile``), which is what tells
a read-only or pseudo file system apart (``os.access`` says yes to root everywhere).

Failures are one-line :class:`~denoisebench.errors.UserInputError` (exit 2) naming the path.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from denoisebench.errors import UserInputError


def _existing_ancestor(path: Path) -> Path:
    current = path
    while not current.exists() and current != current.parent:
        current = current.parent
    return current


def _probe(folder: Path, option: str, target: Path) -> None:
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".denoisebench-probe-"):
            pass
    except OSError as error:
        raise UserInputError(f"{option} {target}: cannot write in {folder} ({error.strerror or error})") from None


def check_writable_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """``path`` is (or can become) a folder this process can write files in; else UserInputError."""
    target = Path(path).expanduser().absolute()
    if target.exists() and not target.is_dir():
        raise UserInputError(f"{option} {target} exists and is not a folder")
    ancestor = _existing_ancestor(target)
    if not ancestor.is_dir():
        raise UserInputError(f"{option} {target}: {ancestor} is a file, not a folder")
    _probe(ancestor, option, target)
    return target


def check_writable_file(path: str | os.PathLike, option: str = "--db") -> Path:
    """``path`` is a writable file, or one that can be created (its folder checked as above)."""
    target = Path(path).expanduser().absolute()
    if target.exists():
        if target.is_dir():
            raise UserInputError(f"{option} {target} is a folder, not a file")
        if not os.access(target, os.R_OK | os.W_OK):
            raise UserInputError(f"{option} {target} is not writable")
        check_writable_dir(target.parent, option)  # SQLite writes its journal/WAL beside the file
        return target
    check_writable_dir(target.parent, option)
    return target
