"""The ``dataset.json`` model (docs/architecture.md, "Dataset on disk"): schema, config hash, splits, quality.

Layout of the manifest (all keys sorted when saved; paths relative to the dataset folder), as
:func:`load_manifest` returns it whatever the schema version on disk::

    {
      "schema": "denoisebench-dataset", "schema_version": 2,
      "frame_records": {"store": "sqlite", "file": "dataset.sqlite", "count": int | null},  # version 2
      "config": {...}, "config_hash": "<sha256 of the canonical JSON of config>",
      "versions": {"python": ..., "numpy": ..., "openexr": ..., <caller's: mitsuba, drjit, usd ...>},
      "complete": true,                      # set by finalize when every expected file is done
      "splits": {"train": [...], "val": [...], "test": [...]},   # scene names, set by finalize
      "scenes": {
        "<scene>": {
          "family": str, "seed": int, "frames": int, "width": int, "height": int,
          "spp": [int, ...], "ref_spp": int | null,
          "usd": "<scene>/scene.usda", "effects": {"declared": [...], "inferred": [...]},
          "plan": {...render plan...}, "camera": {...},  # and anything else the generator adds:
          # generate-dataset adds "source", "stage_files", "stage_sha256", "render_seed", "warnings"
          "renders": {
            "spp0004": {"0000": {"file", "sha256", "spp", "seconds", "seconds_per_spp",
                                  "rel_se", "samples": {"file", "sha256", "count"} | null, ...}},
            # generate-dataset adds "camera_pose" (4×4 camera-to-world at the frame's time sample)
            # and "jit_compile_seconds" (Dr.Jit compile time, excluded from "seconds")
            "reference": {"0000": {"file", "sha256", "spp", "seconds", "seconds_per_spp",
                                    "rel_se", "noisy_rel_se_max", "reference_too_noisy", ...}}
          }
        }
      }
    }

Schema versions. Version 1 (older datasets) keeps every frame record inline in ``dataset.json``
and rewrote the whole file after each record: O(records) per record, quadratic in all. Version 2
keeps the same dict minus ``renders``, which live in the SQLite index named by
``frame_records`` (:mod:`.frame_index`; why SQLite is said there); ``count`` is the number of
records, set when the dataset is finalized. ``dataset.json`` remains the one self-describing file
(config, versions, scenes, plans, splits, completeness) and is rewritten only when a scene is added
and at the end. Both versions are read: :func:`load_header` returns the manifest without frame
records (version 1: with them, inline, since they are in the file anyway), :func:`load_manifest`
the whole logical manifest (version 2: records read from the index, O(records)).
:func:`save_manifest` always writes version 2.

Identical bytes: the EXR files are byte-identical for the same seed and config; the manifest is
identical **except for timings** (render seconds are there by design). A timing is any key whose
name contains ``seconds`` (:func:`is_timing_key`); :func:`manifest_without_timings` drops them, and
that is what must match between an interrupted-and-resumed run and an uninterrupted one. The
manifest holds no wall-clock time stamps.

Reference quality: the relative standard error of an image is
``rel_se = sqrt(mean(color_var)) / max(mean(color), 1e-8)`` over all pixels and channels: the RMS
standard error of the pixel means divided by the mean radiance. It is one robust number per image
(a per-pixel ratio explodes on black pixels) and falls as 1/sqrt(spp). The reference of a frame is
flagged ``reference_too_noisy`` when its rel_se is not at least :data:`REFERENCE_FACTOR` (4) times
lower than that of the noisiest noisy input of the same frame (:func:`reference_quality`): a
reference with a quarter of the input's noise still adds 1/16 of the input's MSE to any score.

Splits (:func:`assign_splits`) are by scene and deterministic: scenes are ordered by
``sha256(f"{seed}:{name}")``, so the result depends only on the seed and the set of names (not on
their order, nor on any library's random generator), and adding a scene never moves the others
relative to each other. Given each scene's family (the generator passes them), the split is
**stratified**: every family with at least 3 scenes puts at least one scene in each of train, val
and test; the scenes of smaller families are pooled and split as one group. Splits are written
into the manifest and read back from it, so datasets made before stratification keep theirs.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import platform
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import OpenEXR

from denoisebench.dataset import layout
from denoisebench.dataset.atomic import atomic_write_bytes
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.exr_io import canonical_json
from denoisebench.dataset.frame_index import FrameIndexReader, FrameIndexWriter

SCHEMA = "denoisebench-dataset"
SCHEMA_VERSION = 2
#: Schema versions this denoisebench reads (1: frame records inline in dataset.json).
READABLE_VERSIONS = (1, 2)
SPLITS = ("train", "val", "test")
DEFAULT_FRACTIONS = (0.7, 0.15, 0.15)

#: The reference must be this many times less noisy (rel_se) than the noisiest input.
REFERENCE_FACTOR = 4.0
#: Floor of the mean radiance in rel_se (a black image with zero variance has rel_se 0).
REL_SE_EPS = 1e-8

__all__ = [
    "SCHEMA",
    "SCHEMA_VERSION",
    "SPLITS",
    "REFERENCE_FACTOR",
    "config_hash",
    "assign_splits",
    "relative_standard_error",
    "reference_quality",
    "software_versions",
    "new_manifest",
    "load_header",
    "load_manifest",
    "manifest_header",
    "save_manifest",
    "manifest_bytes",
    "is_timing_key",
    "manifest_without_timings",
]


# --------------------------------------------------------------------------- config, versions


def config_hash(config: Mapping) -> str:
    """sha256 (hex) of the canonical JSON of ``config`` (sorted keys, no spaces; tuples = lists)."""
    try:
        text = canonical_json(config)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"the dataset config must be plain JSON (no NaN): {exc}") from None
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def software_versions(extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """Python, numpy and OpenEXR versions, plus the caller's (mitsuba, drjit, usd...: passed in)."""

    versions = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "openexr": getattr(OpenEXR, "__version__", "unknown"),
    }
    for key, value in (extra or {}).items():
        versions[str(key)] = str(value)
    return versions


# --------------------------------------------------------------------------- splits


def _round_half_up(x: float) -> int:
    return int(math.floor(x + 0.5))


#: A family with at least this many scenes has one in each split when splits are stratified.
STRATIFY_MIN_SCENES = 3


def assign_splits(
    scene_names: Iterable[str],
    seed: int,
    fractions: tuple[float, float, float] = DEFAULT_FRACTIONS,
    families: Mapping[str, str] | None = None,
) -> dict[str, list[str]]:
    """Split scenes into train/val/test, deterministically from ``seed``.

    Counts for n scenes: test = max(1, round(n·f_test)), val = round(n·f_val), train = the rest,
    with at least one train scene (val shrinks first, then test, down to 1). So there is always at
    least one test scene and one train scene when n ≥ 2. A single scene goes to **test** (the
    harness's first use is benchmarking; training needs several scenes anyway). Rounding is half
    up. Each list is sorted by name.

    ``families`` (scene name → family) stratifies: each family of at least
    :data:`STRATIFY_MIN_SCENES` scenes is split on its own with val and test at least one scene
    each (3 scenes: one per split), and the scenes of smaller families (and names missing from
    ``families``) are pooled and split by the rule above. Without ``families`` (or when no family
    is that large) the result is exactly the unstratified split.
    """
    names = sorted(set(scene_names))
    if len(fractions) != 3 or any(f < 0 for f in fractions) or not math.isclose(sum(fractions), 1.0, abs_tol=1e-9):
        raise ValueError(f"fractions must be three non-negative numbers summing to 1 (got {fractions})")
    if families is not None:
        groups: dict[str, list[str]] = {}
        for name in names:
            groups.setdefault(str(families.get(name, "")), []).append(name)
        large = {family: members for family, members in groups.items() if len(members) >= STRATIFY_MIN_SCENES}
        if large:
            pooled = [name for family, members in groups.items() if family not in large for name in members]
            parts = [assign_splits(pooled, seed, fractions)] + [
                _stratum(members, seed, fractions) for _, members in sorted(large.items())
            ]
            return {split: sorted(name for part in parts for name in part[split]) for split in SPLITS}
    n = len(names)
    if n == 0:
        return {split: [] for split in SPLITS}
    order = sorted(names, key=lambda name: hashlib.sha256(f"{int(seed)}:{name}".encode()).hexdigest())
    if n == 1:
        return {"train": [], "val": [], "test": order}
    n_test = min(max(1, _round_half_up(n * fractions[2])), n - 1)
    n_val = min(_round_half_up(n * fractions[1]), n - 1 - n_test)
    test = order[:n_test]
    val = order[n_test : n_test + n_val]
    train = order[n_test + n_val :]
    return {"train": sorted(train), "val": sorted(val), "test": sorted(test)}


def pin_held_out(splits: Mapping[str, list[str]], held_out: Iterable[str]) -> dict[str, list[str]]:
    """``splits`` with the scenes of held-out variants (``held_out``: names) moved into test.

    Scenes whose stage records ``variants["pool"] == "held_out"`` (the cluttered family's held-out
    shapes, textures and environments) must never be trained or validated on, so that a learned
    model's test score on them measures generalisation. Lists stay sorted; other scenes keep their split."""
    pinned = set(held_out)
    out = {split: sorted(name for name in splits.get(split, []) if name not in pinned) for split in SPLITS}
    everyone = {name for names in splits.values() for name in names}
    out["test"] = sorted(set(out["test"]) | (pinned & everyone))
    return out


def _stratum(names: list[str], seed: int, fractions: tuple[float, float, float]) -> dict[str, list[str]]:
    """One family of n ≥ 3 scenes: test and val max(1, round(n·f)), train the rest (≥ 1)."""
    order = sorted(names, key=lambda name: hashlib.sha256(f"{int(seed)}:{name}".encode()).hexdigest())
    n = len(order)
    n_test = max(1, _round_half_up(n * fractions[2]))
    n_val = max(1, min(_round_half_up(n * fractions[1]), n - 1 - n_test))
    n_test = min(n_test, n - 1 - n_val)
    return {
        "test": sorted(order[:n_test]),
        "val": sorted(order[n_test : n_test + n_val]),
        "train": sorted(order[n_test + n_val :]),
    }


# --------------------------------------------------------------------------- quality


def relative_standard_error(color: np.ndarray, color_var: np.ndarray | None) -> float | None:
    """``sqrt(mean(color_var)) / max(mean(color), 1e-8)``; None without a variance buffer."""
    if color_var is None:
        return None
    var = np.asarray(color_var, dtype=np.float64)
    mean = float(np.mean(np.asarray(color, dtype=np.float64)))
    value = math.sqrt(max(float(np.mean(var)), 0.0)) / max(abs(mean), REL_SE_EPS)
    if not math.isfinite(value):
        raise ValueError("relative standard error is not finite (NaN/Inf in color or color_var)")
    return value


def reference_quality(noisy_rel_se, ref_rel_se: float | None, factor: float = REFERENCE_FACTOR) -> bool:
    """True (**too noisy**) when ``ref_rel_se`` is not at least ``factor``× below the noisiest input.

    ``noisy_rel_se`` is one number or several (the frame's inputs at each spp; None entries are
    ignored). Without a measurable input or reference there is nothing to flag: False.
    """
    if isinstance(noisy_rel_se, (int, float)) or noisy_rel_se is None:
        values = [noisy_rel_se]
    else:
        values = list(noisy_rel_se)
    values = [float(v) for v in values if v is not None]
    if not values or ref_rel_se is None:
        return False
    return bool(float(ref_rel_se) * factor > max(values))


# --------------------------------------------------------------------------- load / save


def new_manifest(config: Mapping, versions: Mapping[str, str]) -> dict:
    config = json.loads(canonical_json(config))  # a plain-JSON copy (tuples → lists)
    return {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "config": config,
        "config_hash": config_hash(config),
        "versions": dict(versions),
        "frame_records": frame_records_entry(None),
        "complete": False,
        "splits": {split: [] for split in SPLITS},
        "scenes": {},
    }


def frame_records_entry(count: int | None) -> dict:
    """The version-2 pointer to the frame records: the index file beside dataset.json, and their count."""
    return {"store": "sqlite", "file": layout.INDEX_NAME, "count": count}


def manifest_header(manifest: Mapping) -> dict:
    """The version-2 ``dataset.json`` content of a logical manifest: everything but the frame records."""
    header = {key: value for key, value in manifest.items() if key != "scenes"}
    header["schema_version"] = SCHEMA_VERSION
    header.setdefault("frame_records", frame_records_entry(None))
    header["scenes"] = {
        name: {key: value for key, value in scene.items() if key != "renders"}
        for name, scene in manifest["scenes"].items()
    }
    return header


def manifest_bytes(manifest: Mapping) -> bytes:
    """Indented JSON with sorted keys (deterministic), UTF-8, final newline."""
    return (json.dumps(manifest, indent=2, sort_keys=True, allow_nan=False) + "\n").encode("utf-8")


def save_manifest(path: str | os.PathLike, manifest: Mapping) -> None:
    """Write a whole logical manifest as version 2: its frame records into the index, then ``dataset.json``.

    O(records): for tools and tests that edit a dataset wholesale (and for migrating version 1);
    the writer records frames one by one instead."""

    path = Path(path)
    renders = {name: scene.get("renders", {}) for name, scene in manifest["scenes"].items()}
    header = manifest_header(manifest)
    header["frame_records"] = frame_records_entry(
        sum(len(frames) for kinds in renders.values() for frames in kinds.values())
    )
    index = FrameIndexWriter(path.parent / layout.INDEX_NAME)
    try:
        index.replace_all(renders)
    finally:
        index.close(seal=True)
    atomic_write_bytes(path, manifest_bytes(header))


def load_header(path: str | os.PathLike) -> dict:
    """Read and check ``dataset.json``; DatasetError (one line, naming the file) when it is not a manifest.

    Version 2: the scenes carry no ``renders`` (they are in the index); version 1: they do."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetError(f"{path} is missing: not a denoisebench dataset (no manifest)") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read {path}: {exc}") from None
    try:
        manifest = json.loads(text)
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{path} is not valid JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(manifest, dict) or manifest.get("schema") != SCHEMA:
        raise DatasetError(f"{path} is not a denoisebench dataset manifest")
    version = manifest.get("schema_version")
    if version not in READABLE_VERSIONS:
        readable = " and ".join(str(v) for v in READABLE_VERSIONS)
        raise DatasetError(f"{path} has schema version {version}; this denoisebench reads versions {readable}")
    for key, kind in (("config", dict), ("config_hash", str), ("versions", dict), ("splits", dict), ("scenes", dict)):
        if not isinstance(manifest.get(key), kind):
            raise DatasetError(f"{path}: manifest field {key!r} is missing or not a {kind.__name__}")
    if version >= 2:
        records = manifest.get("frame_records")
        if (
            not isinstance(records, dict)
            or records.get("store") != "sqlite"
            or records.get("file") != layout.INDEX_NAME
        ):
            raise DatasetError(
                f"{path}: manifest field 'frame_records' must name the SQLite index {layout.INDEX_NAME!r}"
            )
    for name, scene in manifest["scenes"].items():
        if not isinstance(scene, dict) or not isinstance(scene.get("renders", {}), dict):
            raise DatasetError(f"{path}: scene {name!r} has a malformed record")
        if version >= 2 and "renders" in scene:
            raise DatasetError(f"{path}: scene {name!r} has inline frame records in a version-2 manifest")
    return manifest


def index_path(manifest_path: str | os.PathLike) -> Path:
    """Where a version-2 manifest's frame records are: ``dataset.sqlite`` beside it."""
    return Path(manifest_path).parent / layout.INDEX_NAME


def load_manifest(path: str | os.PathLike) -> dict:
    """The whole logical manifest (version 2: frame records read from the index; O(records)).

    DatasetError (one line, naming the file) when it is not a manifest. Readers that need a few
    frames use :func:`~denoisebench.dataset.reader.open_dataset`, which loads records on demand."""
    manifest = load_header(path)
    if manifest["schema_version"] >= 2:
        renders: dict = {}
        if manifest["scenes"]:
            index = FrameIndexReader(index_path(path))
            try:
                renders = dict(index.scenes())
            finally:
                index.close()
        for name, scene in manifest["scenes"].items():
            scene["renders"] = renders.get(name, {})
    return manifest


def is_timing_key(key: str) -> bool:
    """Keys holding measured time (they differ between runs): any name containing ``seconds``."""
    return "seconds" in key


def _strip(value):
    if isinstance(value, dict):
        return {k: _strip(v) for k, v in value.items() if not is_timing_key(k)}
    if isinstance(value, list):
        return [_strip(v) for v in value]
    return value


def manifest_without_timings(manifest: Mapping | str | os.PathLike) -> dict:
    """A copy of the manifest (or of the manifest file at a path) without any timing key."""
    if not isinstance(manifest, Mapping):
        manifest = load_manifest(manifest)
    return _strip(copy.deepcopy(dict(manifest)))
