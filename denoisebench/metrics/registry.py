"""Metrics by name, so reports and plugins can ask for ``"relmse"``, ``"flip"``, ...

A :class:`Metric` pairs the pure function with what a report needs to know about it.
Spatial and gradient metrics take ``(pred, ref)`` H×W×3; temporal ones take
``(pred_seq, ref_seq, **context)`` with the keywords listed in ``accepts`` (``motion``,
``depth``, ``masks``), of which ``requires`` must be given. A metric of any kind whose ``accepts``
lists ``trim`` (the robust scores, :mod:`.robust`) receives the run's trim fraction when one is set.

Aggregation over scenes (``Metric.aggregate``; docs/architecture.md, "Metrics")
-------------------------------------------------------------------------------
Scores of linear radiance grow with a scene's brightness: an arithmetic mean over scenes is then
decided by the brightest scene (measured: ``temporal_l1`` ranked the noisy input above OIDN because
glossy_fireflies scored 1.07–1.44 and every other scene 0.01–0.18). So every metric states how the
leaderboard combines its per-scene values:

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

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from denoisebench.metrics import colorvideovdp as cv
from denoisebench.metrics import floors, gradient, robust, spatial, temporal
from denoisebench.metrics import msssim as ms
from denoisebench.metrics import noisebase as nb
from denoisebench.metrics import oidn_compare as oc

__all__ = [
    "Metric",
    "AGGREGATES",
    "METRIC_SETS",
    "get_metric",
    "metric_names",
    "default_metric_names",
    "expand_metric_names",
    "register_metric",
    "register_metric_set",
    "unregister_metric",
    "ALIASES",
]

Domain = Literal["linear", "tonemapped", "reinhard", "noisebase", "oidn"]
Kind = Literal["spatial", "gradient", "temporal"]
Aggregate = Literal["mean", "geomean", "relative_to_input"]
#: The aggregation rules a Metric may state (module docstring).
AGGREGATES = ("mean", "geomean", "relative_to_input")


@dataclass(frozen=True)
class Metric:
    """A named metric.

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


_REGISTRY: dict[str, Metric] = {}

ALIASES = {
    "rel_mse": "relmse",
    "mae": "l1",
    "hdr_flip": "flip",
    "hdrflip": "flip",
    "deltae": "deltae2000",
    "delta_e": "deltae2000",
    "de2000": "deltae2000",
    "ciede2000": "deltae2000",
    "gradient_l1": "grad_l1",
    "flicker": "temporal_relmse",  # the lead flicker score (scale-free); temporal_l1 is a linear diagnostic
    "temporal_l1_warp": "temporal_l1_warped",
    "t_psnr": "tpsnr",
    "trelmse": "temporal_relmse",
    "relmse_temporal": "temporal_relmse",
    "robust_relmse": "relmse_robust",
    "relmse_trimmed": "relmse_robust",
    "trimmed_relmse": "relmse_robust",
    "temporal_robust_relmse": "temporal_relmse_robust",
    "temporal_rel_mse": "temporal_relmse",
}


def register_metric(metric: Metric, *, replace: bool = False) -> Metric:
    """Add ``metric`` to the registry (``replace=True`` to override an existing name)."""
    if not isinstance(metric, Metric):
        raise ValueError(f"register_metric takes a Metric, got {type(metric).__name__}")
    if metric.name in ALIASES:
        raise ValueError(f"{metric.name!r} is an alias of {ALIASES[metric.name]!r}")
    if metric.name in _REGISTRY and not replace:
        raise ValueError(f"metric {metric.name!r} is already registered (pass replace=True)")
    _REGISTRY[metric.name] = metric
    return metric


def unregister_metric(name: str) -> None:
    """Remove a metric (plugins and tests undoing their registration)."""
    _REGISTRY.pop(name, None)


def get_metric(name: str) -> Metric:
    """The metric called ``name`` (case-insensitive; aliases such as ``"delta_e"`` accepted)."""
    key = str(name).strip().lower()
    key = ALIASES.get(key, key)
    try:
        return _REGISTRY[key]
    except KeyError:
        raise ValueError(f"unknown metric {name!r}; known: {', '.join(metric_names())}") from None


def metric_names(kind: str | None = None) -> list[str]:
    """Registered names in registration order, optionally only those of one ``kind``."""
    return [m.name for m in _REGISTRY.values() if kind is None or m.kind == kind]


#: Named sets a metrics option may name besides single metrics (``--metrics noisebase``, ``--metrics oidn``).
METRIC_SETS: dict[str, tuple[str, ...]] = {}
_OPT_IN: set[str] = set()


def register_metric_set(name: str, members, *, opt_in: bool = False) -> None:
    """Name a set of registered metrics. ``opt_in=True``: its members are left out of the
    default selection ("every registered metric") and run only when asked for, by name or set."""
    key = str(name).strip().lower()
    if key in _REGISTRY or key in ALIASES:
        raise ValueError(f"metric set {name!r} would hide the metric of that name")
    members = tuple(get_metric(m).name for m in members)
    METRIC_SETS[key] = members
    if opt_in:
        _OPT_IN.update(members)


def default_metric_names(kind: str | None = None) -> list[str]:
    """The default selection: registered metrics (of ``kind``) except the opt-in sets' members."""
    return [n for n in metric_names(kind) if n not in _OPT_IN]


def expand_metric_names(names) -> list[str]:
    """Canonical metric names of ``names`` (metrics, aliases or set names), duplicates dropped.

    An unknown name is a ``ValueError`` that lists the metrics and the sets.
    """
    out: list[str] = []
    for name in [names] if isinstance(names, str) else names:
        key = str(name).strip().lower()
        if key in METRIC_SETS and key not in _REGISTRY:
            out.extend(METRIC_SETS[key])
            continue
        try:
            out.append(get_metric(key).name)
        except ValueError:
            sets = f"; sets: {', '.join(METRIC_SETS)}" if METRIC_SETS else ""
            raise ValueError(f"unknown metric {name!r}; known: {', '.join(metric_names())}{sets}") from None
    return list(dict.fromkeys(out))


def _builtin() -> None:
    inf = math.inf
    s, g, t = spatial, gradient, temporal
    f = floors
    rel, geo = "relative_to_input", "geomean"
    for m in (
        Metric(
            "mse",
            s.mse,
            False,
            "linear",
            "spatial",
            s.WORST["mse"],
            0.0,
            s.mse_map,
            "mean squared error",
            aggregate=geo,
            floor_fn=f.mse_floor,
        ),
        Metric(
            "relmse",
            s.relmse,
            False,
            "linear",
            "spatial",
            s.WORST["relmse"],
            0.0,
            s.relmse_map,
            "mean((p-r)^2 / (r^2 + 0.01))",
            floor_fn=f.relmse_floor,
        ),
        Metric(
            "smape",
            s.smape,
            False,
            "linear",
            "spatial",
            s.WORST["smape"],
            0.0,
            s.smape_map,
            "mean(|p-r| / (|p| + |r| + 0.01))",
        ),
        Metric(
            "l1", s.l1, False, "linear", "spatial", s.WORST["l1"], 0.0, s.l1_map, "mean absolute error", aggregate=geo
        ),
        Metric(
            "psnr",
            s.psnr,
            True,
            "tonemapped",
            "spatial",
            s.WORST["psnr"],
            inf,
            None,
            "PSNR of tone-mapped images, peak 1",
            "dB",
        ),
        Metric(
            "ssim",
            s.ssim,
            True,
            "tonemapped",
            "spatial",
            s.WORST["ssim"],
            1.0,
            s.ssim_map,
            "SSIM (scikit-image, Gaussian sigma 1.5, data_range 1)",
        ),
        Metric(
            "flip", s.flip, False, "linear", "spatial", s.WORST["flip"], 0.0, s.flip_map, "HDR-FLIP (flip-evaluator)"
        ),
        Metric(
            "deltae2000",
            s.deltae2000,
            False,
            "reinhard",
            "spatial",
            s.WORST["deltae2000"],
            0.0,
            s.deltae2000_map,
            "CIEDE2000 (colour-science) of Reinhard-mapped linear sRGB",
        ),
        Metric(
            "grad_l1",
            g.grad_l1,
            False,
            "linear",
            "gradient",
            g.WORST["grad_l1"],
            0.0,
            g.grad_l1_map,
            "mean |grad p - grad r| (forward differences)",
            aggregate=rel,
        ),
        Metric(
            "hfen",
            g.hfen,
            False,
            "linear",
            "gradient",
            g.WORST["hfen"],
            0.0,
            g.hfen_map,
            "rms(LoG(p) - LoG(r)) / (rms(LoG(r)) + 0.01), LoG sigma 1.5",
            aggregate=rel,
        ),
        Metric(
            "temporal_l1",
            t.temporal_l1,
            False,
            "linear",
            "temporal",
            t.WORST["temporal_l1"],
            0.0,
            t.temporal_l1_map,
            "mean |(p_t - p_t-1) - (r_t - r_t-1)|",
            accepts=("masks",),
            aggregate=rel,
        ),
        Metric(
            "temporal_l1_warped",
            t.temporal_l1_warped,
            False,
            "linear",
            "temporal",
            t.WORST["temporal_l1_warped"],
            0.0,
            t.temporal_l1_warped_map,
            "temporal_l1 with frame t-1 warped by the motion buffer, disocclusions masked",
            accepts=("motion", "depth", "masks"),
            requires=("motion",),
            aggregate=rel,
        ),
        Metric(
            "temporal_relmse",
            t.temporal_relmse,
            False,
            "linear",
            "temporal",
            t.WORST["temporal_relmse"],
            0.0,
            t.temporal_relmse_map,
            "mean((dp - dr)^2 / (m^2 + 0.01)), warped frame differences, m = 3x3 mean |r_t|",
            accepts=("motion", "depth", "masks"),
            floor_fn=t.temporal_relmse_floor,
        ),
        Metric(
            "tpsnr",
            t.tpsnr,
            True,
            "tonemapped",
            "temporal",
            t.WORST["tpsnr"],
            inf,
            None,
            "PSNR of tone-mapped frame differences, peak 1",
            "dB",
            accepts=("masks",),
        ),
        # The robust (trimmed) scores that lead the report (issue 29): robust.py.
        Metric(
            "relmse_robust",
            robust.relmse_robust,
            False,
            "linear",
            "spatial",
            robust.WORST["relmse_robust"],
            0.0,
            robust.relmse_robust_map,
            "relMSE without the highest 0.1 % of per-pixel errors (--trim; robust.py)",
            accepts=("trim",),
            floor_fn=robust.relmse_robust_floor,
        ),
        Metric(
            "temporal_relmse_robust",
            robust.temporal_relmse_robust,
            False,
            "linear",
            "temporal",
            robust.WORST["temporal_relmse_robust"],
            0.0,
            robust.temporal_relmse_robust_map,
            "temporal_relmse without each pair's highest 0.1 % of per-pixel values (--trim; robust.py)",
            accepts=("motion", "depth", "masks", "trim"),
            floor_fn=robust.temporal_relmse_robust_floor,
        ),
        # Scores comparable with the field (issues 20, 32): msssim.py, colorvideovdp.py, noisebase.py,
        # oidn_compare.py.
        Metric(
            "msssim",
            ms.msssim,
            True,
            "tonemapped",
            "spatial",
            ms.WORST,
            1.0,
            None,
            "MS-SSIM (pytorch-msssim, win 11, sigma 1.5, data_range 1); fewer scales below 161 px",
        ),
        Metric(
            "cvvdp",
            cv.cvvdp,
            True,
            "linear",
            "temporal",
            cv.WORST,
            10.0,
            None,
            "ColorVideoVDP (cvvdp) at 30 fps: " + cv.DISPLAY_DESCRIPTION,
            "JOD",
        ),
        Metric(
            "nb_psnr",
            nb.nb_psnr,
            True,
            "noisebase",
            "spatial",
            nb.WORST["nb_psnr"],
            inf,
            None,
            "Noisebase PSNR: 8-bit ACES (gamma 2.2, truncated) frames, peak 1",
            "dB",
        ),
        Metric(
            "nb_ssim",
            nb.nb_ssim,
            True,
            "noisebase",
            "spatial",
            nb.WORST["nb_ssim"],
            1.0,
            None,
            "Noisebase SSIM (pytorch-msssim) of the 8-bit frames' luminance",
        ),
        Metric(
            "nb_msssim",
            nb.nb_msssim,
            True,
            "noisebase",
            "spatial",
            nb.WORST["nb_msssim"],
            1.0,
            None,
            "Noisebase MS-SSIM (pytorch-msssim) of the 8-bit frames' luminance",
        ),
        Metric(
            "nb_flip",
            nb.nb_flip,
            False,
            "noisebase",
            "spatial",
            nb.WORST["nb_flip"],
            0.0,
            None,
            "Noisebase LDR-FLIP of the 8-bit frames at 67.02 ppd",
        ),
        Metric(
            "nb_tpsnr",
            nb.nb_tpsnr,
            True,
            "noisebase",
            "temporal",
            nb.WORST["nb_tpsnr"],
            inf,
            None,
            "Noisebase tPSNR: mean over pairs of PSNR of 8-bit frame differences",
            "dB",
        ),
        Metric(
            "nb_trmae",
            nb.nb_trmae,
            False,
            "noisebase",
            "temporal",
            nb.WORST["nb_trmae"],
            0.0,
            None,
            "Noisebase tRMAE: mean over pairs of mean(|dp-dr|/(|dr|+0.01))/3 of 8-bit frames",
        ),
        Metric(
            "oidn_psnr",
            oc.oidn_psnr,
            True,
            "oidn",
            "spatial",
            oc.WORST["oidn_psnr"],
            inf,
            None,
            "OIDN compare_image.py PSNR: Hable filmic + sRGB of max(x, 0), peak 1",
            "dB",
        ),
        Metric(
            "oidn_ssim",
            oc.oidn_ssim,
            True,
            "oidn",
            "spatial",
            oc.WORST["oidn_ssim"],
            1.0,
            None,
            "OIDN compare_image.py SSIM (win 11, sigma 1.5, data_range 1) of the Hable + sRGB images, mean of R, G, B",
        ),
    ):
        register_metric(m)
    register_metric_set("noisebase", nb.NOISEBASE_METRICS, opt_in=True)
    register_metric_set("oidn", oc.OIDN_METRICS, opt_in=True)


_builtin()
