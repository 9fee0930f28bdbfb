"""Open a dataset folder and yield :class:`~denoisebench.dataset.frame.Frame` / ``Sequence`` (torch-free).

>>> ds = open_dataset("out")                       # doctest: +SKIP
>>> ds.split("test")                               # scene names
>>> ds.scene("cornell_0").plan                     # the render plan dict
>>> for frame in ds.frames("cornell_0", 4): ...    # Frames at 4 spp, reference attached
>>> seq = ds.sequence("cornell_0", 4)              # all frames, in order

A Frame carries the noisy buffers (``color``, features, ``*_var``), ``reference`` (the reference
color, H×W×3) when the scene has one, ``samples`` (S×H×W×C per buffer) when per-sample data was
written, and ``meta``: the frame record's ``file``, ``seconds``, ``seconds_per_spp``, ``rel_se``,
and ``reference_file``, ``reference_spp``, ``reference_seconds``, ``reference_rel_se``,
``reference_too_noisy``, ``reference_half_spp`` (the spp of the reference's two halves, or None:
``metrics.half_reference``) and ``reference_buffers`` (every layer of the reference file: ``color``,
``color_var`` and, when written, ``diffuse``/``specular`` and their variances).

Every problem is a one-line :class:`~denoisebench.dataset.errors.DatasetError` naming the scene,
frame and file: an unknown scene or spp, a frame with no record (incomplete dataset), a missing or
corrupt file, NaN/Inf in it, and with ``verify=True`` a sha256 that differs from the manifest.

Frame records are loaded on demand (schema version 2, :mod:`.frame_index`): opening a dataset parses
only ``dataset.json`` (config, scenes, splits), :meth:`Dataset.frame` looks up the records it needs
by key, and :meth:`Dataset.scene` loads one scene's records (the last scene's are kept). A
version-1 dataset (records inline in ``dataset.json``) opens as before.
:meth:`Dataset.content_hash` streams the manifest scene by scene.

Manifest paths are untrusted: :meth:`Dataset.path` confines each to the dataset root (relative,
no ``..`` part, and the resolved path, symlinks followed, inside the resolved root) before any
file is opened; a path that escapes is a DatasetError naming it.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np

from denoisebench.dataset import layout
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.exr_io import canonical_json, load_exr, load_samples_exr
from denoisebench.dataset.frame import Frame, Sequence
from denoisebench.dataset.frame_index import FrameIndexReader
from denoisebench.dataset.manifest import SPLITS, load_header, manifest_without_timings


@dataclass(frozen=True)
class SceneInfo:
    """One scene's manifest record (without its frame records, which stay in ``renders``)."""

    name: str
    record: dict

    @property
    def plan(self) -> dict:
        return self.record.get("plan", {})

    @property
    def family(self) -> str:
        return self.record.get("family", "")

    @property
    def seed(self) -> int:
        return self.record.get("seed", 0)

    @property
    def frame_count(self) -> int:
        return int(self.record["frames"])

    @property
    def spp(self) -> list[int]:
        return list(self.record["spp"])

    @property
    def ref_spp(self) -> int | None:
        return self.record.get("ref_spp")

    @property
    def width(self) -> int:
        return int(self.record["width"])

    @property
    def height(self) -> int:
        return int(self.record["height"])

    @property
    def effects(self):
        return self.record.get("effects", {})

    @property
    def camera(self) -> dict:
        return self.record.get("camera", {})

    @property
    def usd(self) -> str:
        return self.record.get("usd", layout.usd_path(self.name))

    @property
    def has_reference(self) -> bool:
        return bool(self.record.get("ref_spp"))

    @property
    def meta(self) -> dict:
        return {k: v for k, v in self.record.items() if k != "renders"}


class Dataset:
    """A dataset folder opened by :func:`open_dataset`.

    ``manifest`` is what ``dataset.json`` holds: for schema version 2 the scenes carry no
    ``renders`` (use :meth:`scene` or :meth:`record`); for version 1 they do."""

    def __init__(self, root: Path, manifest: dict, verify: bool = False):
        self.root = root
        self.manifest = manifest
        self.verify = verify
        self._index = None
        if int(manifest.get("schema_version", 1)) >= 2:
            self._index = FrameIndexReader(self.path(layout.INDEX_NAME, "frame index"))
        self._cached: tuple[str, dict] | None = None

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_cached"] = None
        return state

    # ------------------------------------------------------------------ catalogue

    @property
    def config(self) -> dict:
        return self.manifest["config"]

    @property
    def config_hash(self) -> str:
        return self.manifest["config_hash"]

    @property
    def versions(self) -> dict:
        return self.manifest["versions"]

    @property
    def complete(self) -> bool:
        return bool(self.manifest.get("complete", False))

    @property
    def scenes(self) -> list[str]:
        return sorted(self.manifest["scenes"])

    @property
    def splits(self) -> dict[str, list[str]]:
        return {split: list(self.manifest["splits"].get(split, [])) for split in SPLITS}

    def split(self, name: str) -> list[str]:
        """Scene names of split ``name`` (train, val or test)."""
        if name not in SPLITS:
            raise DatasetError(f"unknown split {name!r}; splits are {', '.join(SPLITS)}")
        return self.splits[name]

    def _scene_record(self, name: str) -> dict:
        try:
            return self.manifest["scenes"][name]
        except KeyError:
            known = ", ".join(self.scenes[:8]) + (", ..." if len(self.scenes) > 8 else "")
            raise DatasetError(f"{self.root}: no scene {name!r} (scenes: {known or 'none'})") from None

    def scene(self, name: str, *, renders: bool = True) -> SceneInfo:
        """Scene ``name``; its record has ``renders`` (its frame records: one look-up of that scene's
        records in a version-2 dataset, kept until another scene is asked for) unless ``renders=False``."""
        record = self._scene_record(name)
        if self._index is None or not renders:
            return SceneInfo(name, record)
        if self._cached is None or self._cached[0] != name:
            self._cached = (name, self._index.scene(name))
        return SceneInfo(name, {**record, "renders": self._cached[1]})

    def record(self, scene: str, spp: int | str, index: int) -> dict | None:
        """The manifest record of frame ``index`` of ``scene`` at ``spp`` (or ``"reference"``), or None."""
        return self._lookup(scene, layout.spp_key(spp), layout.frame_key(index))

    def _lookup(self, scene: str, key: str, fkey: str) -> dict | None:
        if self._index is None:
            return self._scene_record(scene).get("renders", {}).get(key, {}).get(fkey)
        if self._cached is not None and self._cached[0] == scene:
            return self._cached[1].get(key, {}).get(fkey)
        return self._index.get(scene, key, fkey)

    def content_hash(self) -> str:
        """sha256 of the canonical JSON of the whole manifest without timings, streamed one scene at a time.

        The same text as ``canonical_json(manifest_without_timings(load_manifest(...)))``, so a
        version-1 dataset keeps the hash it had; memory is one scene's records, time O(records)."""
        header = manifest_without_timings({k: v for k, v in self.manifest.items() if k != "scenes"})
        marker = "\u0000scenes\u0000"
        parts = canonical_json({**header, "scenes": marker}).split(canonical_json(marker))
        if len(parts) != 2:
            raise DatasetError(f"{self.root}: the manifest holds the reserved text {marker!r}")
        head, tail = parts
        digest = hashlib.sha256(head.encode())
        digest.update(b"{")
        for n, name in enumerate(sorted(self.manifest["scenes"])):
            record = self.scene(name).record
            digest.update(f"{',' if n else ''}{canonical_json(name)}:".encode())
            digest.update(canonical_json(manifest_without_timings(record)).encode())
        digest.update(b"}")
        digest.update(tail.encode())
        return digest.hexdigest()

    def _frame_record(self, scene: str, key: str, index: int, what: str, expected: str) -> dict:
        info = self.scene(scene, renders=False)
        if not 0 <= index < info.frame_count:
            raise DatasetError(f"scene {scene!r} has frames 0..{info.frame_count - 1}, not {index}")
        record = self._lookup(scene, key, layout.frame_key(index))
        if record is None:
            raise DatasetError(
                f"{self.root}: scene {scene!r} frame {index} has no {what} in the manifest "
                f"(expected {self.root / expected}; incomplete dataset?)"
            )
        return record

    # ------------------------------------------------------------------ paths

    def path(self, relative: object, what: str = "manifest path") -> Path:
        """``root / relative``, refused (DatasetError) unless it stays inside the dataset root.

        ``relative`` must be a non-empty relative POSIX path without ``..`` parts, and the path it
        names, symlinks resolved, must lie inside the resolved root: an absolute path
        (``/etc/passwd``), ``../other/frame.exr`` or a symlink pointing out are all refused.
        """
        text = relative if isinstance(relative, str) else None
        if not text or "\0" in text:
            raise DatasetError(f"{self.root}: {what} {relative!r} in the manifest is not a relative path")
        posix = PurePosixPath(text)
        if (
            posix.is_absolute()
            or PureWindowsPath(text).is_absolute()
            or PureWindowsPath(text).drive
            or ".." in posix.parts
        ):
            raise DatasetError(f"{self.root}: {what} {text!r} in the manifest leaves the dataset folder (refused)")
        full = self.root / posix
        root = self.root.resolve()
        resolved = full.resolve()
        if resolved != root and root not in resolved.parents:
            raise DatasetError(
                f"{self.root}: {what} {text!r} resolves to {resolved}, outside the dataset folder (refused)"
            )
        return full

    # ------------------------------------------------------------------ loading

    def reference(self, scene: str, index: int) -> tuple[dict[str, np.ndarray], dict]:
        """The reference file's layers and its manifest record."""
        record = self._frame_record(scene, layout.REFERENCE, index, "reference", layout.reference_path(scene, index))
        what = f"scene {scene!r} frame {index} reference file"
        path = self.path(record.get("file"), what)
        contents = load_exr(path, record["sha256"] if self.verify else None, what=what)
        if "color" not in contents.buffers:
            raise DatasetError(f"{what} {path} has no color layer")
        return contents.buffers, record

    def frame(
        self,
        scene: str,
        spp: int,
        index: int,
        *,
        reference: bool = True,
        samples: bool = True,
        buffers: Iterable[str] | None = None,
    ) -> Frame:
        """Frame ``index`` of ``scene`` at ``spp``.

        ``reference``: attach the reference when the scene has one; ``samples``: load per-sample
        data when present; ``buffers``: keep only these noisy buffers (``color`` always kept).
        """
        info = self.scene(scene, renders=False)
        spp = int(spp)
        if spp not in info.spp:
            raise DatasetError(f"scene {scene!r} was rendered at spp {info.spp}, not {spp}")
        record = self._frame_record(
            scene, layout.spp_key(spp), index, f"{spp}-spp frame", layout.noisy_path(scene, spp, index)
        )
        what = f"scene {scene!r} frame {index} ({spp} spp) file"
        path = self.path(record.get("file"), what)
        contents = load_exr(path, record["sha256"] if self.verify else None, what=what)
        layers = contents.buffers
        if "color" not in layers:
            raise DatasetError(f"{what} {path} has no color layer")
        if buffers is not None:
            wanted = ["color"] + [b for b in buffers if b != "color"]
            absent = [b for b in wanted if b not in layers]
            if absent:
                raise DatasetError(
                    f"{what} {path} has no buffer(s) {', '.join(absent)} (has {', '.join(sorted(layers))})"
                )
            layers = {b: layers[b] for b in wanted}
        meta = {k: record[k] for k in ("file", "seconds", "seconds_per_spp", "rel_se") if k in record}
        ref_color = None
        if reference and info.has_reference:
            ref_layers, ref_record = self.reference(scene, index)
            ref_color = ref_layers["color"]
            if ref_color.shape != layers["color"].shape:
                raise DatasetError(
                    f"scene {scene!r} frame {index} reference is {ref_color.shape[:2]}, the frame is {layers['color'].shape[:2]}"
                )
            meta.update(
                reference_file=ref_record["file"],
                reference_spp=ref_record.get("spp"),
                reference_seconds=ref_record.get("seconds"),
                reference_rel_se=ref_record.get("rel_se"),
                reference_too_noisy=ref_record.get("reference_too_noisy", False),
                reference_half_spp=(ref_record.get("reference_adaptive") or {}).get("half_spp"),
                reference_buffers=ref_layers,
            )
        sample_data = None
        if samples and record.get("samples"):
            entry = record["samples"]
            samples_what = f"scene {scene!r} frame {index} ({spp} spp) samples file"
            sample_data = load_samples_exr(
                self.path(entry.get("file"), samples_what),
                entry["sha256"] if self.verify else None,
                what=samples_what,
            ).samples
            meta["samples_file"] = entry["file"]
        try:
            return Frame(
                buffers=layers, spp=spp, scene=scene, index=index, reference=ref_color, samples=sample_data, meta=meta
            )
        except ValueError as exc:
            raise DatasetError(f"{what} {path}: {exc}") from None

    def frames(self, scene: str, spp: int, **options) -> Iterator[Frame]:
        """Frames 0..N−1 of ``scene`` at ``spp``, loaded one at a time (options as :meth:`frame`)."""
        for index in range(self.scene(scene, renders=False).frame_count):
            yield self.frame(scene, spp, index, **options)

    def sequence(self, scene: str, spp: int, **options) -> Sequence:
        """All frames of ``scene`` at ``spp`` in order; ``meta`` is the scene record (plan, camera...)."""
        info = self.scene(scene, renders=False)
        return Sequence(scene=scene, spp=int(spp), frames=list(self.frames(scene, spp, **options)), meta=info.meta)


def open_dataset(path: str | os.PathLike, verify: bool = False) -> Dataset:
    """Open the dataset at ``path`` (the folder, or its ``dataset.json``).

    ``verify``: check every file's sha256 against the manifest as it is read.
    """
    path = Path(path)
    if path.name == layout.MANIFEST_NAME and path.is_file():
        root, manifest_path = path.parent, path
    else:
        root, manifest_path = path, path / layout.MANIFEST_NAME
    if not root.exists():
        raise DatasetError(f"dataset folder {root} does not exist")
    return Dataset(root, load_header(manifest_path), verify=verify)
