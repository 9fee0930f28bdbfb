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
"""

from __future__ import annotations

import numpy as np

from denoisebench.metrics import temporal_relmse_map

# Lazy imports: scipy only where windows are chosen.

#: Frames in a strip (the first ones of the sequence).
STRIP_FRAMES = 8

__all__ = ["STRIP_FRAMES", "window_size", "worst_windows", "strip_side", "choose_window", "cut"]


def window_size(height: int, width: int) -> int:
    """Side of a worst-region window: a quarter of the short side, at least 4 pixels."""
    return max(4, min(height, width) // 4)


def worst_windows(error_map: np.ndarray, size: int, count: int = 2) -> list[tuple[int, int]]:
    """(top, left) of up to ``count`` non-overlapping size×size windows with the largest mean error."""
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


def strip_side(height: int, width: int) -> int:
    return int(min(height, width, max(8, min(48, min(height, width) // 4))))


def choose_window(noisy: np.ndarray, refs: np.ndarray, motion: np.ndarray | None = None) -> tuple[int, int, int]:
    """(top, left, side) of the square where the noisy input's frame-to-frame error is largest."""
    height, width = refs.shape[1:3]
    side = strip_side(height, width)
    if len(refs) < 2:
        return (height - side) // 2, (width - side) // 2, side
    error = temporal_relmse_map(noisy, refs, motion=motion).mean(axis=0)
    found = worst_windows(error, side, count=1)
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
