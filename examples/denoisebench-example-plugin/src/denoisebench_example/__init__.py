"""Example denoisebench plugin: a median filter on albedo-demodulated colour.

Dividing the colour by the albedo (plus ε) removes texture before filtering, so the median smooths
lighting rather than surface detail; multiplying back restores the texture. The median (not a
mean) removes isolated fireflies instead of spreading them.

Notes:
    * ε = 0.05 keeps the division finite where the albedo is zero or tiny (black surfaces,
      background): there the filter works on colour / ε, the same as on colour.
    * Inputs are read-only views: everything here computes new arrays.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter

from denoisebench.denoisers.protocol import DenoiserBase

EPSILON = 0.05


class DemodulatedMedian(DenoiserBase):
    """Median filter of ``size``×``size`` pixels on colour / (albedo + ε)."""

    name = "example_median"
    needs = frozenset({"color", "albedo"})
    temporal = False

    def __init__(self, size: int = 3) -> None:
        if int(size) < 1:
            raise ValueError(f"size must be >= 1 (got {size})")
        self.size = int(size)

    def denoise(self, frame) -> np.ndarray:
        color = np.maximum(np.asarray(frame.color, dtype=np.float32), 0.0)
        albedo = np.clip(np.asarray(frame.buffers["albedo"], dtype=np.float32), 0.0, None) + EPSILON
        irradiance = median_filter(color / albedo, size=(self.size, self.size, 1), mode="nearest")
        return (irradiance * albedo).astype(np.float32)
