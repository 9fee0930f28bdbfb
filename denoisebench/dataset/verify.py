"""Check a dataset's files against its manifest before they are used (datasets are untrusted input).

:func:`verify_files` hashes every listed file (sha256, streamed) and compares it with the manifest's
record; the first mismatch, missing file, missing hash or path that leaves the dataset folder is a
one-line :class:`~denoisebench.dataset.errors.DatasetError` naming the file. The benchmark runs it
over :func:`run_files` before its first unit, so a reference that was scaled after the dataset was
made, or a truncated (corrupt) EXR, is refused up front instead of being scored or found mid-run.

Pitfall: a hash check proves that the files are those the manifest lists, not that the manifest is
genuine; the dataset hash a run records (of the manifest, sha256s included) is what ties results to
one dataset.
"""

from __future__ import annotations

import hashlib
import sys
from dataclasses import dataclass

from tqdm import tqdm

from denoisebench.dataset import layout
from denoisebench.dataset.errors import DatasetError

_CHUNK = 1 << 20


@dataclass(frozen=True)
class ListedFile:
    """One file a manifest lists: what it is (for messages), its relative path and sha256."""

    what: str
    file: object
    sha256: object


def run_files(dataset, scenes: list[str], spp: list[int], *, samples: bool = True) -> list[ListedFile]:
    """Every file a benchmark of ``scenes`` at ``spp`` reads: noisy frames (and their per-sample
    files when ``samples``) and references, in manifest order."""
    files: list[ListedFile] = []
    for scene in scenes:
        info = dataset.scene(scene)
        renders = info.record.get("renders", {})
        for index in range(info.frame_count):
            key = layout.frame_key(index)
            ref = renders.get(layout.REFERENCE, {}).get(key)
            if ref is not None:
                files.append(
                    ListedFile(f"scene {scene!r} frame {index} reference file", ref.get("file"), ref.get("sha256"))
                )
            for s in spp:
                record = renders.get(layout.spp_key(s), {}).get(key)
                if record is None:
                    continue
                what = f"scene {scene!r} frame {index} ({s} spp) file"
                files.append(ListedFile(what, record.get("file"), record.get("sha256")))
                entry = record.get("samples")
                if samples and isinstance(entry, dict):
                    files.append(ListedFile(f"{what[:-5]} samples file", entry.get("file"), entry.get("sha256")))
    return files


def file_sha256(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for chunk in iter(lambda: handle.read(_CHUNK), b""):
            digest.update(chunk)
    return digest.hexdigest()


def verify_files(dataset, files: list[ListedFile], *, progress: bool = True) -> int:
    """Check every file of ``files``; return how many bytes were hashed. DatasetError on the first problem."""
    total = 0
    for listed in tqdm(
        files, desc="verify: sha256 of dataset files", unit="file", file=sys.stderr, disable=not progress, leave=False
    ):
        path = dataset.path(listed.file, listed.what)
        if not isinstance(listed.sha256, str) or len(listed.sha256) != 64:
            raise DatasetError(
                f"{listed.what} {path} has no sha256 in the manifest; cannot verify it (--no-verify skips the check)"
            )
        try:
            digest = file_sha256(path)
            total += path.stat().st_size
        except OSError as error:
            raise DatasetError(f"{listed.what} {path} cannot be read ({error.strerror or error})") from None
        if digest != listed.sha256.lower():
            raise DatasetError(
                f"{listed.what} {path} does not match the manifest (sha256 {digest[:12]}…, expected "
                f"{listed.sha256[:12]}…): changed or corrupt after the dataset was made"
            )
    return total
