"""Frame strips: one crop of consecutive frames per denoiser, so a reader can *see* flicker.

The runner cuts the strip of every unit (:func:`cut`) while the outputs are in memory and the
store keeps it (table ``strips``); the report lays each one out side by side (:func:`strip_png`),
frames left to right, beside the noisy input's and the reference's strips of the same crop, and
also as an animated PNG (:func:`strip_apng`) that loops the frames in place.

Notes
-----
* **The same crop for every denoiser.** The window is chosen from the data alone, never from a
  denoiser's output: the square where the noisy input flickers most (its mean
  ``temporal_relmse`` map over the strip's frame pairs, warped by the motion buffer when there is
  one). Every unit of a sequence at one spp therefore cuts the same pixels.
* At most :data:`STRIP_FRAMES` frames, the first ones of the sequence (a temporal denoiser's
  warm-up is part of what a reader should see); the side is a quarter of the image's short side,
  between 8 and 48 pixels.
* Images are tone-mapped like the metrics (:func:`.images.to_png`) and upscaled by pixel
  repetition.
"""

from __future__ import annotations

import io

import numpy as np

from denoisebench.leaderboard.images import worst_windows
from denoisebench.metrics import temporal_relmse_map
from denoisebench.metrics.tonemap import tonemap

# Lazy imports: PIL only where a strip is encoded.

#: Frames in a strip (the first ones of the sequence).
STRIP_FRAMES = 8

__all__ = ["STRIP_FRAMES", "strip_side", "choose_window", "cut", "strip_png", "strip_apng"]


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


def _pixels(crops: np.ndarray, scale: int) -> list[np.ndarray]:

    frames = []
    for crop in crops:
        display = np.clip(np.nan_to_num(tonemap(crop), nan=0.0), 0.0, 1.0)
        pixels = np.round(display * 255.0).astype(np.uint8)
        if scale > 1:
            pixels = np.repeat(np.repeat(pixels, scale, axis=0), scale, axis=1)
        frames.append(pixels)
    return frames


def strip_png(crops: np.ndarray, scale: int = 2, gap: int = 2) -> bytes:
    """PNG of the crops side by side, frame 0 on the left, ``gap`` white pixels between them."""
    from PIL import Image

    frames = _pixels(crops, scale)
    height, width = frames[0].shape[:2]
    canvas = np.full((height, len(frames) * (width + gap) - gap, 3), 255, dtype=np.uint8)
    for i, pixels in enumerate(frames):
        canvas[:, i * (width + gap) : i * (width + gap) + width] = pixels
    buffer = io.BytesIO()
    Image.fromarray(canvas, mode="RGB").save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


def strip_apng(crops: np.ndarray, scale: int = 3, milliseconds: int = 250) -> bytes:
    """Animated PNG looping the crops in place (pillow's APNG writer), ``milliseconds`` per frame."""
    from PIL import Image

    frames = [Image.fromarray(p, mode="RGB") for p in _pixels(crops, scale)]
    buffer = io.BytesIO()
    frames[0].save(buffer, format="PNG", save_all=True, append_images=frames[1:], duration=milliseconds, loop=0)
    return buffer.getvalue()
