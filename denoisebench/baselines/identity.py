"""The identity baseline: the noisy input itself, the score every denoiser has to beat."""

from __future__ import annotations

import numpy as np

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.protocol import DenoiserBase


class Identity(DenoiserBase):
    """Returns a float32 copy of ``frame.color``."""

    name = "identity"
    needs = frozenset({"color"})
    temporal = False

    def denoise(self, frame: Frame) -> np.ndarray:
        return np.array(frame.color, dtype=np.float32, copy=True)
