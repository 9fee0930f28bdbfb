"""MS-SSIM (multi-scale SSIM, Wang, Simoncelli & Bovik 2003) from ``pytorch-msssim``.

``msssim(pred, ref)``: H×W×3 linear radiance, both tone-mapped with the project's one tone map
(:func:`denoisebench.metrics.tonemap.tonemap`, values in [0, 1)), then
``pytorch_msssim.ms_ssim(X, Y, data_range=1, win_size=11, win_sigma=1.5, K=(0.01, 0.03))`` on
the three channels (the library averages the channels). Higher is better, 1 = identical;
a prediction with NaN/Inf scores 0 (the library clamps each scale's term at 0 with a ReLU, so
MS-SSIM lies in [0, 1]).

Small images (the pitfall of MS-SSIM on our 16–128 px data)
-----------------------------------------------------------
The standard five scales halve the image four times and the library *asserts* that the
smaller side exceeds ``(win_size − 1) · 2⁴ = 160`` px, so that the 11-tap window still fits at
the coarsest scale. Our images are often 16–128 px. We neither pad nor upsample (both invent
structure the window then measures). Instead we use **fewer scales**: the largest ``n ≤ 5``
with ``smaller side > 10 · 2^(n−1)`` (the library's own condition generalised to n scales),
with the first ``n`` of the standard weights (0.0448, 0.2856, 0.3001, 0.2363, 0.1333)
renormalised to sum to 1, and the same per-scale terms as the library (contrast-structure at
every scale but the last, full SSIM at the last, each clamped at 0, combined as a weighted
product). So: ≥ 161 px → the library's five-scale MS-SSIM exactly; 81–160 px → 4 scales;
41–80 → 3; 21–40 → 2; 11–20 → 1 (plain Gaussian SSIM of pytorch-msssim); < 11 px →
``ValueError``. ``msssim_scales(h, w)`` says which. Values over fewer scales are not
comparable with five-scale values of other papers; reports compare denoisers on the same data.
"""

from __future__ import annotations

import numpy as np

from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.tonemap import tonemap
from denoisebench.metrics.torch_threads import one_torch_thread
from denoisebench.metrics.validation import MetricNotApplicable, check_pair

# Lazy imports: torch (1 s) and pytorch-msssim are imported when MS-SSIM is computed, so that
# the metric registry stays cheap to import.

__all__ = ["WEIGHTS", "WIN_SIZE", "WIN_SIGMA", "METRICS", "WORST", "msssim", "msssim_scales", "ms_ssim_tensor"]

WEIGHTS = (0.0448, 0.2856, 0.3001, 0.2363, 0.1333)
WIN_SIZE = 11
WIN_SIGMA = 1.5


def msssim_scales(height: int, width: int, win_size: int = WIN_SIZE) -> int:
    """Number of scales used for an image of this size (module Notes); ValueError below win_size."""
    side = min(int(height), int(width))
    if side < win_size:
        raise MetricNotApplicable(f"MS-SSIM needs images of at least {win_size}×{win_size} px, got {height}×{width}")
    n = 1
    while n < len(WEIGHTS) and side > (win_size - 1) * 2**n:
        n += 1
    return n


def ms_ssim_tensor(x, y, data_range: float = 1.0, scales: int | None = None):
    """MS-SSIM of N×C×H×W float tensors with the scale count of :func:`msssim_scales` (a tensor).

    Five scales call ``pytorch_msssim.ms_ssim`` itself; fewer reuse the library's per-scale
    ``_ssim`` and window, and combine them exactly as ``ms_ssim`` does. ``scales`` forces our
    loop with that many scales (at most what the size allows; tests compare it with the library).
    """
    import torch
    import torch.nn.functional as F
    from pytorch_msssim import ms_ssim
    from pytorch_msssim.ssim import _fspecial_gauss_1d, _ssim

    n = msssim_scales(x.shape[-2], x.shape[-1])
    if scales is not None:
        if not 1 <= scales <= n:
            raise ValueError(f"{x.shape[-2]}×{x.shape[-1]} px allows 1..{n} scales, asked {scales}")
        n = scales
    elif n == len(WEIGHTS):
        return ms_ssim(x, y, data_range=data_range, win_size=WIN_SIZE, win_sigma=WIN_SIGMA)
    weights = x.new_tensor(WEIGHTS[:n])
    if n < len(WEIGHTS):  # the standard five sum to 1.0001; kept as the library has them
        weights = weights / weights.sum()
    win = _fspecial_gauss_1d(WIN_SIZE, WIN_SIGMA).repeat([x.shape[1], 1, 1, 1])
    mcs = []
    for i in range(n):
        ssim_per_channel, cs = _ssim(x, y, data_range=data_range, win=win, size_average=False)
        if i < n - 1:
            mcs.append(torch.relu(cs))
            padding = [s % 2 for s in x.shape[2:]]
            x = F.avg_pool2d(x, kernel_size=2, padding=padding)
            y = F.avg_pool2d(y, kernel_size=2, padding=padding)
    stacked = torch.stack(mcs + [torch.relu(ssim_per_channel)], dim=0)
    return torch.prod(stacked ** weights.view(-1, 1, 1), dim=0).mean()


def _nchw(a: np.ndarray):
    import torch

    return torch.from_numpy(np.ascontiguousarray(np.moveaxis(a, -1, 0)[None], dtype=np.float32))


def msssim(pred, ref) -> float:
    """MS-SSIM of the tone-mapped images (pytorch-msssim, fewer scales below 161 px). Higher is better."""
    c = check_pair(pred, ref)
    msssim_scales(*c.ref.shape[:2])
    if c.nonfinite_count:
        return WORST["msssim"]
    import torch

    with one_torch_thread(), torch.no_grad():
        return float(ms_ssim_tensor(_nchw(tonemap(c.pred)), _nchw(tonemap(c.ref))))


METRICS: tuple[Metric, ...] = (
    Metric(
        name="msssim",
        fn=msssim,
        higher_is_better=True,
        domain="tonemapped",
        kind="spatial",
        worst=0.0,  # each scale's term is clamped at 0: MS-SSIM lies in [0, 1]
        perfect=1.0,
        description="MS-SSIM (pytorch-msssim, win 11, sigma 1.5, data_range 1); fewer scales below 161 px",
    ),
)

#: Worst value, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
