"""Where files live inside a dataset folder (docs/architecture.md, "Dataset on disk").

::

    OUT/dataset.json
    OUT/dataset.sqlite                       the frame records (schema version 2, see manifest.py)
    OUT/<scene>/scene.usda
    OUT/<scene>/spp0004/frame_0000.exr
    OUT/<scene>/spp0004/samples/frame_0000.exr
    OUT/<scene>/reference/frame_0000.exr

All paths in the manifest are relative to OUT, with ``/`` separators.
"""

from __future__ import annotations

import re

MANIFEST_NAME = "dataset.json"
INDEX_NAME = "dataset.sqlite"
REFERENCE = "reference"
SCENE_USD = "scene.usda"

_SCENE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


def check_scene_name(name: str) -> str:
    """A scene name is a folder name: letters, digits, ``._-``, not starting with ``.``/``-``."""
    if not isinstance(name, str) or not _SCENE_NAME.match(name) or name in (MANIFEST_NAME, INDEX_NAME):
        raise ValueError(f"bad scene name {name!r}: use letters, digits, '.', '_' and '-'")
    return name


def spp_key(spp: int | str) -> str:
    """Manifest key and folder name of a sample count: ``spp0004``; ``"reference"`` passes through."""
    if spp == REFERENCE:
        return REFERENCE
    spp = int(spp)
    if spp < 1:
        raise ValueError(f"spp must be >= 1 (got {spp})")
    return f"spp{spp:04d}"


def frame_key(frame: int) -> str:
    frame = int(frame)
    if frame < 0:
        raise ValueError(f"frame index must be >= 0 (got {frame})")
    return f"{frame:04d}"


def frame_file(frame: int) -> str:
    return f"frame_{frame_key(frame)}.exr"


def noisy_path(scene: str, spp: int, frame: int) -> str:
    return f"{scene}/{spp_key(spp)}/{frame_file(frame)}"


def samples_path(scene: str, spp: int, frame: int) -> str:
    return f"{scene}/{spp_key(spp)}/samples/{frame_file(frame)}"


def reference_path(scene: str, frame: int) -> str:
    return f"{scene}/{REFERENCE}/{frame_file(frame)}"


def usd_path(scene: str) -> str:
    return f"{scene}/{SCENE_USD}"
