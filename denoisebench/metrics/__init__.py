"""Metrics of denoised images against references: pure functions over numpy arrays.

Spatial (``spatial``), gradient (``gradient``) and temporal (``temporal``) metrics, their cost
(``cost``), the one tone map (``tonemap``), input checks and the non-finite policy
(``validation``), a registry by name (``registry``) and ``compute_metrics`` for a chosen set on a
frame or a sequence. docs/architecture.md, section "Metrics", is the contract. This package imports nothing
else of denoisebench; bad input raises ``ValueError``.
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
from denoisebench.metrics.floors import Floor, mse_floor, relmse_floor
from denoisebench.metrics.gradient import grad_l1, grad_l1_map, hfen, hfen_map
from denoisebench.metrics.registry import Metric, get_metric, metric_names, register_metric, unregister_metric
from denoisebench.metrics.spatial import (
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
from denoisebench.metrics.temporal import (
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
