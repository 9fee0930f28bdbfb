"""Metrics by name, so reports and plugins can ask for ``"relmse"``, ``"flip"``, ...

A :class:`~.metric.Metric` pairs the pure function with what a report needs to know about it
(:mod:`.metric`: the fields, the context keywords, the aggregation rules over scenes, floors).
The built-in entries are declared beside their functions, in each metric module's ``METRICS``
tuple; this module registers them in the order of :data:`BUILTIN_MODULES`, then the entries of
each module in their order, which is the order of :func:`metric_names`. Plugins add theirs with
:func:`register_metric`; ``ALIASES`` maps other spellings to the names, and named sets
(:func:`register_metric_set`) select several at once.
"""

from __future__ import annotations

from denoisebench.metrics.field import colorvideovdp, msssim, noisebase, oidn_compare
from denoisebench.metrics.metric import AGGREGATES, Metric
from denoisebench.metrics.ours import gradient, robust, spatial, temporal

__all__ = [
    "Metric",
    "AGGREGATES",
    "BUILTIN_MODULES",
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

#: The modules whose ``METRICS`` entries are registered, in registration order.
BUILTIN_MODULES = (spatial, gradient, temporal, robust, msssim, colorvideovdp, noisebase, oidn_compare)

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
    for module in BUILTIN_MODULES:
        for metric in module.METRICS:
            register_metric(metric)
    register_metric_set("noisebase", noisebase.NOISEBASE_METRICS, opt_in=True)
    register_metric_set("oidn", oidn_compare.OIDN_METRICS, opt_in=True)


_builtin()
