"""The benchmark side's one rule for usable numbers: a score or a time is used only when it is finite.

A metric can be NaN (a constant image's correlation) or infinite (a PSNR of an exact match), a
time can be missing (None); the store keeps such values as NULL and every mean, aggregate and
interval leaves them out. Everything that filters goes through here, so they all leave out the
same values.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np


def is_finite(value) -> bool:
    """True for a number that is neither None, NaN nor ±Inf."""
    return value is not None and math.isfinite(value)


def finite_values(values: Iterable) -> list[float]:
    """The finite ones of ``values``, as floats, in order."""
    return [float(v) for v in values if is_finite(v)]


def finite_or_none(value) -> float | None:
    """``value`` as a float when finite, else None (what the store writes as NULL)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def finite_mean(values: Iterable) -> float | None:
    """Arithmetic mean of the finite ``values`` (``numpy.mean``'s summation), None when there are none."""
    kept = finite_values(values)
    return float(np.mean(kept)) if kept else None


def num(value, digits: int = 3) -> str:
    """``value`` to ``digits`` significant digits, "—" for None or a non-finite value."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value:.{digits}g}"
