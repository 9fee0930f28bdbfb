"""The Denoiser protocol (docs/architecture.md) and a small base class that fills in its defaults.

A denoiser is any object with::

    name: str
    needs: frozenset[str]      # buffers read, e.g. {"color", "albedo", "normal"}, or {"samples"}
    temporal: bool             # True: frames arrive in order; reset() is called between sequences
    trained_scenes: frozenset[str]  # optional: scene names (family_seed) a learned denoiser was trained on
    def reset(self) -> None: ...
    def denoise(self, frame: Frame) -> np.ndarray: ...   # H×W×3 float32 linear radiance

Only ``denoise`` is required of a plugin: :func:`describe` reads the other attributes with the
defaults ``name`` = the spec it was loaded from, ``needs`` = {"color"}, ``temporal`` = False and a
no-op ``reset``; ``trained_scenes`` defaults to none. A learned denoiser that declares the scenes it
was trained on (the built-in ``dpcn``/``kpcn``/``rae``/``lbf`` read them from their checkpoint) has its
scores on those scenes marked in the benchmark and its report as not held-out: a scene name is its
family and seed, so the same name is the same stage. The frame a denoiser receives has been sanitised by the runner (no NaN/Inf) and its
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
    trained_scenes: frozenset[str] = frozenset()

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
    trained_scenes: frozenset[str] = frozenset()


def describe(denoiser: object, fallback_name: str = "unnamed") -> DenoiserInfo:
    """Read ``name``, ``needs``, ``temporal`` and ``trained_scenes`` of any denoiser-like object, with defaults.

    Raises TypeError (one line) when the object has no callable ``denoise`` or a malformed
    attribute (``needs`` or ``trained_scenes`` not a collection of strings, ``name`` not a string).
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
    trained = getattr(denoiser, "trained_scenes", None) or frozenset()
    if isinstance(trained, str) or not all(isinstance(item, str) for item in trained):
        raise TypeError(f"denoiser {name!r}: trained_scenes must be a collection of scene names")
    return DenoiserInfo(name=name, needs=frozenset(needs), temporal=temporal, trained_scenes=frozenset(trained))
