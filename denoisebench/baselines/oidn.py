"""Intel Open Image Denoise through ``pyoidn`` (pinned in requirements.txt): the production peer.

The "RT" filter in HDR mode (``hdr=True``) on linear radiance, with the albedo and normal buffers
as auxiliary images when the frame has them (OIDN takes a normal only together with an albedo).
Inputs are made what OIDN documents: colour non-negative, albedo clipped to [0, 1], normals to
[-1, 1], all float32 and contiguous. ``quality`` is OIDN's: high (the default), balanced or fast.
The auxiliary images are noisy at low spp, so ``clean_aux`` stays False (OIDN prefilters them).

Isolated fireflies are clamped before OIDN sees them (``firefly_factor``, default 16): a pixel
channel above 16× the largest value of its 8 neighbours is set to that bound. OIDN's network
otherwise smears a single 1e5 pixel over a ~10×10 patch (the hard-case suite measured a robust mean
438× the input's); smooth ranges pass untouched (a 1e-6..1e6 ramp over 32 pixels steps 2.4× per pixel).
``firefly_factor=None`` gives plain OIDN.

Without ``pyoidn`` (or with a build that cannot load its native library) constructing the
denoiser raises :class:`~denoisebench.denoisers.registry.DenoiserUnavailableError` with a one-line
reason, which the registry reports as a load error.
"""

from __future__ import annotations

import numpy as np

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.protocol import DenoiserBase
from denoisebench.denoisers.registry import DenoiserUnavailableError

# Lazy imports: pyoidn (optional: a missing package is this denoiser's load error, not an
# import error of the registry) and scipy are imported where they are used.

QUALITIES = ("high", "balanced", "fast")
PYOIDN_PIN = "pyoidn==2.5.1.0"
FIREFLY_FACTOR = 16.0


def load_pyoidn():
    """The ``pyoidn`` module, or DenoiserUnavailableError saying why it cannot be used."""
    try:
        import pyoidn  # noqa: PLC0415 - optional dependency
    except Exception as error:  # noqa: BLE001 - ImportError, or OSError from the native library
        detail = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise DenoiserUnavailableError(f"oidn needs the pyoidn package ({PYOIDN_PIN}): {detail}") from None
    return pyoidn


def oidn_version() -> str | None:
    """The OIDN library version pyoidn wraps, or None when it is not available."""
    try:
        module = load_pyoidn()
    except DenoiserUnavailableError:
        return None
    version = getattr(getattr(module, "version", None), "oidn_version", None)
    return str(version) if version is not None else None


def clamp_isolated(color: np.ndarray, factor: float) -> np.ndarray:
    """``color`` (H×W×C, non-negative) with each value capped at ``factor`` × the largest value of
    its 8 neighbours in the same channel (edges replicate)."""
    from scipy.ndimage import maximum_filter  # noqa: PLC0415

    ring = np.ones((3, 3, 1), dtype=bool)
    ring[1, 1, 0] = False
    bound = maximum_filter(color, footprint=ring, mode="nearest") * np.float32(factor)
    return np.minimum(color, bound)


class OIDN(DenoiserBase):
    """OIDN RT filter, HDR, with albedo + normal. ``quality``: high, balanced or fast."""

    needs = frozenset({"color"})  # albedo and normal are used when present
    temporal = False

    def __init__(
        self,
        quality: str = "high",
        *,
        use_albedo: bool = True,
        use_normal: bool = True,
        firefly_factor: float | None = FIREFLY_FACTOR,
    ) -> None:
        if quality not in QUALITIES:
            raise ValueError(f"unknown OIDN quality {quality!r}; known: {', '.join(QUALITIES)}")
        if firefly_factor is not None and not firefly_factor >= 1.0:
            raise ValueError(f"firefly_factor must be >= 1 or None (got {firefly_factor})")
        self.firefly_factor = firefly_factor
        self._pyoidn = load_pyoidn()
        self.quality = quality
        self.use_albedo = use_albedo
        self.use_normal = use_normal
        # read when the frame has them (normal only beside albedo): what its input's render is charged
        self.uses = frozenset(("albedo", "normal") if use_albedo and use_normal else ("albedo",) if use_albedo else ())
        self.name = "oidn" if quality == "high" else f"oidn_{quality}"

    def denoise(self, frame: Frame) -> np.ndarray:
        color = np.maximum(np.asarray(frame.color, dtype=np.float32), 0.0)
        if self.firefly_factor is not None:
            color = clamp_isolated(color, self.firefly_factor)
        color = np.ascontiguousarray(color, dtype=np.float32)
        albedo = normal = None
        if self.use_albedo and frame.has("albedo"):
            albedo = np.ascontiguousarray(np.clip(frame.buffers["albedo"], 0.0, 1.0), dtype=np.float32)
            if self.use_normal and frame.has("normal"):
                normal = np.ascontiguousarray(np.clip(frame.buffers["normal"], -1.0, 1.0), dtype=np.float32)
        output = self._pyoidn.denoise(color, albedo, normal, hdr=True, quality=self.quality)
        return np.maximum(np.asarray(output, dtype=np.float32), 0.0)
