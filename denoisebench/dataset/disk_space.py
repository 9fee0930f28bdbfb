"""Free space: checked before a long write, and a full disk reported in one line.

``generate-dataset`` checks its output folder's filesystem before rendering anything
(:func:`check_generate`): where even a lower bound of the dataset's size does not fit, it is exit 2
with one line naming the folder, the space needed and the space free. While it runs, or while
``run-benchmark`` writes its store and report, a write that finds the disk full
(``ENOSPC``/``EDQUOT``, SQLite's "database or disk is full") stops the command with one line
naming the folder and about how much more it needs (:func:`full_disk_is_one_line`, exit 2).
Every file is written atomically (:mod:`.atomic`; SQLite's transactions), so nothing partial is
left, and the same command resumes once space is freed, to the same bytes.

Notes
-----
* The up-front figure is a **lower bound**, so that a dataset that would fit is never refused:
  :data:`MIN_EXR_BYTES_PER_PIXEL` bytes per pixel per EXR file (the color's three float32
  channels; render noise leaves them nearly incompressible). Measured on the Cornell box at 64 px:
  24.5 B/px for a reference, 36 and 72 B/px for the noisy files at 1 and 4 spp. A dataset between
  the bound and its real size starts and then stops at the full disk, resumable.
* A resumed output folder (its ``dataset.json`` exists) is not checked up front: what is left to
  render is known only once the manifest is read. The stop mid-run still reports it.
* Mid-run, the space needed is projected from the EXR files written so far (their mean size times
  the files still missing), or the lower bound when there are none yet; for a results store, from
  its size per unit stored (:func:`store_need`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import sqlite3
from collections.abc import Callable, Iterator
from pathlib import Path

from denoisebench.errors import UserInputError

#: Lower bound of one EXR file's bytes per pixel (see the module notes).
MIN_EXR_BYTES_PER_PIXEL = 12
_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT}


class DiskFullError(UserInputError):
    """The output's filesystem has (or will have) no room: one line, exit 2."""


def human(n: float | None) -> str:
    if n is None:
        return "an unknown amount"
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"


def _existing(path: Path) -> Path:
    path = Path(path).absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def free_bytes(path: str | os.PathLike) -> int | None:
    """Bytes free for this user on the filesystem that ``path`` (or its nearest existing folder) is on."""
    try:
        return shutil.disk_usage(_existing(Path(path))).free
    except OSError:
        return None


def check_fits(folder: str | os.PathLike, needed: int, option: str, what: str) -> None:
    """DiskFullError when ``needed`` bytes do not fit where ``folder`` lies."""
    free = free_bytes(folder)
    if free is not None and needed > free:
        raise DiskFullError(
            f"{option} {folder}: {what} needs at least {human(needed)}, and its filesystem has {human(free)} free"
        )


def generate_lower_bound(width: int, height: int, frames: int, rungs: int) -> int:
    """Bytes a dataset of ``frames`` frames takes at least: one EXR per rung and a reference each."""
    return int(frames) * (int(rungs) + 1) * int(width) * int(height) * MIN_EXR_BYTES_PER_PIXEL


def check_generate(out: str | os.PathLike, *, width: int, height: int, frames: int, rungs: int) -> None:
    """Before rendering: exit 2 where the lower bound does not fit (not for a resumed folder)."""
    if (Path(out) / "dataset.json").exists():
        return
    check_fits(out, generate_lower_bound(width, height, frames, rungs), "--out", "the dataset")


def remaining_exr_bytes(out: str | os.PathLike, expected_files: int, lower_bound_per_file: int) -> int:
    """Bytes the EXR files still missing under ``out`` will take, from the mean of those written."""
    sizes = [p.stat().st_size for p in Path(out).rglob("*.exr") if not p.name.startswith(".")]
    per_file = max(sum(sizes) / len(sizes), lower_bound_per_file) if sizes else lower_bound_per_file
    return int(max(expected_files - len(sizes), 1) * per_file)


def is_disk_full(error: BaseException) -> bool:
    if isinstance(error, OSError) and error.errno in _FULL_ERRNOS:
        return True
    return isinstance(error, sqlite3.OperationalError) and "full" in str(error).lower()


def _folder_of(error: BaseException, default: Path) -> Path:
    name = getattr(error, "filename", None)
    return Path(name).parent if name else default


@contextlib.contextmanager
def full_disk_is_one_line(
    folder: str | os.PathLike, option: str, what: str, remaining: Callable[[], int | str | None] | None = None
) -> Iterator[None]:
    """Turn a full disk inside the block into DiskFullError naming the folder and the space needed
    (``remaining()``: bytes, or a phrase such as :func:`store_need`'s)."""
    try:
        yield
    except DiskFullError:
        raise
    except Exception as error:
        if not is_disk_full(error):
            raise
        where = _folder_of(error, Path(folder))
        try:
            needed = remaining() if remaining else None
        except Exception:  # noqa: BLE001 - the estimate must not hide the disk being full
            needed = None
        need = needed if isinstance(needed, str) else f"about {human(needed)} more"
        raise DiskFullError(
            f"no space left on the filesystem of {where} ({option} {folder}): {what} needs {need} "
            f"({human(free_bytes(where))} free); free some and run the same command again to resume"
        ) from None


def store_need(db: str | os.PathLike) -> str:
    """What a results store needs per further unit, from its size and the units it holds."""
    path = Path(db)
    size = sum(p.stat().st_size for p in (path, Path(f"{path}-wal")) if p.exists())
    try:
        with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as conn:
            units = int(conn.execute("SELECT COUNT(*) FROM units").fetchone()[0])
    except sqlite3.Error:
        units = 0
    if not units:
        return f"more than its {human(size)}"
    return f"about {human(size / units)} more per unit still to measure ({units} stored)"
