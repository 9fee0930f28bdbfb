"""Export a dataset into the layout of OIDN's training toolkit (``training/`` of the OIDN repository).

Layout written under ``OUT`` (one folder per split, OIDN's ``-t``/``-v``/``-i`` dataset names)::

    OUT/train/<scene>_f0000_0001spp.hdr.exr   noisy color at 1 spp, frame 0
    OUT/train/<scene>_f0000_0001spp.alb.exr   its albedo
    OUT/train/<scene>_f0000_0001spp.nrm.exr   its normals
    OUT/train/<scene>_f0000_0004spp.hdr.exr   ... every rung of the spp ladder
    OUT/train/<scene>_f0000_ref.hdr.exr       the target: the reference color
    OUT/train/<scene>.json                    {"exposure": x}, the scene's display exposure
    OUT/val/...  OUT/test/...
    OUT/denoisebench_export.json              what was exported from where, and the conventions

Notes
-----
OIDN's grouping rule (``get_image_sample_groups`` in ``training/dataset.py``): an image's name is
its file name without the two extensions ``.<feature>.exr``; its group is the name before the last
``_`` when the part after it is a number, ``<n>spp``, ``ref``, ``reference``, ``gt`` or ``target``.
Within a group the names are sorted and the *last* is the target. Hence the zero-padded spp (every
rung of a group has the same number of digits, at least four) and ``_ref``, which sorts after any
digit. The frame index is written ``f0000`` so that scene names ending in digits stay unambiguous.

Each feature is its own single-layer EXR with channels ``R, G, B`` (``Z`` for depth), float32,
read by OIDN through OpenImageIO (``load_image`` in ``training/image.py``, first three channels).
Values are clipped as OIDN clips them when it loads (``load_image_features``), so the files hold
what OIDN trains on: ``hdr`` ≥ 0, ``alb`` in [0, 1], ``nrm`` in [−1, 1], ``z`` ≥ 0.

Conversions from our buffers (docs/architecture.md, Buffers):

* ``hdr``: ``color`` (linear radiance, the mean of the rung's samples); the target's is the
  reference's ``color``.
* ``alb``: our ``albedo``, the diffuse reflectance at the first *non-delta* hit (paths through
  mirrors and smooth glass are followed to the first rough surface), which is what OIDN's
  documentation asks of an albedo buffer.
* ``nrm``: our ``normal``, the **world-space** shading normal at the first hit (Mitsuba world,
  Y up), averaged over the pixel's samples (so not unit length at edges). OIDN accepts world- or
  view-space normals; it does not transform them.
* ``z`` (only when asked, ``features`` containing ``"z"``): our ``depth``, camera-space linear
  depth in meters (OIDN applies its log transfer function to it).
* The target's ``alb``/``nrm``/``z`` (for OIDN's ``--clean_aux``) are the top rung's features:
  our references store color only. They are as noisy as that rung's features, not clean.

``<scene>.json`` holds ``{"exposure": 0.18 / g}`` with ``g`` the geometric mean of the luminance
``0.2126 R + 0.7152 G + 0.0722 B`` (plus 1e-4) over the scene's reference frames (its top rung when
it has no reference): the key-value exposure OIDN's ``infer.py`` and ``compare_image.py`` apply
before tone mapping (``load_image_metadata`` finds it by stripping ``_`` parts of a name). It does
not change training, where OIDN computes its own autoexposure.

OIDN trains on random crops of ``--tile_size`` pixels (default 256): every image must be at least
that large on each side, or its loader fails. ``tile_size`` here is checked against every scene
before anything is written (pass the same value to OIDN's ``train.py --tile_size``). OIDN's default
loss (``mix``: L1 and MS-SSIM) needs tiles of at least 161 px (MS-SSIM's five scales); below that,
train with ``-l l1``. Checked by running OIDN's ``preprocess.py``, ``train.py`` and ``infer.py``
(repository at e050ac8) on an export of a 32 px synthetic dataset.
"""

from __future__ import annotations

import io
import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import OpenEXR
from tqdm import tqdm

from denoisebench.dataset.atomic import atomic_write_bytes
from denoisebench.dataset.manifest import SPLITS
from denoisebench.dataset.reader import Dataset
from denoisebench.errors import UserInputError

#: OIDN feature name -> (our buffer, channel names in the file, clip range).
FEATURES: dict[str, tuple[str, tuple[str, ...], tuple[float | None, float | None]]] = {
    "hdr": ("color", ("R", "G", "B"), (0.0, None)),
    "alb": ("albedo", ("R", "G", "B"), (0.0, 1.0)),
    "nrm": ("normal", ("R", "G", "B"), (-1.0, 1.0)),
    "z": ("depth", ("Z",), (0.0, None)),
}
DEFAULT_FEATURES = ("hdr", "alb", "nrm")
DEFAULT_TILE_SIZE = 256
#: Suffixes after the last ``_`` that make OIDN group a name with its prefix (training/dataset.py).
GROUP_SUFFIXES = ("ref", "reference", "gt", "target")
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
KEY = 0.18


def parse_features(text: str) -> tuple[str, ...]:
    """``"hdr,alb,nrm"`` -> a tuple in OIDN's order; ``hdr`` is required. UserInputError otherwise."""
    names = [name.strip() for name in text.split(",") if name.strip()]
    unknown = [name for name in names if name not in FEATURES]
    if unknown:
        raise UserInputError(f"--features: unknown OIDN feature(s) {', '.join(unknown)}; known: {', '.join(FEATURES)}")
    if "hdr" not in names:
        raise UserInputError("--features must include hdr (the noisy color OIDN denoises)")
    return tuple(name for name in FEATURES if name in names)


def spp_digits(spp: Iterable[int]) -> int:
    """Digits of the zero-padded spp in names: at least 4, enough for the largest rung."""
    return max(4, *(len(str(int(s))) for s in spp))


def image_name(scene: str, frame: int, spp: int | None, digits: int = 4) -> str:
    """``<scene>_f0000_0004spp`` for a rung, ``<scene>_f0000_ref`` for the target (spp None)."""
    tag = "ref" if spp is None else f"{int(spp):0{digits}d}spp"
    return f"{scene}_f{frame:04d}_{tag}"


def oidn_group(name: str) -> str:
    """The group OIDN puts image ``name`` in (its rule, restated; see the module Notes)."""
    if "_" not in name:
        return name
    prefix, suffix = name.rsplit("_", 1)
    suffix = suffix.lower()
    if suffix.isdecimal() or (suffix.endswith("spp") and suffix[:-3].isdecimal()) or suffix in GROUP_SUFFIXES:
        return prefix
    return name


def encode_feature(feature: str, array: np.ndarray) -> bytes:
    """One single-layer EXR (float32, ZIP) of ``array`` (H×W×C), clipped as OIDN clips ``feature``."""
    _, channels, (low, high) = FEATURES[feature]
    data = np.nan_to_num(np.asarray(array, dtype=np.float32)[..., : len(channels)])
    data = np.clip(data, low, high)
    planes = {name: np.ascontiguousarray(data[..., i]) for i, name in enumerate(channels)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    stream = io.BytesIO()
    OpenEXR.File(header, planes).write(stream)
    return stream.getvalue()


def scene_exposure(references: list[np.ndarray]) -> float:
    """``0.18 / geometric mean luminance`` over the frames (see the module Notes)."""
    lum = np.concatenate([np.maximum(r.astype(np.float64) @ LUMINANCE, 0.0).ravel() for r in references])
    return float(KEY / np.exp(np.mean(np.log(lum + 1e-4))))


def check_exportable(dataset: Dataset, features: tuple[str, ...], tile_size: int) -> None:
    """UserInputError for anything that would make the export unusable, before writing."""
    if tile_size < 1:
        raise UserInputError(f"--tile-size must be >= 1 (got {tile_size})")
    if not dataset.scenes:
        raise UserInputError(f"{dataset.root}: the dataset has no scenes")
    for name in dataset.scenes:
        info = dataset.scene(name)
        if min(info.width, info.height) < tile_size:
            raise UserInputError(
                f"scene {name!r} is {info.width}x{info.height} px, smaller than OIDN's tile size {tile_size}: "
                f"render at least {tile_size} px a side, or pass --tile-size N (and train.py --tile_size N)"
            )
        if not info.has_reference and len(info.spp) > 1:
            raise UserInputError(
                f"scene {name!r} has no reference: OIDN would take its top rung ({max(info.spp)} spp) as the "
                "target of its other rungs; leave it out with --scenes"
            )
        missing = [f for f in features if FEATURES[f][0] not in _buffers_of(info)]
        if missing:
            raise UserInputError(
                f"scene {name!r} has no {', '.join(FEATURES[f][0] for f in missing)} buffer for OIDN feature(s) "
                f"{', '.join(missing)}; leave them out of --features"
            )


def _buffers_of(info) -> set[str]:
    return {"color", *info.plan.get("features", ("albedo", "normal", "depth"))}


def split_of(dataset: Dataset) -> dict[str, str]:
    """Scene -> split folder name (``train``, ``val``, ``test``); scenes in no split go to ``test``."""
    where = {scene: split for split in SPLITS for scene in dataset.split(split)}
    return {scene: where.get(scene, "test") for scene in dataset.scenes}


def export_oidn(
    dataset: Dataset,
    out: Path,
    features: tuple[str, ...] = DEFAULT_FEATURES,
    tile_size: int = DEFAULT_TILE_SIZE,
    progress: bool = True,
) -> dict:
    """Write the OIDN layout of ``dataset`` into the (empty, staging) folder ``out``; return a summary.

    Call :func:`check_exportable` first (the command does). The summary counts files per split
    and is also written to ``out/denoisebench_export.json``.
    """
    splits = split_of(dataset)
    jobs = [(scene, frame) for scene in dataset.scenes for frame in range(dataset.scene(scene).frame_count)]
    counts = {split: 0 for split in SPLITS}
    groups = {split: 0 for split in SPLITS}
    references: dict[str, list[np.ndarray]] = {}
    for scene, frame in tqdm(jobs, desc="export oidn", unit="frame", disable=not progress):
        info = dataset.scene(scene)
        folder = out / splits[scene]
        digits = spp_digits(info.spp)
        top = None
        for spp in sorted(info.spp):
            loaded = dataset.frame(scene, spp, frame, reference=False, samples=False)
            top = loaded
            for feature in features:
                data = encode_feature(feature, loaded.buffers[FEATURES[feature][0]])
                atomic_write_bytes(folder / f"{image_name(scene, frame, spp, digits)}.{feature}.exr", data)
                counts[splits[scene]] += 1
        if info.has_reference:
            layers, _ = dataset.reference(scene, frame)
            references.setdefault(scene, []).append(layers["color"])
            target = image_name(scene, frame, None)
            atomic_write_bytes(folder / f"{target}.hdr.exr", encode_feature("hdr", layers["color"]))
            counts[splits[scene]] += 1
            for feature in features:
                if feature != "hdr":
                    data = encode_feature(feature, top.buffers[FEATURES[feature][0]])
                    atomic_write_bytes(folder / f"{target}.{feature}.exr", data)
                    counts[splits[scene]] += 1
        else:
            references.setdefault(scene, []).append(top.buffers["color"])
        groups[splits[scene]] += 1
    exposures = {}
    for scene, frames in references.items():
        exposures[scene] = scene_exposure(frames)
        payload = json.dumps({"exposure": exposures[scene]}, indent=2) + "\n"
        atomic_write_bytes(out / splits[scene] / f"{scene}.json", payload.encode())
    summary = {
        "format": "oidn",
        "source": str(dataset.root.resolve()),
        "config_hash": dataset.config_hash,
        "features": list(features),
        "tile_size": tile_size,
        "files": {k: v for k, v in counts.items() if v},
        "groups": {k: v for k, v in groups.items() if v},
        "exposure": exposures,
        "conventions": {
            "hdr": "color (linear radiance), clipped >= 0; target: the reference color",
            "alb": "albedo: diffuse reflectance at the first non-delta hit, clipped to [0, 1]",
            "nrm": "normal: world-space shading normal at the first hit (pixel mean), clipped to [-1, 1]",
            "z": "depth: camera-space linear depth (m), clipped >= 0",
            "target_aux": "the target's alb/nrm/z are the top rung's features (references store color only)",
        },
    }
    atomic_write_bytes(out / "denoisebench_export.json", (json.dumps(summary, indent=2) + "\n").encode())
    return summary
