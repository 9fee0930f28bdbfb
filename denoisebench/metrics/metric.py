"""The :class:`Metric` entry: a pure metric function and what a report needs to know about it.

Every module that defines metric functions declares their entries beside them, in a module-level
``METRICS`` tuple, with keyword-only fields; :mod:`.registry` collects those tuples by name. A
module's ``WORST`` (the value its functions return for a non-finite prediction) is derived from
its entries, so direction, domain and worst value are each stated once.

Spatial and gradient metrics take ``(pred, ref)`` H×W×3; temporal ones take
``(pred_seq, ref_seq, **context)`` with the keywords listed in ``accepts`` (``motion``,
``depth``, ``masks``), of which ``requires`` must be given. A metric of any kind whose ``accepts``
lists ``trim`` (the robust scores, :mod:`.robust`) receives the run's trim fraction when one is set.

Aggregation over scenes (``Metric.aggregate``; docs/architecture.md, "Metrics")
-------------------------------------------------------------------------------
Scores of linear radiance grow with a scene's brightness: an arithmetic mean over scenes is then
decided by the brightest scene (measured: ``temporal_l1`` ranked the noisy input above OIDN because
glossy_fireflies scored 1.07–1.44 and every other scene 0.01–0.18). So every metric states how the
analyses combine its per-scene values:

* ``"mean"``: arithmetic mean. Only for scale-free scores (relMSE and its robust form, SMAPE, FLIP,
  SSIM, PSNR, tPSNR, ΔE2000 of tone-mapped colour, ``temporal_relmse`` and its robust form).
* ``"geomean"``: geometric mean (a brightness factor of a scene multiplies every denoiser's
  value alike, so it cannot change the ranking). A zero value makes the mean 0.
* ``"relative_to_input"``: per scene and spp, the value divided by the noisy input's on the same
  scene, then the geometric mean of those ratios; the noisy input scores 1 (lower is better for
  an error: 0.2 = a fifth of the input's error left).

A plugin metric states its rule too (default ``"mean"``: state otherwise when the score is
linear in radiance). ``floor_fn`` (optional): the metric's reference-noise floor
(:mod:`.floors`), called as ``floor_fn(pred, ref, ref_var)`` (spatial) or
``floor_fn(pred_seq, ref_seq, ref_var_seq, **context)`` (temporal) and returning a
:class:`~.floors.Floor`; MSE-family metrics have one.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Literal

__all__ = ["AGGREGATES", "Aggregate", "Domain", "Kind", "Metric", "worst_values"]

Domain = Literal["linear", "tonemapped", "reinhard", "noisebase", "oidn"]
Kind = Literal["spatial", "gradient", "temporal"]
Aggregate = Literal["mean", "geomean", "relative_to_input"]
#: The aggregation rules a Metric may state (module docstring).
AGGREGATES = ("mean", "geomean", "relative_to_input")


@dataclass(frozen=True, kw_only=True)
class Metric:
    """A named metric; every field is a keyword.

    ``domain``: ``"linear"`` (HDR radiance as given), ``"tonemapped"`` (the documented tone map,
    [0, 1)), ``"reinhard"`` (its linear Reinhard stage, for ΔE2000), ``"noisebase"`` (Noisebase's
    8-bit ACES encoding, :mod:`.noisebase`) or ``"oidn"`` (OIDN's Hable filmic + sRGB transfer,
    :mod:`.oidn_compare`). ``worst`` is the value a
    non-finite prediction gets; ``perfect`` the value of prediction == reference. ``aggregate``:
    how values combine over scenes (module docstring); ``floor_fn``: reference-noise floor.
    """

    name: str
    fn: Callable[..., float]
    higher_is_better: bool
    domain: Domain
    kind: Kind
    worst: float
    perfect: float
    map_fn: Callable | None = None
    description: str = ""
    unit: str = ""
    accepts: tuple[str, ...] = ()
    requires: tuple[str, ...] = ()
    aggregate: Aggregate = "mean"
    floor_fn: Callable | None = None

    def __post_init__(self) -> None:
        if not self.name or self.name != self.name.lower():
            raise ValueError(f"metric names are non-empty lower case, got {self.name!r}")
        if self.kind not in ("spatial", "gradient", "temporal"):
            raise ValueError(f"unknown metric kind {self.kind!r}")
        if not callable(self.fn):
            raise ValueError(f"metric {self.name!r}: fn is not callable")
        if self.aggregate not in AGGREGATES:
            raise ValueError(
                f"metric {self.name!r}: aggregate must be one of {', '.join(AGGREGATES)}, got {self.aggregate!r}"
            )
        if self.floor_fn is not None and not callable(self.floor_fn):
            raise ValueError(f"metric {self.name!r}: floor_fn is not callable")

    @property
    def temporal(self) -> bool:
        return self.kind == "temporal"

    def better(self, a: float, b: float) -> bool:
        """True when value ``a`` is strictly better than ``b``."""
        return a > b if self.higher_is_better else a < b


def worst_values(metrics: Iterable[Metric]) -> dict[str, float]:
    """``{name: worst}`` of ``metrics``: a module's ``WORST``, derived from its entries."""
    return {m.name: m.worst for m in metrics}
