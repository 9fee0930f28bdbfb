"""Geometric augmentation of buffers (numpy, torch-free): flips and 90° rotations, consistent for all.

A :class:`Transform` is a quarter-turn rotation ``rot`` (counter-clockwise as displayed, i.e.
``np.rot90`` on the row/column axes) followed by an optional horizontal flip (columns reversed)
and an optional vertical flip (rows reversed). Drawing the three uniformly covers the 8
symmetries of the square uniformly. Arrays are ``...×H×W×C`` (a frame, or K frames).

What each buffer needs besides moving its pixels:

* ``motion`` (x = towards larger column, y = towards larger row, in pixels; docs/architecture.md): a vector
  field, so its components transform with the image. Pixel centre (x, y) goes to
  (x', y') = (y, W − x) under one quarter turn, so (mx, my) → (my, −mx); a horizontal flip
  negates mx; a vertical flip negates my. Then warping the transformed previous frame with the
  transformed motion gives the transformed current frame (tests prove it).
* ``motion_var``: per-component variances; a rotation swaps the components, flips change nothing.
* ``normal`` and ``position`` are **world-space**, and so is everything else (colors, albedo,
  depth, roughness, variances): the scene does not move, only the image grid is resampled, so
  their values stay as they are. (A camera-space normal would need its x/y transformed like
  motion; the dataset has none.)
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Transform:
    rot: int = 0  # quarter turns, counter-clockwise as displayed (row 0 at the top)
    flip_h: bool = False  # reverse columns (left ↔ right), after the rotation
    flip_v: bool = False  # reverse rows (top ↔ bottom), after the rotation

    @property
    def is_identity(self) -> bool:
        return self.rot % 4 == 0 and not self.flip_h and not self.flip_v


IDENTITY = Transform()


def all_transforms() -> list[Transform]:
    """The 8 distinct symmetries of the square (rotations, and rotations then a horizontal flip)."""
    return [Transform(rot, flip, False) for flip in (False, True) for rot in range(4)]


def random_transform(rng: np.random.Generator) -> Transform:
    rot, flip_h, flip_v = rng.integers(0, 4), rng.integers(0, 2), rng.integers(0, 2)
    return Transform(int(rot), bool(flip_h), bool(flip_v))


def _pixels(array: np.ndarray, t: Transform) -> np.ndarray:
    rows, cols = array.ndim - 3, array.ndim - 2
    out = np.rot90(array, t.rot % 4, axes=(rows, cols))
    if t.flip_h:
        out = np.flip(out, axis=cols)
    if t.flip_v:
        out = np.flip(out, axis=rows)
    return out


def transform_motion(motion: np.ndarray, t: Transform) -> np.ndarray:
    """Move the pixels of a ``...×H×W×2`` motion field and transform its (x, y) components."""
    out = _pixels(motion, t)
    mx, my = out[..., 0], out[..., 1]
    for _ in range(t.rot % 4):
        mx, my = my, -mx
    if t.flip_h:
        mx = -mx
    if t.flip_v:
        my = -my
    return np.stack([mx, my], axis=-1)


def transform_array(name: str, array: np.ndarray, t: Transform) -> np.ndarray:
    """Apply ``t`` to buffer ``name`` (``...×H×W×C``); returns a C-contiguous array."""
    base = name.removeprefix("reference_")
    if base == "motion":
        out = transform_motion(array, t)
    elif base == "motion_var":
        out = _pixels(array, t)
        if t.rot % 2:
            out = out[..., ::-1]
    else:
        out = _pixels(array, t)
    return np.ascontiguousarray(out)


def transform_buffers(buffers: Mapping[str, np.ndarray], t: Transform) -> dict[str, np.ndarray]:
    """Apply the same ``t`` to every buffer (motion vectors transformed as well)."""
    return {name: transform_array(name, array, t) for name, array in buffers.items()}
