"""Compute a chosen set of registered metrics on one frame or on a sequence.

``compute_metrics(pred, ref)`` with H×W×3 arrays evaluates spatial and gradient metrics; with
T×H×W×3 arrays (or lists of frames) it evaluates them per frame (value = mean over frames,
``per_frame`` the list) and the temporal metrics. Each result says how many prediction values
were non-finite; when any were, ``value`` is the metric's defined worst value (never a mean
that skipped them). Given the reference's variance (``ref_var``), metrics with a ``floor_fn``
(the MSE family) also carry their reference-noise ``floor``, ``ref_se`` and ``corrected`` value
(:mod:`.floors`); over a sequence's frames the floor is the mean and ``ref_se`` combines the
frames' as independent (sqrt of the summed squares over the frame count).
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from denoisebench.metrics.registry import Metric, default_metric_names, expand_metric_names, get_metric
from denoisebench.metrics.validation import check_pair, check_sequences

__all__ = ["MetricResult", "compute_metrics"]


@dataclass(frozen=True)
class MetricResult:
    """One metric's value on a frame or a sequence.

    ``nonfinite_count``: NaN/Inf values in the prediction (all frames). When > 0, ``value`` is the
    metric's worst value (``worst_value_used`` is True). ``per_frame``: spatial/gradient values of
    each frame of a sequence. ``map``: H×W (frame), T×H×W (per-frame maps of a sequence) or
    (T−1)×H×W (temporal) when maps were asked for and the metric has one. ``seconds``: wall time.
    """

    name: str
    value: float
    higher_is_better: bool
    domain: str
    kind: str
    nonfinite_count: int = 0
    per_frame: tuple[float, ...] | None = None
    map: np.ndarray | None = field(default=None, repr=False, compare=False)
    seconds: float = 0.0
    floor: float | None = None
    ref_se: float | None = None

    @property
    def corrected(self) -> float | None:
        """``value − floor``: an unbiased estimate of the score against the noise-free image."""
        if self.floor is None:
            return None
        return self.value - self.floor

    @property
    def worst_value_used(self) -> bool:
        return self.nonfinite_count > 0

    def as_dict(self) -> dict:
        """JSON-friendly fields (no map)."""
        return {
            "name": self.name,
            "value": self.value,
            "higher_is_better": self.higher_is_better,
            "domain": self.domain,
            "kind": self.kind,
            "nonfinite_count": self.nonfinite_count,
            "worst_value_used": self.worst_value_used,
            "per_frame": list(self.per_frame) if self.per_frame is not None else None,
            "seconds": self.seconds,
            "floor": self.floor,
            "corrected": self.corrected,
            "ref_se": self.ref_se,
        }


def _is_sequence(pred) -> bool:
    if isinstance(pred, (list, tuple)):
        return True
    ndim = np.ndim(pred)
    if ndim in (3, 4):
        return ndim == 4
    raise ValueError(f"prediction must be H×W×3 or T×H×W×3 (or a list of frames), got shape {np.shape(pred)}")


def _select(names: Iterable[str] | str | None, sequence: bool, context: dict) -> list[Metric]:
    if isinstance(names, str):
        names = [names]
    if names is None:
        chosen = [get_metric(n) for n in default_metric_names()]  # opt-in sets (noisebase) left out
        chosen = [
            m for m in chosen if not m.temporal or (sequence and all(context.get(k) is not None for k in m.requires))
        ]
    else:
        chosen = [get_metric(n) for n in expand_metric_names(names)]  # set names expand
    for m in chosen:
        if m.temporal and not sequence:
            raise ValueError(f"metric {m.name!r} is temporal: it needs sequences (T×H×W×3), not one frame")
        missing = [k for k in m.requires if context.get(k) is None]
        if missing:
            raise ValueError(f"metric {m.name!r} needs {', '.join(missing)}")
    return chosen


def compute_metrics(
    pred,
    ref,
    metrics: Iterable[str] | str | None = None,
    *,
    motion=None,
    depth=None,
    masks=None,
    maps: bool = False,
    ref_var=None,
    trim: float | None = None,
) -> dict[str, MetricResult]:
    """Evaluate ``metrics`` (names; default: every registered one that applies) on pred vs ref.

    ``motion``, ``depth``, ``masks``: per-frame buffers for temporal metrics (see
    ``temporal``); each metric receives those it accepts. ``maps=True`` also returns per-pixel
    maps. ``ref_var``: the reference's per-pixel variance (H×W×3, or T×H×W×3 for a sequence) for
    the floors. ``trim``: the fraction of highest per-pixel errors the robust scores drop (those
    whose ``accepts`` lists ``"trim"``, :mod:`.robust`; None: their default 0.1 %). Returns
    ``{name: MetricResult}`` in the order asked. Bad input (shapes, a non-finite
    reference, a temporal metric on one frame, a missing motion buffer) is a ``ValueError``.
    """
    sequence = _is_sequence(pred)
    context = {"motion": motion, "depth": depth, "masks": masks, "trim": trim}
    chosen = _select(metrics, sequence, context)
    checked = check_sequences(pred, ref) if sequence else check_pair(pred, ref)
    pred_arr, ref_arr, total_bad = checked.pred, checked.ref, checked.nonfinite_count

    results: dict[str, MetricResult] = {}
    for m in chosen:
        t0 = time.perf_counter()
        per_frame = None
        the_map = None
        kwargs = _kwargs(m, context)
        if m.temporal:
            value = float(m.fn(pred_arr, ref_arr, **kwargs))
            if maps and m.map_fn is not None:
                the_map = m.map_fn(pred_arr, ref_arr, **kwargs)
        elif sequence:
            values = [float(m.fn(p, r, **kwargs)) for p, r in zip(pred_arr, ref_arr)]
            per_frame = tuple(values)
            value = m.worst if total_bad else float(np.mean(values))
            if maps and m.map_fn is not None:
                the_map = np.stack([m.map_fn(p, r, **kwargs) for p, r in zip(pred_arr, ref_arr)])
        else:
            value = float(m.fn(pred_arr, ref_arr, **kwargs))
            if maps and m.map_fn is not None:
                the_map = m.map_fn(pred_arr, ref_arr, **kwargs)
        if total_bad:
            value = m.worst
        floor = se = None
        if ref_var is not None and m.floor_fn is not None:
            floor, se = _floor(m, pred_arr, ref_arr, ref_var, sequence, context)
        results[m.name] = MetricResult(
            name=m.name,
            value=value,
            higher_is_better=m.higher_is_better,
            domain=m.domain,
            kind=m.kind,
            nonfinite_count=total_bad,
            per_frame=per_frame,
            map=the_map,
            seconds=time.perf_counter() - t0,
            floor=floor,
            ref_se=se,
        )
    return results


def _kwargs(m: Metric, context: dict) -> dict:
    """The context keywords ``m`` accepts that were given (motion, depth, masks, trim)."""
    return {k: context[k] for k in m.accepts if context.get(k) is not None}


def _floor(m: Metric, pred, ref, ref_var, sequence: bool, context: dict) -> tuple[float, float]:
    kwargs = _kwargs(m, context)
    if m.temporal or not sequence:  # one call: a whole sequence (temporal) or one frame
        result = m.floor_fn(pred, ref, ref_var, **kwargs)
        return float(result[0]), float(result[1])
    ref_var = np.asarray(ref_var, dtype=np.float64)
    if ref_var.shape[0] != len(ref):
        raise ValueError(f"ref_var has {ref_var.shape[0]} frames, the reference {len(ref)}")
    parts = [m.floor_fn(p, r, v, **kwargs) for p, r, v in zip(pred, ref, ref_var)]
    floors = np.array([float(x[0]) for x in parts])
    ses = np.array([float(x[1]) for x in parts])
    return float(floors.mean()), float(np.sqrt(np.sum(np.square(ses))) / len(parts))
