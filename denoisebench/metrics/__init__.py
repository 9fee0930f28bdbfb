"""Metrics of denoised images against references: pure functions over numpy arrays.

Grouped by concern (docs/architecture.md, section "Metrics", is the contract):

* here: the machinery: the ``Metric`` entry (``metric``), a registry by name (``registry``),
  ``compute_metrics`` for a chosen set on a frame or a sequence (``compute``), input checks and the
  non-finite policy (``validation``), the one tone map (``tonemap``), cost (``cost``);
* ``ours/``: our own scores (``spatial``, ``gradient``, ``temporal``, ``robust``);
* ``field/``: the field's scores as their authors compute them (``noisebase``, ``oidn_compare``,
  ``colorvideovdp``, ``msssim``);
* ``floors/``: what the reference's noise adds to a score (``closed_form``, ``half_reference``).

**The one place of re-exports.** The public names below (``__all__``) are re-exported here and only
here; the subpackages re-export nothing. This package imports nothing else of denoisebench; bad input
raises ``ValueError``.
"""

from denoisebench.metrics import tonemap  # the module: tonemap.tonemap(x), tonemap.reinhard(x), tonemap.srgb_oetf(y)
from denoisebench.metrics.compute import MetricResult, compute_metrics
from denoisebench.metrics.cost import (
    CallCost,
    CostSummary,
    measure_call,
    megapixels,
    seconds_per_megapixel,
    summarize_costs,
    total_seconds,
)
from denoisebench.metrics.floors.closed_form import Floor, mse_floor, relmse_floor
from denoisebench.metrics.ours.gradient import grad_l1, grad_l1_map, hfen, hfen_map
from denoisebench.metrics.ours.spatial import (
    deltae2000,
    deltae2000_map,
    flip,
    flip_map,
    l1,
    l1_map,
    mse,
    mse_map,
    psnr,
    relmse,
    relmse_map,
    smape,
    smape_map,
    ssim,
    ssim_map,
)
from denoisebench.metrics.ours.temporal import (
    disocclusion_mask,
    temporal_l1,
    temporal_l1_map,
    temporal_l1_warped,
    temporal_l1_warped_map,
    temporal_relmse,
    temporal_relmse_floor,
    temporal_relmse_map,
    tpsnr,
    warp_previous,
    warped_valid_masks,
)
from denoisebench.metrics.registry import Metric, get_metric, metric_names, register_metric, unregister_metric

__all__ = [
    "MetricResult",
    "compute_metrics",
    "CallCost",
    "CostSummary",
    "measure_call",
    "megapixels",
    "seconds_per_megapixel",
    "summarize_costs",
    "total_seconds",
    "Floor",
    "mse_floor",
    "relmse_floor",
    "grad_l1",
    "grad_l1_map",
    "hfen",
    "hfen_map",
    "Metric",
    "get_metric",
    "metric_names",
    "register_metric",
    "unregister_metric",
    "deltae2000",
    "deltae2000_map",
    "flip",
    "flip_map",
    "l1",
    "l1_map",
    "mse",
    "mse_map",
    "psnr",
    "relmse",
    "relmse_map",
    "smape",
    "smape_map",
    "ssim",
    "ssim_map",
    "disocclusion_mask",
    "temporal_l1",
    "temporal_l1_map",
    "temporal_l1_warped",
    "temporal_l1_warped_map",
    "temporal_relmse",
    "temporal_relmse_floor",
    "temporal_relmse_map",
    "tpsnr",
    "warp_previous",
    "warped_valid_masks",
    "tonemap",
]
