"""The lens sample → lens point map our renderer uses, in numpy (for filters and synthetic frames).

Per-sample data stores the lens random parameter as the uniform square sample (u, v) ∈ [0, 1)²
that drove the ray (docs/architecture.md, "Buffers"); the renderer maps it to the unit disk with Shirley and
Chiu's concentric map, as Mitsuba's ``square_to_uniform_disk_concentric`` does. A defocused hit point
moves linearly with the *disk* point, not with (u, v), so statistics about lens dependence (RPF's
mutual information) are taken on the disk point.
"""

from __future__ import annotations

import numpy as np


def square_to_disk_concentric(square: np.ndarray) -> np.ndarray:
    """…×2 samples in [0, 1)² → …×2 points in the unit disk (Shirley & Chiu 1997), area preserving."""
    square = np.asarray(square, dtype=np.float64)
    a = 2.0 * square[..., 0] - 1.0
    b = 2.0 * square[..., 1] - 1.0
    first = np.abs(a) > np.abs(b)
    radius = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, (np.pi / 4.0) * (b / a), (np.pi / 2.0) - (np.pi / 4.0) * (a / b))
    phi = np.where((a == 0.0) & (b == 0.0), 0.0, phi)
    return np.stack([radius * np.cos(phi), radius * np.sin(phi)], axis=-1)
