"""Input checks shared by every metric, and the non-finite policy.

Policy
------
* Shapes: images are H×W×3 (H, W ≥ 1), sequences T×H×W×3 (an array or a list of images).
  Prediction and reference must have the same shape; otherwise ``ValueError`` naming both.
* Dtypes: real numbers (float or integer). bool, complex and object arrays are a ``ValueError``.
* The **reference** must be finite: NaN/Inf there is bad data, a ``ValueError``.
* A **prediction** with NaN/Inf is never averaged away: the scalar metric returns that metric's
  defined worst value (``+inf`` for unbounded errors, the bound for bounded scores, see each
  function and ``registry``), and :func:`denoisebench.metrics.compute_metrics` reports how many
  values were non-finite. Per-pixel maps put the worst value at the pixels that have a non-finite
  channel (pixel-wise metrics) or everywhere (windowed metrics, whose neighbourhoods would mix).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "Checked",
    "as_image",
    "as_sequence",
    "check_pair",
    "check_sequences",
    "count_nonfinite",
    "as_motion",
    "as_depth",
    "as_mask",
]


class MetricNotApplicable(ValueError):  # noqa: N818 - reads as what it says: "metric not applicable"
    """A metric's precondition on the frames (not on the prediction) is not met, e.g. SSIM on frames
    smaller than its window. The benchmark records the metric as not applicable with this message
    and keeps the frame's other metrics; anything else raising ValueError is bad input."""


class Checked(NamedTuple):
    """A validated prediction/reference pair (or pair of sequences).

    ``bad`` marks pixels (…×H×W) of the prediction with at least one non-finite channel;
    ``nonfinite_count`` counts non-finite *values* (channels) in the prediction.
    """

    pred: np.ndarray
    ref: np.ndarray
    bad: np.ndarray
    nonfinite_count: int


def _as_real_array(a, name: str) -> np.ndarray:
    try:
        arr = np.asarray(a)
    except Exception as exc:  # ragged lists and the like
        raise ValueError(f"{name} is not an array: {exc}") from None
    if arr.dtype.kind not in "fiu":
        raise ValueError(f"{name} must hold real numbers (float or int), got dtype {arr.dtype}")
    if arr.dtype.kind != "f":
        arr = arr.astype(np.float64)
    return arr


def as_image(a, name: str = "image") -> np.ndarray:
    """``a`` as an H×W×3 real array (no copy when it already is one)."""
    arr = _as_real_array(a, name)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise ValueError(f"{name} must be H×W×3 with H, W ≥ 1, got shape {arr.shape}")
    return arr


def as_sequence(seq, name: str = "sequence") -> np.ndarray:
    """A list of H×W×3 images or a T×H×W×3 array as a T×H×W×3 array."""
    if isinstance(seq, (list, tuple)):
        if len(seq) == 0:
            raise ValueError(f"{name} is empty")
        frames = [as_image(f, f"{name}[{i}]") for i, f in enumerate(seq)]
        shapes = {f.shape for f in frames}
        if len(shapes) > 1:
            raise ValueError(f"{name} mixes frame shapes {sorted(shapes)}")
        return np.stack(frames)
    arr = _as_real_array(seq, name)
    if arr.ndim != 4 or arr.shape[3] != 3 or min(arr.shape[:3]) < 1:
        raise ValueError(f"{name} must be T×H×W×3 (or a list of H×W×3), got shape {arr.shape}")
    return arr


def count_nonfinite(a: np.ndarray) -> int:
    """Number of NaN/±Inf values in ``a``."""
    return int(a.size - np.count_nonzero(np.isfinite(a)))


def _check(pred: np.ndarray, ref: np.ndarray, what: str) -> Checked:
    if pred.shape != ref.shape:
        raise ValueError(f"prediction {what} has shape {pred.shape} but reference {what} has shape {ref.shape}")
    ref_bad = count_nonfinite(ref)
    if ref_bad:
        raise ValueError(f"reference {what} has {ref_bad} non-finite values (NaN/Inf): bad data")
    finite = np.isfinite(pred)
    count = int(pred.size - np.count_nonzero(finite))
    bad = ~finite.all(axis=-1) if count else np.zeros(pred.shape[:-1], dtype=bool)
    return Checked(pred, ref, bad, count)


def check_pair(pred, ref) -> Checked:
    """Validate an image pair: shapes, dtypes, a finite reference; count the prediction's NaN/Inf."""
    return _check(as_image(pred, "prediction"), as_image(ref, "reference"), "image")


def check_sequences(pred_seq, ref_seq, min_frames: int = 1) -> Checked:
    """Validate a pair of sequences (T×H×W×3 each) like :func:`check_pair`."""
    pred = as_sequence(pred_seq, "prediction sequence")
    ref = as_sequence(ref_seq, "reference sequence")
    checked = _check(pred, ref, "sequence")
    if pred.shape[0] < min_frames:
        raise ValueError(f"needs at least {min_frames} frames, got {pred.shape[0]}")
    return checked


def _frames(a, name: str, n: int, hw: tuple[int, int], channels: int) -> np.ndarray:
    if isinstance(a, (list, tuple)):
        a = np.stack([np.asarray(x) for x in a]) if len(a) else np.empty((0,))
    arr = _as_real_array(a, name)
    if channels == 1 and arr.ndim == 4 and arr.shape[3] == 1:
        arr = arr[..., 0]
    expected = (n, *hw) + ((channels,) if channels > 1 else ())
    if arr.shape != expected:
        raise ValueError(f"{name} must have shape {expected} (one per frame), got {arr.shape}")
    bad = count_nonfinite(arr)
    if bad:
        raise ValueError(f"{name} has {bad} non-finite values (NaN/Inf)")
    return arr


def as_motion(motion, n: int, hw: tuple[int, int]) -> np.ndarray:
    """Motion buffers, one H×W×2 (x, y) per frame (entry 0 is unused), as T×H×W×2; finite."""
    return _frames(motion, "motion", n, hw, 2)


def as_depth(depth, n: int, hw: tuple[int, int]) -> np.ndarray:
    """Depth buffers, one H×W or H×W×1 per frame, as T×H×W; finite."""
    return _frames(depth, "depth", n, hw, 1)


def as_mask(masks, n: int, hw: tuple[int, int]) -> np.ndarray:
    """Masks (True = pixel counts), one H×W per frame or one H×W for all frames, as T×H×W bool."""
    arr = np.asarray(masks)
    if arr.dtype != bool:
        raise ValueError(f"masks must be boolean (True = pixel counts), got dtype {arr.dtype}")
    if arr.shape == hw:
        return np.broadcast_to(arr, (n, *hw))
    if arr.ndim == 4 and arr.shape[3] == 1:
        arr = arr[..., 0]
    if arr.shape != (n, *hw):
        raise ValueError(f"masks must have shape {hw} or {(n, *hw)}, got {arr.shape}")
    return arr
