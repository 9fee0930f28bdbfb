"""LBF: the learning-based filter of Kalantari, Bako & Sen 2015, "A Machine Learning Approach for
Filtering Monte Carlo Noise" (SIGGRAPH 2015): a multi-layer perceptron reads per-pixel feature
statistics and predicts the bandwidths of a cross-bilateral filter for that pixel; the filter is
applied differentiably, so the MLP trains end to end on the *filtered* image (the lecture's
"Multi-layer Perceptron → filter weights" slides).

Filter (the lecture's d_ij, one weight per pixel j in the (2R+1)² window of pixel i)::

    d_ij = exp(−‖p_i − p_j‖² / 2α_i²) · exp(−D(c_i, c_j) / 2β_i²) · Π_k exp(−D_k(f_ik, f_jk) / 2γ_k,i²)
    out_i = Σ_j d_ij c_j / Σ_j d_ij

* p: pixel coordinates; c: colour, compared as log(1 + c) (HDR: a firefly must not make every
  neighbour "different" by a factor of 10⁶), filtered as linear radiance (so energy is kept);
* features k: albedo (3), shading normal (3), log(1 + depth) relative to the image's median (1);
* D and D_k are squared Euclidean distances; the colour distance is divided by
  (COLOR_VAR_EPS + var_i + var_j) of the log colour (delta method from ``color_var``), so β is in
  units of the noise the pixel pair carries: a noisy pair is allowed to differ more. With
  ``var_median`` that variance is first replaced by its 3×3 median: at 2 spp a pixel's own
  variance estimate is itself very noisy (often 0 when both samples agree). A frame whose
  ``color_var`` is all zero (1 spp, or none given) gets a robust spatial estimate instead
  (:func:`spread_variance`); the shipped weights were trained at 2-8 spp and still filter 1-spp
  frames less well than cross_bilateral (``make demo``, 1 spp: relMSE 0.666 against 0.121).
* ``demodulate``: colour (and its variance) is divided by albedo + ε before filtering and
  multiplied back after (:func:`~denoisebench.models.features.albedo_factor`: emitters, background
  and black materials are left as they are), so texture detail is not blurred away with the noise.

MLP inputs ("secondary features", the paper's kinds, scaled down): for every primary channel
(log colour 3, albedo 3, normal 3, relative log depth 1) its mean and standard deviation over
square blocks of each size in ``blocks``; per feature group the Sobel gradient magnitude and the
mean absolute deviation over 3×3; the median absolute deviation of log luminance over 3×3; and
the log of the pixel's colour variance (our stand-in for the paper's sample count: it falls as
1/spp). The MLP is a per-pixel network (1×1 convolutions, ``hidden`` sigmoid units per layer, as
the paper's perceptron) with Xavier-initialised weights; its outputs pass through softplus and
are read as *precisions* 1/(2σ²), so every bandwidth is positive and finite by construction
(σ = (2·precision)^−½; :meth:`LBF.bandwidths` returns α, β, γ in those units).

Notes
-----
* Stability: the centre pixel's weight is exactly 1 (all distances 0) and every other weight is
  in [0, 1], so the normaliser is ≥ 1; the output is a convex combination of the (exposure
  normalised, firefly-clamped: :func:`~denoisebench.models.features.normalize_radiance`) input
  colours and can never overflow, go negative or be NaN. A black frame stays black.
* Window: applied as (2R+1)² shifted views of a replicate-padded image, accumulating numerator and
  normaliser (no N×C·(2R+1)²×H×W unfold tensor), so any image size works, 1×1 included. While
  autograd records, each shift keeps its own small intermediates; crops of 32–64 px are cheap.
* Initialisation: the output biases start at α = 2 px, β = 1 (noise units) and γ = 0.2 for
  every feature, a sensible hand-tuned cross-bilateral filter; training moves them per pixel.
* Deviation from the paper (stated, scaled for a CPU): a small window and block sizes, our
  buffers for its primary features (no second-bounce texture or direct-visibility buffers in
  this data), colour variance for the sample count; the paper's loss (relative MSE) is the
  default training loss (``denoisebench train --model lbf`` uses ``--loss relmse``).
"""

from __future__ import annotations

import math

import torch
from torch import nn
from torch.nn import functional as F

from denoisebench.models.features import _get, albedo_factor, normalize_radiance, safe, to_log

#: Floor of the colour distance's noise normaliser (log-colour variance units).
COLOR_VAR_EPS = 1e-3
#: Feature names of the γ_k outputs, in output order after α and β.
FEATURES = ("albedo", "normal", "depth")
#: Initial bandwidths: α (pixels), β (noise units), γ per feature.
INIT_BANDWIDTHS = {"alpha": 2.0, "beta": 1.0, "gamma": 0.2}

CONFIGS = {
    # 11×11 window; statistics over 3×3 and 7×7 blocks; one hidden layer of 10 sigmoid units. A
    # 15×15 window with the median-smoothed variance (var_median), trained alike (1200 steps on
    # the card's data), scored worse on the val split: relMSE 0.195 against this form's 0.159; so
    # did this form with demodulate (0.172), with 32 hidden units (0.194) and with a 3×3 box-mean
    # colour guide (31.5: the filter stopped filtering).
    "small": {"radius": 5, "hidden": [10], "blocks": [3, 7]},
    # Our reading of the paper's scale: a 55×55 filter window, statistics up to 55×55 blocks,
    # one hidden layer of 10 units. Slow on a CPU.
    "paper": {"radius": 27, "hidden": [10], "blocks": [7, 21, 55]},
}

_PRIMARY_CHANNELS = 10  # log colour 3, albedo 3, normal 3, relative log depth 1
_GROUPS = ((0, 3), (3, 6), (6, 9), (9, 10))  # colour, albedo, normal, depth


def input_channels(blocks: list[int]) -> int:
    """MLP inputs: block mean and std per primary channel and block, 2 per group, MAD, variance."""
    return 2 * _PRIMARY_CHANNELS * len(blocks) + 2 * len(_GROUPS) + 1 + 1


def _box(x: torch.Tensor, size: int) -> torch.Tensor:
    """Mean over size×size blocks centred on each pixel (replicated borders, any image size)."""
    half = size // 2
    return F.avg_pool2d(F.pad(x, (half, half, half, half), mode="replicate"), size, stride=1)


def _neighbours(x: torch.Tensor) -> torch.Tensor:
    """N×C×9×H×W: the 3×3 neighbourhood of each pixel (replicated borders)."""
    height, width = x.shape[-2:]
    padded = F.pad(x, (1, 1, 1, 1), mode="replicate")
    return torch.stack([padded[..., dy : dy + height, dx : dx + width] for dy in range(3) for dx in range(3)], dim=2)


def _sobel_magnitude(x: torch.Tensor) -> torch.Tensor:
    """Gradient magnitude (Sobel, summed over channels): N×1×H×W."""
    n = _neighbours(x)  # order: (dy, dx) row-major over 3×3
    gx = (n[:, :, 2] + 2 * n[:, :, 5] + n[:, :, 8]) - (n[:, :, 0] + 2 * n[:, :, 3] + n[:, :, 6])
    gy = (n[:, :, 6] + 2 * n[:, :, 7] + n[:, :, 8]) - (n[:, :, 0] + 2 * n[:, :, 1] + n[:, :, 2])
    return torch.sqrt((gx * gx + gy * gy).sum(dim=1, keepdim=True) + 1e-12)


def _median3x3(x: torch.Tensor) -> torch.Tensor:
    return _neighbours(x).median(dim=2).values


def spread_variance(color: torch.Tensor) -> torch.Tensor:
    """A variance of the mean colour where the frame has none (1 spp: a single sample has no spread):
    (1.4826 · median of |c − median3×3(c)|)², the median taken by two 3×3 passes (5×5 wide). The
    cross-bilateral baseline's rule (there with one 5×5 median); robust, so a firefly does not raise its
    neighbours' variance. Without it the MLP, trained at 2-8 spp, read "noise-free" at 1 spp and barely
    filtered (``make demo``, 1 spp: relMSE 1.12 against cross_bilateral's 0.121)."""
    deviation = (color - _median3x3(color)).abs()
    sigma = 1.4826 * _median3x3(_median3x3(deviation))
    return sigma * sigma


def primary_features(buffers: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The filter's inputs from exposure-normalised buffers (see the module docstring).

    Returns ``color`` (linear, filtered), ``log_color`` (compared), ``log_color_var`` (its
    variance by the delta method), ``albedo``, ``normal``, ``depth`` (log, relative to the image
    median) and ``stack`` (the 10 primary channels for the MLP's statistics).
    """
    color = buffers["color"]

    def get(name: str, channels: int) -> torch.Tensor:
        return _get(buffers, name, channels, color)

    log_color = to_log(color)
    # Var[log(1 + X)] ≈ Var[X] / (1 + X)², channel mean
    color_var = get("color_var", 3).clamp_min(0.0)
    unknown = color_var.flatten(1).amax(dim=1) <= 0.0  # no variance buffer, or 1 spp (all zero)
    if bool(unknown.any()):
        color_var = torch.where(unknown.view(-1, 1, 1, 1), spread_variance(color), color_var)
    log_color_var = (color_var / (1.0 + color) ** 2).mean(dim=1, keepdim=True)
    albedo = get("albedo", 3).clamp(0.0, 1.0)
    normal = get("normal", 3).clamp(-1.0, 1.0)
    depth = torch.log1p(get("depth", 1).clamp(0.0, 1e8))
    depth = depth - depth.flatten(1).median(dim=1).values.view(-1, 1, 1, 1)
    return {
        "color": color,
        "log_color": log_color,
        "log_color_var": log_color_var,
        "albedo": albedo,
        "normal": normal,
        "depth": depth,
        "stack": torch.cat([log_color, albedo, normal, depth], dim=1),
    }


def secondary_features(primary: dict[str, torch.Tensor], blocks: list[int]) -> torch.Tensor:
    """The MLP's per-pixel inputs, N×input_channels(blocks)×H×W (see the module docstring)."""
    stack = primary["stack"]
    parts = []
    for size in blocks:
        mean = _box(stack, size)
        var = (_box(stack * stack, size) - mean * mean).clamp_min(0.0)
        parts += [mean, torch.sqrt(var + 1e-8)]
    for start, stop in _GROUPS:
        group = stack[:, start:stop]
        parts.append(_sobel_magnitude(group))
        parts.append((_neighbours(group) - group.unsqueeze(2)).abs().mean(dim=(1, 2)).unsqueeze(1))
    luminance = stack[:, 0:3].mean(dim=1, keepdim=True)
    around = _neighbours(luminance)[:, 0]  # N×9×H×W
    median = around.median(dim=1, keepdim=True).values
    parts.append((around - median).abs().median(dim=1, keepdim=True).values)
    parts.append(torch.log(primary["log_color_var"] + 1e-8) / 10.0)
    return torch.cat(parts, dim=1)


def _softplus_inverse(y: float) -> float:
    return y + math.log(-math.expm1(-y))


def _precision(sigma: float) -> float:
    return 1.0 / (2.0 * sigma * sigma)


class LBF(nn.Module):
    """MLP-predicted cross-bilateral filter. ``forward(buffers)`` → ``{"color", "precisions"}``.

    ``precisions`` (N×(2+K)×H×W) are 1/(2σ²) for α, β, γ_albedo, γ_normal, γ_depth.
    """

    def __init__(
        self,
        radius: int = 5,
        hidden: list[int] | tuple[int, ...] = (10,),
        blocks: list[int] | tuple[int, ...] = (3, 7),
        var_median: bool = False,
        demodulate: bool = False,
    ):
        super().__init__()
        self.var_median = bool(var_median)
        self.demodulate = bool(demodulate)
        if radius < 1:
            raise ValueError(f"radius must be >= 1 (got {radius})")
        if not blocks or any(int(b) < 1 or int(b) % 2 == 0 for b in blocks):
            raise ValueError(f"blocks must be odd sizes >= 1 (got {blocks})")
        self.radius = int(radius)
        self.blocks = [int(b) for b in blocks]
        layers: list[nn.Module] = []
        width = input_channels(self.blocks)
        for units in hidden:
            layers += [nn.Conv2d(width, int(units), 1), nn.Sigmoid()]
            width = int(units)
        layers.append(nn.Conv2d(width, 2 + len(FEATURES), 1))
        self.mlp = nn.Sequential(*layers)
        with torch.no_grad():
            for module in self.mlp:
                if isinstance(module, nn.Conv2d):
                    nn.init.xavier_uniform_(module.weight)
                    module.bias.zero_()
            head = self.mlp[-1]
            head.weight.mul_(0.1)  # start close to the hand-tuned filter below
            starts = [INIT_BANDWIDTHS["alpha"], INIT_BANDWIDTHS["beta"]] + [INIT_BANDWIDTHS["gamma"]] * len(FEATURES)
            head.bias.copy_(torch.tensor([_softplus_inverse(_precision(s)) for s in starts]))

    def precisions(
        self, buffers: dict[str, torch.Tensor]
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor], torch.Tensor]:
        """(precisions, primary features, output scale) for raw buffers; with ``demodulate`` the scale
        is per pixel (exposure × albedo factor)."""
        buffers, scale = normalize_radiance(buffers)
        if self.demodulate:
            factor = albedo_factor(buffers, buffers["color"])
            buffers = dict(buffers)
            buffers["color"] = buffers["color"] / factor
            if "color_var" in buffers:
                buffers["color_var"] = safe(buffers["color_var"]).clamp_min(0.0) / factor**2
            scale = scale * factor
        primary = primary_features(buffers)
        if self.var_median:
            primary["log_color_var"] = _median3x3(primary["log_color_var"])
        inputs = secondary_features(primary, self.blocks)
        return F.softplus(self.mlp(inputs)), primary, scale

    def bandwidths(self, buffers: dict[str, torch.Tensor]) -> torch.Tensor:
        """α (pixels), β (noise units), γ_k per pixel: N×(2+K)×H×W, σ = (2·precision)^−½."""
        precisions, _, _ = self.precisions(buffers)
        return (2.0 * precisions).rsqrt()

    def forward(self, buffers: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        precisions, primary, scale = self.precisions(buffers)
        return {"color": filter_image(primary, precisions, self.radius) * scale, "precisions": precisions}


def filter_image(primary: dict[str, torch.Tensor], precisions: torch.Tensor, radius: int) -> torch.Tensor:
    """Σ_j d_ij c_j / Σ_j d_ij over the (2R+1)² window (module docstring), by shifted views."""
    height, width = primary["color"].shape[-2:]
    pad = (radius, radius, radius, radius)
    guides = [primary["log_color"], primary["albedo"], primary["normal"], primary["depth"]]
    padded_guides = [F.pad(g, pad, mode="replicate") for g in guides]
    padded_var = F.pad(primary["log_color_var"], pad, mode="replicate")
    padded_color = F.pad(primary["color"], pad, mode="replicate")
    alpha, beta = precisions[:, 0:1], precisions[:, 1:2]
    gammas = [precisions[:, 2 + k : 3 + k] for k in range(len(FEATURES))]
    var_i = primary["log_color_var"]
    numerator = torch.zeros_like(primary["color"])
    normaliser = torch.zeros_like(var_i)
    size = 2 * radius + 1
    if not (torch.is_grad_enabled() and precisions.requires_grad):
        return _filter_in_place(
            padded_guides, guides, padded_var, padded_color, alpha, beta, gammas, var_i, numerator, normaliser, radius
        )
    for dy in range(size):
        for dx in range(size):
            window = (slice(None), slice(None), slice(dy, dy + height), slice(dx, dx + width))
            r2 = float((dy - radius) ** 2 + (dx - radius) ** 2)
            colour = ((padded_guides[0][window] - guides[0]) ** 2).sum(dim=1, keepdim=True)
            colour = colour / (COLOR_VAR_EPS + var_i + padded_var[window])
            exponent = alpha * r2 + beta * colour
            for gamma, guide, padded in zip(gammas, guides[1:], padded_guides[1:]):
                exponent = exponent + gamma * ((padded[window] - guide) ** 2).sum(dim=1, keepdim=True)
            weight = torch.exp(-exponent)
            numerator = numerator + weight * padded_color[window]
            normaliser = normaliser + weight
    return numerator / normaliser


def _filter_in_place(
    padded_guides, guides, padded_var, padded_color, alpha, beta, gammas, var_i, numerator, normaliser, radius
):
    """:func:`filter_image`'s sums without autograd: the same arithmetic, buffers reused in place
    (inference; about half the time of the differentiable loop)."""
    height, width = var_i.shape[-2:]
    exponent = torch.empty_like(var_i)
    scratch = torch.empty_like(guides[0])
    single = torch.empty_like(var_i)
    size = 2 * radius + 1
    for dy in range(size):
        for dx in range(size):
            window = (slice(None), slice(None), slice(dy, dy + height), slice(dx, dx + width))
            r2 = float((dy - radius) ** 2 + (dx - radius) ** 2)
            torch.sub(padded_guides[0][window], guides[0], out=scratch).square_()
            torch.sum(scratch, dim=1, keepdim=True, out=exponent)
            torch.add(var_i, padded_var[window], out=single).add_(COLOR_VAR_EPS)
            exponent.div_(single).mul_(beta).add_(alpha, alpha=r2)
            for gamma, guide, padded in zip(gammas, guides[1:], padded_guides[1:]):
                difference = (padded[window] - guide).square_()
                torch.sum(difference, dim=1, keepdim=True, out=single)
                exponent.addcmul_(gamma, single)
            weight = exponent.neg_().exp_()
            numerator.addcmul_(weight, padded_color[window])
            normaliser.add_(weight)
    return numerator.div_(normaliser)


def make_lbf(
    radius: int = 5,
    hidden: list[int] | tuple[int, ...] = (10,),
    blocks: list[int] | tuple[int, ...] = (3, 7),
    var_median: bool = False,
    demodulate: bool = False,
) -> LBF:
    return LBF(radius, hidden, blocks, var_median, demodulate)
