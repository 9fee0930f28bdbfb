"""Which crops of a run's images are kept: worst-error windows and the flicker strip's window.

The runner cuts every unit's strip (:func:`cut`) while its outputs are in memory and the store keeps
it (table ``strips``); reports lay strips and worst-region crops out (:mod:`denoisebench.reports`).

Notes
-----
* **The same crop for every denoiser.** A strip's window is chosen from the data alone, never from
  a denoiser's output: the square where the noisy input flickers most (its mean
  ``temporal_relmse`` map over the strip's frame pairs, warped by the motion buffer when there is
  one). Every unit of a sequence at one spp therefore cuts the same pixels.
* At most :data:`STRIP_FRAMES` frames, the first ones of the sequence (a temporal denoiser's warm-up
  is part of what a reader should see); the side is a quarter of the image's short side, between 8
  and 48 pixels.
* Worst-region windows do not overlap; a window's score is its mean error.
* **A window shows something.** Where a ``content`` map is given (:func:`content_map`: the pixels
  of the reference visible after the report's tone map, at least :data:`VISIBLE_LEVEL` in display
  units), a window must cover at least :data:`MIN_CONTENT` of such pixels whenever any window does.
  A relative error such as relMSE is largest around small bright things on black (a lamp in the
  night sky), and a crop there is black on every tile; the rule keeps the worst window among those a
  reader can see into. An image with no such window falls back to the error alone.
"""

from __future__ import annotations

import numpy as np

from denoisebench.metrics import temporal_relmse_map
from denoisebench.metrics.tonemap import tonemap

# Lazy imports: scipy only where windows are chosen.

#: Frames in a strip (the first ones of the sequence).
STRIP_FRAMES = 8

#: Least share of visible reference pixels a window must cover (where any window does).
MIN_CONTENT = 0.5
#: A reference pixel is visible when its tone-mapped value reaches this (display units 0–1; 8/255:
#: darker reads as black on a screen).
VISIBLE_LEVEL = 8 / 255

__all__ = [
    "STRIP_FRAMES",
    "MIN_CONTENT",
    "VISIBLE_LEVEL",
    "window_size",
    "content_map",
    "worst_windows",
    "strip_side",
    "choose_window",
    "cut",
]


def window_size(*, width: int, height: int) -> int:
    """Side of a worst-region window: a quarter of the short side, at least 4 pixels (a frame's size
    is passed by name, width then height, as everywhere on the benchmark side)."""
    return max(4, min(height, width) // 4)


def content_map(reference: np.ndarray) -> np.ndarray:
    """H×W share of visible pixels of a reference (H×W×C, or F×H×W×C: the share over frames)."""
    display = tonemap(np.nan_to_num(np.asarray(reference, np.float64), nan=0.0, posinf=0.0, neginf=0.0))
    visible = np.asarray(display, np.float64).max(axis=-1) >= VISIBLE_LEVEL
    return visible.mean(axis=0) if visible.ndim == 3 else visible.astype(np.float64)


def worst_windows(
    error_map: np.ndarray, size: int, count: int = 2, content: np.ndarray | None = None
) -> list[tuple[int, int]]:
    """(top, left) of up to ``count`` non-overlapping size×size windows with the largest mean error;
    with ``content`` (:func:`content_map`) among those covering :data:`MIN_CONTENT` of it, where any does."""
    from scipy.ndimage import uniform_filter

    height, width = error_map.shape
    size = min(size, height, width)
    score = uniform_filter(np.nan_to_num(error_map.astype(np.float64), nan=0.0, posinf=0.0), size=size, mode="constant")
    # the filter centres windows; keep only centres whose window lies inside the image
    half = size // 2
    valid = np.full(score.shape, -np.inf)
    valid[half : height - (size - half) + 1, half : width - (size - half) + 1] = score[
        half : height - (size - half) + 1, half : width - (size - half) + 1
    ]
    if content is not None:
        coverage = uniform_filter(np.asarray(content, np.float64), size=size, mode="constant")
        lit = valid > -np.inf
        lit &= coverage >= MIN_CONTENT - 1e-9
        if lit.any():
            valid = np.where(lit, valid, -np.inf)
    found: list[tuple[int, int]] = []
    for _ in range(count):
        index = int(np.argmax(valid))
        if not np.isfinite(valid.flat[index]):
            break
        cy, cx = divmod(index, width)
        top, left = cy - half, cx - half
        found.append((top, left))
        # forbid centres whose window would overlap this one
        valid[
            max(0, top - size + 1 + half) : top + size + half, max(0, left - size + 1 + half) : left + size + half
        ] = -np.inf
    return found


def strip_side(*, width: int, height: int) -> int:
    return int(min(height, width, max(8, min(48, min(height, width) // 4))))


def choose_window(noisy: np.ndarray, refs: np.ndarray, motion: np.ndarray | None = None) -> tuple[int, int, int]:
    """(top, left, side) of the square where the noisy input's frame-to-frame error is largest, among
    those that show the reference (module notes)."""
    height, width = refs.shape[1:3]
    side = strip_side(width=width, height=height)
    if len(refs) < 2:
        return (height - side) // 2, (width - side) // 2, side
    error = temporal_relmse_map(noisy, refs, motion=motion).mean(axis=0)
    found = worst_windows(error, side, count=1, content=content_map(refs))
    top, left = found[0] if found else ((height - side) // 2, (width - side) // 2)
    return int(top), int(left), side


def cut(outputs, noisy, refs, motion=None) -> tuple[int, tuple[int, int, int], np.ndarray]:
    """(first frame, window, F×side×side×3 float32 crops of ``outputs``) for the strip."""
    count = min(STRIP_FRAMES, len(outputs))
    noisy = np.stack(noisy[:count]).astype(np.float64)
    refs_arr = np.stack(refs[:count]).astype(np.float64)
    mot = None if motion is None else np.asarray(motion[:count])
    top, left, side = choose_window(np.nan_to_num(noisy), refs_arr, mot)
    crops = np.stack([np.asarray(o)[top : top + side, left : left + side] for o in outputs[:count]]).astype(np.float32)
    return 0, (top, left, side), crops
