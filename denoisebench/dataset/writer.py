"""Write a dataset folder: EXR files and the ``dataset.json`` records, resumable.

:class:`DatasetWriter` is driven by one process (render workers hand their arrays to it). Every
file is written atomically, then its record is committed to the frame index (``dataset.sqlite``,
:mod:`.frame_index`): one small durable transaction per record, whatever the number of records
already written, so recording the 10 000th frame costs what the first did. A frame is **done**
when its record is committed and its file(s) exist with the recorded sha256
(:meth:`DatasetWriter.is_done`), so a run killed at any point (``kill -9`` included) loses at most
the frame in flight, and started again with the same config skips what is done and rewrites
anything else: the EXR bytes and the manifest without timings come out the same as from an
uninterrupted run (see :mod:`.manifest`).

``dataset.json`` (the header: config, versions, scenes, splits; schema version 2) is written when
the writer opens, before the first record after scenes were added or a finished dataset was
changed, and by :meth:`DatasetWriter.finalize`: a constant number of times per run, never per
record. A version-1 dataset (records inline) resumed with the same config is migrated: its records
go into the index in one transaction and ``dataset.json`` becomes version 2.

A different config (another hash) is refused unless ``force``; then the old dataset is cleared
*safely*: its ``dataset.json`` is removed first (so an interruption never leaves a manifest
claiming stale frames), then the frame index, then only the scene folders the old manifest names are deleted (scene
names are plain folder names; symbolic links are unlinked, never followed). Other files in OUT
are left alone.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from denoisebench.dataset import layout
from denoisebench.dataset.atomic import atomic_write_bytes, is_temporary
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.exr_io import canonical_json, sha256_file, write_exr
from denoisebench.dataset.frame_index import FrameIndexWriter, remove_index
from denoisebench.dataset.manifest import (
    SCHEMA_VERSION,
    SPLITS,
    config_hash,
    frame_records_entry,
    load_manifest,
    manifest_bytes,
    manifest_header,
    new_manifest,
    reference_quality,
    relative_standard_error,
    software_versions,
)

#: Keys every scene record needs (add_scene); others (usd, effects, plan, camera, ...) are free.
REQUIRED_SCENE_KEYS = ("family", "seed", "frames", "width", "height", "spp")
#: Keys the writer owns inside frame records (``extra`` may not override them).
_RESERVED_RECORD_KEYS = frozenset(
    {
        "file",
        "sha256",
        "spp",
        "seconds",
        "seconds_per_spp",
        "rel_se",
        "samples",
        "noisy_rel_se_max",
        "reference_too_noisy",
    }
)


class DatasetWriter:
    """Create or resume the dataset at ``out_dir`` for ``config``.

    ``versions``: software versions the caller knows (mitsuba, drjit, usd...); python, numpy and
    OpenEXR are added here. On resume the first run's versions stay; differing ones are appended to
    ``versions_resumed``.
    """

    def __init__(
        self,
        out_dir: str | os.PathLike,
        config: Mapping,
        versions: Mapping[str, str] | None = None,
        force: bool = False,
    ):
        self.root = Path(out_dir)
        if self.root.exists() and not self.root.is_dir():
            raise DatasetError(f"{self.root} exists and is not a folder")
        self.manifest_path = self.root / layout.MANIFEST_NAME
        self.index_path = self.root / layout.INDEX_NAME
        self.config_hash = config_hash(config)
        current_versions = software_versions(versions)
        self.resumed = False
        manifest = None
        if self.manifest_path.exists():
            try:
                old = load_manifest(self.manifest_path)
            except DatasetError as exc:
                if not force:
                    raise DatasetError(f"{exc}; use --force to overwrite {self.root}") from None
                old = None
            if old is not None and old["config_hash"] == self.config_hash:
                manifest = old
                self.resumed = True
                if manifest["versions"] != current_versions:
                    history = manifest.setdefault("versions_resumed", [])
                    if current_versions not in history:
                        history.append(current_versions)
            elif old is not None and not force:
                raise DatasetError(
                    f"{self.root} was made with a different config (hash {old['config_hash'][:12]}); "
                    f"use --force to overwrite"
                )
            else:
                self._clear(old)
        if manifest is None:
            remove_index(self.index_path)  # records of no manifest (a run killed before its first save)
            manifest = new_manifest(config, current_versions)
        self.root.mkdir(parents=True, exist_ok=True)
        self._index = FrameIndexWriter(self.index_path)
        if manifest.get("schema_version") != SCHEMA_VERSION:  # version 1, resumed: migrate its records
            self._index.replace_all({name: scene.get("renders", {}) for name, scene in manifest["scenes"].items()})
            manifest["schema_version"] = SCHEMA_VERSION
            manifest["frame_records"] = frame_records_entry(None)
        self.manifest = manifest
        self._remove_temporaries()
        self._save()

    # ------------------------------------------------------------------ housekeeping

    def _clear(self, old: dict | None) -> None:
        self.manifest_path.unlink(missing_ok=True)
        remove_index(self.index_path)
        for name in sorted((old or {}).get("scenes", {})):
            if not _is_plain_name(name):
                continue  # never delete a path a malformed manifest makes up
            target = self.root / name
            if target.is_symlink():
                target.unlink()
            elif target.is_dir():
                shutil.rmtree(target)

    def _remove_temporaries(self) -> None:
        """Delete the hidden ``*.tmp`` files a killed run left behind (their names hold the dead pid,
        so no later write would replace them). Only OUT and the scene folders are searched."""
        folders = [self.root] + [self.root / name for name in sorted(self.manifest["scenes"]) if _is_plain_name(name)]
        for folder in folders:
            if not folder.is_dir() or folder.is_symlink():
                continue
            pattern = "*" if folder == self.root else "**/*"
            for path in sorted(folder.glob(pattern)):
                if is_temporary(path) and path.is_file() and not path.is_symlink():
                    path.unlink(missing_ok=True)

    def _save(self) -> None:
        """Write the header (``dataset.json``, without frame records): O(scenes), not O(records)."""
        atomic_write_bytes(self.manifest_path, manifest_bytes(manifest_header(self.manifest)))
        self._header_saved = True

    def close(self) -> None:
        """Close the frame index (the writer cannot record frames afterwards)."""
        self._index.close()

    def path(self, relative: str) -> Path:
        """Absolute path of a manifest-relative path."""
        return self.root / relative

    def scene_dir(self, scene: str) -> Path:
        """``OUT/<scene>`` (created), e.g. for the generator's ``scene.usda``."""
        folder = self.root / layout.check_scene_name(scene)
        folder.mkdir(parents=True, exist_ok=True)
        return folder

    def _scene(self, scene: str) -> dict:
        try:
            return self.manifest["scenes"][scene]
        except KeyError:
            raise ValueError(f"scene {scene!r} was not added (call add_scene first)") from None

    # ------------------------------------------------------------------ scenes

    def add_scene(self, name: str, record: Mapping) -> None:
        """Record a scene (see :data:`REQUIRED_SCENE_KEYS`; ``renders`` is the writer's).

        On resume, an identical record keeps the scene's frame records; a different one (the plan
        changed, say) drops them, so every frame of that scene is rendered again. The header is
        saved when something changed; :meth:`add_scenes` saves it once for many scenes.
        """
        self.add_scenes({name: record})

    def add_scenes(self, records: Mapping[str, Mapping]) -> None:
        """:meth:`add_scene` for each ``name → record``, every record checked first, the header saved
        once (adding n scenes one by one would write n headers of up to n scenes: O(n²))."""
        plain = {name: self._plain_scene(name, record) for name, record in records.items()}
        changed = False
        for name, record in plain.items():
            old = self.manifest["scenes"].get(name)
            renders = {}
            if old is not None:
                old_plain = {k: v for k, v in old.items() if k != "renders"}
                if old_plain == record:
                    renders = old.get("renders", {})
                elif old.get("renders"):
                    self._index.delete_scene(name)
            record["renders"] = renders
            changed |= old is None or record != old
            self.manifest["scenes"][name] = record
        self._mark_changed()
        if changed or not self._header_saved:
            self._save()

    def _plain_scene(self, name: str, record: Mapping) -> dict:
        layout.check_scene_name(name)
        record = dict(record)
        if "renders" in record:
            raise ValueError("'renders' in a scene record is reserved for the writer")
        missing = [key for key in REQUIRED_SCENE_KEYS if key not in record]
        if missing:
            raise ValueError(f"scene {name!r} record lacks {', '.join(missing)}")
        for key in ("frames", "width", "height"):
            if not isinstance(record[key], (int, np.integer)) or record[key] < 1:
                raise ValueError(f"scene {name!r}: {key} must be a positive integer (got {record[key]!r})")
        spp = sorted({int(s) for s in record["spp"]})
        if not spp or spp[0] < 1:
            raise ValueError(f"scene {name!r}: spp must be a non-empty list of positive integers")
        record["spp"] = spp
        ref_spp = record.setdefault("ref_spp", None)
        if ref_spp is not None and (int(ref_spp) < 1):
            raise ValueError(f"scene {name!r}: ref_spp must be a positive integer or None")
        record.setdefault("usd", layout.usd_path(name))
        try:
            plain = json.loads(canonical_json(record))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"scene {name!r} record is not plain JSON: {exc}") from None
        return plain

    # ------------------------------------------------------------------ frames

    def _check_frame(self, scene: str, frame: int, shape) -> dict:
        record = self._scene(scene)
        if not 0 <= int(frame) < record["frames"]:
            raise ValueError(f"scene {scene!r} has frames 0..{record['frames'] - 1}, not {frame}")
        if tuple(shape[:2]) != (record["height"], record["width"]):
            raise ValueError(
                f"scene {scene!r} is {record['height']}×{record['width']}, got buffers of {tuple(shape[:2])}"
            )
        return record

    def _record(self, scene: str, key: str, frame: int) -> dict | None:
        return self.manifest["scenes"].get(scene, {}).get("renders", {}).get(key, {}).get(layout.frame_key(frame))

    def is_done(self, scene: str, frame: int, spp: int | str) -> bool:
        """True when ``(scene, frame, spp)`` (or ``"reference"``) has a record and intact file(s)."""
        record = self._record(scene, layout.spp_key(spp), frame)
        if record is None:
            return False
        files = [record]
        if record.get("samples"):
            files.append(record["samples"])
        for entry in files:
            path = self.path(entry["file"])
            if not path.is_file() or sha256_file(path) != entry["sha256"]:
                return False
        return True

    def write_frame(
        self,
        scene: str,
        frame: int,
        spp: int,
        buffers: Mapping[str, np.ndarray],
        samples: Mapping[str, np.ndarray] | None = None,
        seconds: float = 0.0,
        extra: Mapping | None = None,
    ) -> dict:
        """Write the noisy buffers of one frame at ``spp`` (and its per-sample data), then record it."""
        if "color" not in buffers:
            raise ValueError("a frame needs a 'color' buffer")
        record = self._check_frame(scene, frame, np.shape(buffers["color"]))
        spp = int(spp)
        if spp not in record["spp"]:
            raise ValueError(f"scene {scene!r} renders spp {record['spp']}, not {spp}")
        timing = _timing(seconds, spp)  # checked before anything is written
        _check_extra(extra)
        relative = layout.noisy_path(scene, spp, frame)
        written, entry = self._write_file(relative, "noisy", scene, frame, spp, timing, buffers, samples)
        entry["samples"] = None
        if written.samples is not None:
            count = int(np.shape(next(iter(samples.values())))[0])
            entry["samples"] = {
                "file": layout.samples_path(scene, spp, frame),
                "sha256": written.samples.sha256,
                "count": count,
            }
        return self._put(scene, layout.spp_key(spp), frame, entry, extra)

    def write_reference(
        self,
        scene: str,
        frame: int,
        color: np.ndarray,
        color_var: np.ndarray,
        seconds: float = 0.0,
        *,
        spp: int | None = None,
        buffers: Mapping[str, np.ndarray] | None = None,
        extra: Mapping | None = None,
    ) -> dict:
        """Write the reference of one frame (color, its variance, and optional ``buffers`` such as
        diffuse/specular and their variances), then record it with its quality flag."""
        record = self._check_frame(scene, frame, np.shape(color))
        spp = int(spp if spp is not None else (record.get("ref_spp") or 0))
        if spp < 1:
            raise ValueError(f"scene {scene!r} has no ref_spp; pass spp=")
        timing = _timing(seconds, spp)  # checked before anything is written
        _check_extra(extra)
        layers = {"color": color, "color_var": color_var, **dict(buffers or {})}
        _, entry = self._write_file(layout.reference_path(scene, frame), "reference", scene, frame, spp, timing, layers)
        entry.update(noisy_rel_se_max=None, reference_too_noisy=False)
        return self._put(scene, layout.REFERENCE, frame, entry, extra)

    def _write_file(
        self,
        relative: str,
        kind: str,
        scene: str,
        frame: int,
        spp: int,
        timing: dict,
        layers: Mapping[str, np.ndarray],
        samples: Mapping[str, np.ndarray] | None = None,
    ) -> tuple:
        """Write one frame's EXR (``kind`` ``noisy`` or ``reference`` in its header) at ``relative``;
        return what ``write_exr`` wrote and the record's common fields (file, hash, spp, timing and the
        relative standard error of ``layers``' color)."""
        header = {"scene": scene, "frame": int(frame), "spp": spp, "kind": kind}
        written = write_exr(self.path(relative), layers, samples, header)
        entry = {
            "file": relative,
            "sha256": written.main.sha256,
            "spp": spp,
            **timing,
            # one sample per pixel has no variance estimate (its color_var is 0, not a measurement):
            # unknown (None), never "less noisy" than anything
            "rel_se": None if spp < 2 else relative_standard_error(layers["color"], layers.get("color_var")),
        }
        return written, entry

    def _put(self, scene: str, key: str, frame: int, entry: dict, extra: Mapping | None) -> dict:
        _check_extra(extra)
        entry.update(dict(extra or {}))
        entry = json.loads(canonical_json(entry))
        self._mark_changed()
        if not self._header_saved:
            self._save()  # the scene records this frame belongs to are on disk before it
        renders = self.manifest["scenes"][scene]["renders"]
        fkey = layout.frame_key(frame)
        renders.setdefault(key, {})[fkey] = entry
        rows = [(scene, key, fkey, entry)]
        if self._update_reference_flag(scene, frame) and key != layout.REFERENCE:
            rows.append((scene, layout.REFERENCE, fkey, renders[layout.REFERENCE][fkey]))
        self._index.put_many(rows)  # the frame is done when this returns
        return entry

    def _mark_changed(self) -> None:
        """The dataset is no longer complete: say so on disk before the next record (once)."""
        if self.manifest.get("complete") or self.manifest.get("frame_records", {}).get("count") is not None:
            self.manifest["complete"] = False
            self.manifest["frame_records"] = frame_records_entry(None)
            self._header_saved = False

    def _update_reference_flag(self, scene: str, frame: int) -> bool:
        """Recompute the reference's noise flag from the frame's inputs; True when its record changed."""
        renders = self.manifest["scenes"][scene]["renders"]
        fkey = layout.frame_key(frame)
        reference = renders.get(layout.REFERENCE, {}).get(fkey)
        if reference is None:
            return False
        noisy = [
            records[fkey]["rel_se"]
            for key, records in renders.items()
            if key != layout.REFERENCE and fkey in records and records[fkey].get("rel_se") is not None
        ]
        before = (reference.get("noisy_rel_se_max"), reference.get("reference_too_noisy"))
        reference["noisy_rel_se_max"] = max(noisy) if noisy else None
        reference["reference_too_noisy"] = reference_quality(noisy, reference.get("rel_se"))
        return before != (reference["noisy_rel_se_max"], reference["reference_too_noisy"])

    # ------------------------------------------------------------------ completion

    def expected(self) -> list[tuple[str, int, int | str]]:
        """Every (scene, frame, spp or "reference") the scene records call for, in order."""
        out = []
        for name in sorted(self.manifest["scenes"]):
            record = self.manifest["scenes"][name]
            kinds: list[int | str] = list(record["spp"])
            if record.get("ref_spp"):
                kinds.append(layout.REFERENCE)
            for frame in range(record["frames"]):
                out.extend((name, frame, kind) for kind in kinds)
        return out

    def missing(self, verify: bool = False) -> list[tuple[str, int, int | str]]:
        """What is not done yet: no record or no file (``verify``: also a wrong sha256)."""
        out = []
        for scene, frame, kind in self.expected():
            if verify:
                if not self.is_done(scene, frame, kind):
                    out.append((scene, frame, kind))
                continue
            record = self._record(scene, layout.spp_key(kind), frame)
            if record is None or not self.path(record["file"]).is_file():
                out.append((scene, frame, kind))
        return out

    def finalize(self, splits: Mapping[str, list[str]], allow_incomplete: bool = False) -> None:
        """Store the splits (every scene in exactly one of train/val/test) and mark the dataset complete.

        Raises ValueError when expected files are missing, unless ``allow_incomplete``.
        """
        unknown_splits = sorted(set(splits) - set(SPLITS))
        if unknown_splits:
            raise ValueError(f"unknown split(s) {unknown_splits}; splits are {list(SPLITS)}")
        scenes = set(self.manifest["scenes"])
        seen: dict[str, str] = {}
        for split in SPLITS:
            for name in splits.get(split, []):
                if name not in scenes:
                    raise ValueError(f"split {split!r} names scene {name!r}, which was not added")
                if name in seen:
                    raise ValueError(f"scene {name!r} is in both {seen[name]!r} and {split!r}")
                seen[name] = split
        left_out = sorted(scenes - set(seen))
        if left_out:
            raise ValueError(f"scene(s) {left_out} are in no split")
        missing = self.missing()
        if missing and not allow_incomplete:
            scene, frame, kind = missing[0]
            raise ValueError(f"{len(missing)} file(s) not written yet, e.g. scene {scene!r} frame {frame} {kind}")
        changed = []
        for name in sorted(scenes):
            for frame in range(self.manifest["scenes"][name]["frames"]):
                if self._update_reference_flag(name, frame):
                    fkey = layout.frame_key(frame)
                    changed.append(
                        (name, layout.REFERENCE, fkey, self.manifest["scenes"][name]["renders"][layout.REFERENCE][fkey])
                    )
        if changed:
            self._index.put_many(changed)
        self._index.seal()
        self.manifest["splits"] = {split: sorted(splits.get(split, [])) for split in SPLITS}
        self.manifest["complete"] = not missing
        count = sum(len(frames) for scene in self.manifest["scenes"].values() for frames in scene["renders"].values())
        self.manifest["frame_records"] = frame_records_entry(count)
        self._save()


def _check_extra(extra: Mapping | None) -> None:
    for name in dict(extra or {}):
        if name in _RESERVED_RECORD_KEYS:
            raise ValueError(f"extra key {name!r} is reserved for the writer")


def _is_plain_name(name: str) -> bool:
    try:
        layout.check_scene_name(name)
    except ValueError:
        return False
    return True


def _timing(seconds: float, spp: int) -> dict:
    seconds = float(seconds)
    if not math.isfinite(seconds) or seconds < 0:
        raise ValueError(f"render seconds must be finite and >= 0 (got {seconds})")
    return {"seconds": seconds, "seconds_per_spp": seconds / spp}
