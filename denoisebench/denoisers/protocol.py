"""The Denoiser protocol (DESIGN.md) and a small base class that fills in its defaults.

A denoiser is any object with::

    name: str
    needs: frozenset[str]      # buffers read, e.g. {"color", "albedo", "normal"}, or {"samples"}
    temporal: bool             # True: frames arrive in order; reset() is called between sequences
    def reset(self) -> None: ...
    def denoise(self, frame: Frame) -> np.ndarray: ...   # H×W×3 float32 linear radiance

Only ``denoise`` is required of a plugin: :func:`describe` reads the other attributes with the
defaults ``name`` = the spec it was loaded from, ``needs`` = {"color"}, ``temporal`` = False and a
no-op ``reset``. The frame a denoiser receives has been sanitised by the runner (no NaN/Inf) and its
arrays are read-only views: a denoiser that wants to write must copy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from denoisebench.dataset.frame import Frame


@runtime_checkable
class Denoiser(Protocol):
    name: str
    needs: frozenset[str]
    temporal: bool

    def reset(self) -> None: ...

    def denoise(self, frame: Frame) -> np.ndarray: ...


class DenoiserBase:
    """Convenience base: a spatial denoiser that reads color only. Subclasses override ``denoise``."""

    name: str = "unnamed"
    needs: frozenset[str] = frozenset({"color"})
    temporal: bool = False

    def reset(self) -> None:
        """Forget state between sequences (nothing to forget for a spatial denoiser)."""

    def denoise(self, frame: Frame) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<denoiser {self.name}>"


@dataclass(frozen=True)
class DenoiserInfo:
    """What the harness reads of a denoiser object, with the protocol's defaults filled in."""

    name: str
    needs: frozenset[str]
    temporal: bool


def describe(denoiser: object, fallback_name: str = "unnamed") -> DenoiserInfo:
    """Read ``name``, ``needs`` and ``temporal`` of any denoiser-like object, with defaults.

    Raises TypeError (one line) when the object has no callable ``denoise`` or a malformed
    attribute (``needs`` not a collection of strings, ``name`` not a string).
    """
    if not callable(getattr(denoiser, "denoise", None)):
        raise TypeError(f"{type(denoiser).__name__} object has no callable denoise(frame)")
    name = getattr(denoiser, "name", None) or fallback_name
    if not isinstance(name, str):
        raise TypeError(f"denoiser name must be a string, got {type(name).__name__}")
    needs = getattr(denoiser, "needs", None)
    if needs is None:
        needs = frozenset({"color"})
    if isinstance(needs, str) or not all(isinstance(item, str) for item in needs):
        raise TypeError(f"denoiser {name!r}: needs must be a collection of buffer names")
    temporal = bool(getattr(denoiser, "temporal", False))
    return DenoiserInfo(name=name, needs=frozenset(needs), temporal=temporal)
