"""Image files to arrays: the one place where reading a scene's textures needs Mitsuba.

USD names texture files; decoding them (PNG, JPEG, EXR, HDR, ...) is done with Mitsuba's
``Bitmap``, the same decoder the renderer would use, so that a texture's stored values are the
ones a Mitsuba render of the file would see. This module is that crossing, and nothing else:
``generator.usd`` calls it to read textures into plain arrays, and no USD object enters it.

Notes
-----
Mitsuba is loaded when the first image is decoded (``mitsuba_runtime.load_mitsuba`` picks the
variant and libLLVM), not at import, so that importing the USD side stays free of Dr.Jit.
Non-finite decoded values (a corrupt EXR) become 0 here, so a texture can never put NaN into a
render.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

from denoisebench.mitsuba_runtime import load_mitsuba


def decode_image(data: bytes, suffix: str) -> np.ndarray:
    """Image bytes → float32 H×W×C array of the stored values (0..1 for integer formats; no curve applied)."""
    mi = load_mitsuba()
    handle, temporary = tempfile.mkstemp(prefix="denoisebench-texture-", suffix=suffix)
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
        bitmap = mi.Bitmap(temporary)
    finally:
        os.unlink(temporary)
    bitmap.set_srgb_gamma(False)  # keep the stored numbers; the colour space is decided below
    converted = bitmap.convert(component_format=mi.Struct.Type.Float32, srgb_gamma=False)
    array = np.array(converted, dtype=np.float32)
    if array.ndim == 2:
        array = array[..., None]
    if array.ndim != 3 or min(array.shape) < 1:
        raise ValueError(f"decoded to an empty image {array.shape}")
    if not np.all(np.isfinite(array)):
        array = np.nan_to_num(array, nan=0.0, posinf=0.0, neginf=0.0)
    return array
