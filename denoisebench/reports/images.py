"""Images for reports: tone-mapped PNG (base64 data URIs), worst-region windows and zoomed crops.

Notes
-----
* The tone map is the metrics' one (:func:`denoisebench.metrics.tonemap.tonemap`: Reinhard then
  sRGB), so what the reader sees is what PSNR/SSIM measured. NaN/Inf never reach it: images shown
  are references, sanitised inputs and checked denoiser outputs.
* Crops are upscaled by pixel repetition (no interpolation): a zoom must show the denoiser's
  pixels, not a resampler's.
* Worst regions are chosen on the mean relMSE map of all the denoisers shown, so every column of a
  comparison shows the same place; windows do not overlap.
"""

from __future__ import annotations

import base64
import io

import numpy as np

from denoisebench.metrics.tonemap import tonemap

# Lazy imports: PIL, matplotlib's colour maps and scipy only where an image is encoded, coloured or
# filtered, so that a run without a report never loads them.


def to_png(image: np.ndarray, scale: int = 1) -> bytes:
    """PNG bytes of the tone-mapped H×W×3 linear image, upscaled ``scale``× by pixel repetition."""
    from PIL import Image

    display = np.clip(np.nan_to_num(tonemap(image), nan=0.0), 0.0, 1.0)
    pixels = np.round(display * 255.0).astype(np.uint8)
    if scale > 1:
        pixels = np.repeat(np.repeat(pixels, scale, axis=0), scale, axis=1)
    buffer = io.BytesIO()
    Image.fromarray(pixels, mode="RGB").save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


def data_uri(png: bytes, mime: str = "image/png") -> str:
    return f"data:{mime};base64,{base64.b64encode(png).decode('ascii')}"


def crop(image: np.ndarray, top: int, left: int, size: int) -> np.ndarray:
    return image[top : top + size, left : left + size]


def crop_scale(size: int, target: int = 128) -> int:
    """Pixel repetition that brings a crop to about ``target`` pixels."""
    return max(1, target // max(size, 1))


#: Colour of pixels with fewer than one sample in an spp map (outside the colour map's range).
NO_SAMPLE_RGB = (255, 0, 0)


def _viridis(values: np.ndarray) -> np.ndarray:
    """uint8 RGB of ``values`` in [0, 1] on matplotlib's viridis map (perceptually uniform, grey-scale safe)."""
    from matplotlib import colormaps

    rgba = colormaps["viridis"](np.clip(values, 0.0, 1.0))
    return np.round(rgba[..., :3] * 255.0).astype(np.uint8)


def _png(pixels: np.ndarray, scale: int = 1) -> bytes:
    from PIL import Image

    if scale > 1:
        pixels = np.repeat(np.repeat(pixels, scale, axis=0), scale, axis=1)
    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels), mode="RGB").save(buffer, format="PNG", optimize=True)
    return buffer.getvalue()


def spp_map_png(counts: np.ndarray, top: int, scale: int = 1) -> bytes:
    """PNG of an H×W samples-per-pixel map: viridis, linear from 0 spp to ``top`` spp (brighter: more
    samples; above ``top`` clips); pixels with fewer than one sample in :data:`NO_SAMPLE_RGB`."""
    counts = np.asarray(counts, dtype=np.float64)
    pixels = _viridis(counts / max(float(top), 1.0))
    pixels[counts < 1] = NO_SAMPLE_RGB
    return _png(pixels, scale)


def colour_bar_png(width: int = 128, height: int = 10) -> bytes:
    """The spp maps' colour bar: viridis from 0 (left) to the map's ``top`` (right), ``width``×``height`` px."""
    row = _viridis(np.linspace(0.0, 1.0, width))
    return _png(np.repeat(row[None], height, axis=0))
