"""Where a comparison's zoomed crops look: the worst relMSE among windows a reader can see into.

The error is the denoisers' mean relMSE map (as before); the windows are restricted to those that
cover at least :data:`denoisebench.results.crops.MIN_CONTENT` of the reference's visible pixels
(:func:`denoisebench.results.crops.content_map`), wherever any window does. relMSE's ``+ 0.01`` keeps
single black pixels from deciding it, but a patch of night sky around small lamps still scores
highest, and its crop is black on every tile.

:func:`shows_something` is the check a report makes of a crop it did not choose (a stored frame
strip's window is chosen when the run is made): its tone-mapped reference must reach
:data:`denoisebench.results.crops.VISIBLE_LEVEL` on at least that share of its pixels.
"""

from __future__ import annotations

import numpy as np

from denoisebench.metrics import relmse_map
from denoisebench.results.crops import MIN_CONTENT, content_map, worst_windows


def error_map(images: list[np.ndarray], reference: np.ndarray) -> np.ndarray:
    """H×W mean over ``images`` of the channel-mean relMSE map against ``reference``."""
    height, width = reference.shape[:2]
    if not images:
        return np.zeros((height, width))
    return np.mean([relmse_map(img, reference).reshape(height, width, -1).mean(axis=-1) for img in images], axis=0)


def crop_windows(images: list[np.ndarray], reference: np.ndarray, size: int, count: int = 2) -> list[tuple[int, int]]:
    """(top, left) of up to ``count`` non-overlapping windows of worst relMSE that show the reference."""
    return worst_windows(error_map(images, reference), size, count, content=content_map(reference))


def shows_something(reference_crop: np.ndarray) -> bool:
    """Whether a crop of the reference (H×W×3 or F×H×W×3, linear) is visible on at least
    MIN_CONTENT of its pixels after the tone map."""
    crop = np.asarray(reference_crop)
    return bool(crop.size) and float(content_map(crop).mean()) >= MIN_CONTENT - 1e-9
