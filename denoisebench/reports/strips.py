"""Frame strips: one crop of consecutive frames per denoiser, so a reader can *see* flicker.

The runner cuts the strip of every unit (:func:`denoisebench.results.crops.cut`, which also says
how its window is chosen) and the store keeps it; a report lays each one out side by side
(:func:`strip_png`), frames left to right, beside the noisy input's and the reference's strips of
the same crop, and also as an animated PNG (:func:`strip_apng`) that loops the frames in place.

Notes
-----
* Images are tone-mapped like the metrics (:func:`.images.to_png`) and upscaled by pixel
  repetition.
"""

from __future__ import annotations

import io

import numpy as np

from denoisebench.metrics.tonemap import tonemap

# Lazy imports: PIL only where a strip is encoded.

__all__ = ["strip_png", "strip_apng"]


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
