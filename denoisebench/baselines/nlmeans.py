"""Non-local means (Buades et al. 2005) from scikit-image: the image-only classic.

scikit-image's ``denoise_nl_means`` expects roughly uniform noise, which HDR Monte Carlo
noise is not, so the filter runs in the log domain, y = log(1 + c / m) with m the frame's mean
colour, and maps back with m·(exp(y) − 1). The noise level σ of y is Immerkær's estimate (mean absolute
response to the 3×3 Laplacian-difference mask, averaged over channels: no PyWavelets needed), h = ``h_factor``·σ, ``fast_mode`` with 5×5 patches searched within
``patch_distance`` = 6 pixels. Log-domain averaging darkens noisy regions a little (Jensen);
this baseline reads colour only and ignores every feature buffer.
"""

from __future__ import annotations

import numpy as np

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.protocol import DenoiserBase

# Lazy imports: scipy and scikit-image (0.3-0.9 s) are imported inside the filter, so that
# the registry can list this denoiser without loading them.


def immerkaer_sigma(image: np.ndarray) -> float:
    """Gaussian noise σ of an H×W×C image (Immerkær 1996), averaged over channels."""
    from scipy.ndimage import convolve

    mask = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    height, width = image.shape[:2]
    if height < 3 or width < 3:
        return 0.0
    sigmas = []
    for channel in range(image.shape[2]):
        response = convolve(image[..., channel], mask, mode="nearest")[1:-1, 1:-1]
        sigmas.append(np.sqrt(np.pi / 2.0) * np.mean(np.abs(response)) / 6.0)
    return float(np.mean(sigmas))


class NLMeans(DenoiserBase):
    name = "nlmeans"
    needs = frozenset({"color"})
    temporal = False

    def __init__(self, patch_size: int = 5, patch_distance: int = 6, h_factor: float = 0.8) -> None:
        if patch_size < 1 or patch_distance < 1 or h_factor <= 0:
            raise ValueError("patch_size and patch_distance must be >= 1 and h_factor > 0")
        self.patch_size = int(patch_size)
        self.patch_distance = int(patch_distance)
        self.h_factor = float(h_factor)

    def denoise(self, frame: Frame) -> np.ndarray:
        from skimage.restoration import denoise_nl_means

        color = np.maximum(np.asarray(frame.color, dtype=np.float64), 0.0)
        height, width = color.shape[:2]
        scale = float(np.mean(color))
        if min(height, width) < 3 or not scale > 0:
            return color.astype(np.float32)
        y = np.log1p(color / scale)
        sigma = immerkaer_sigma(y)
        if not np.isfinite(sigma) or sigma <= 0:
            return color.astype(np.float32)
        patch = min(self.patch_size, height, width)
        filtered = denoise_nl_means(
            y,
            patch_size=patch,
            patch_distance=self.patch_distance,
            h=self.h_factor * sigma,
            sigma=sigma,
            fast_mode=True,
            channel_axis=-1,
        )
        out = scale * np.expm1(np.maximum(filtered, 0.0))
        return out.astype(np.float32)
