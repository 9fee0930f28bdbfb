"""Input preparation shared by the learned denoisers: buffers → network tensors and back.

Every model reads a dict of N×C×H×W float32 tensors keyed by buffer name (what
:class:`~denoisebench.dataset.torch_dataset.CropDataset` yields after batching, and what
:func:`frame_tensors` makes of a :class:`~denoisebench.dataset.frame.Frame`), plus the per-frame
scalars of FRAME_SCALARS as N×1×1×1 tensors: ``spp`` (the frame's sample count, when known) and
``exposure`` (set by a tiled wrapper). Pitfall: code that crops or tiles the dict must pass those
through whole.

Transforms (Bako et al. 2017, section 4.1):

* diffuse is demodulated by ``albedo + ALBEDO_EPS`` (ε = 0.00316, the paper's) and remodulated after,
  except where the albedo is below ALBEDO_MIN (emitters, background: see :func:`albedo_factor`);
* specular is taken as ``log(1 + x)`` and mapped back with ``exp(x) − 1``;
* each feature gets its x and y gradients, and each colour buffer its per-pixel variance, carried
  through the same transform by the delta method (Var f(X) ≈ f'(μ)² Var X).

Before any of this, :func:`normalize_radiance` divides the radiance buffers by the image's
exposure (a winsorised mean luminance, as OIDN's auto-exposure does) and caps isolated fireflies
at FIREFLY_FACTOR × their neighbours; the models multiply their output back by the exposure.
So the networks see the same range at any brightness (the 1e-6..1e6 case) and a black frame
gives exactly black.

Notes
-----
* The network always *sees* colour as ``log(1 + ·)``, the demodulated diffuse included: a
  demodulated firefly of 1e6 / ε ≈ 3e8 would otherwise saturate the first layer. KPCN's kernels
  still act on the demodulated (linear) diffuse and on the log specular, as in the paper.
* Inputs are made safe here as well as by the harness: NaN/Inf become 0 and colour is clamped to
  [0, COLOR_MAX], so a training batch with a bad pixel cannot poison the weights.
* Frames without ``diffuse``/``specular`` (a user's own data) are treated as all-diffuse; frames
  without a feature or a variance get zeros for it, the same at training and at inference.
"""

from __future__ import annotations

import numpy as np
import torch
from torch.nn import functional as F

ALBEDO_EPS = 0.00316
#: Below this mean albedo a pixel is an emitter, background or black material: not demodulated.
ALBEDO_MIN = 0.01
#: Largest radiance passed on; far above any real pixel, far below float32 overflow after the transforms.
COLOR_MAX = 1e8
#: log(1 + x) outputs are clamped to this before exp(): exp(30) ≈ 1e13 stays finite in float32.
LOG_MAX = 30.0

#: Keys of a model's input dict that hold one value per frame (N×1×1×1), not an image.
FRAME_SCALARS = ("spp", "exposure")
#: A pixel whose albedo and depth both read as a surface covering less than this fraction of it is
#: partly background (:func:`partly_background`).
COVER_MIN = 0.9

#: An isolated value above this multiple of its 8 neighbours' maximum is a firefly (the OIDN wrapper's rule).
FIREFLY_FACTOR = 16.0
#: The exposure is the mean luminance after clipping at this quantile (a winsorised mean).
EXPOSURE_QUANTILE = 0.99

#: Buffers the learned denoisers use when the frame has them (``color`` is the only one required).
OPTIONAL_BUFFERS = (
    "color_var",
    "diffuse",
    "diffuse_var",
    "specular",
    "specular_var",
    "albedo",
    "albedo_var",
    "normal",
    "normal_var",
    "depth",
    "depth_var",
    "roughness",
)
_CHANNELS = {"albedo": 3, "normal": 3, "depth": 1, "roughness": 1}


def safe(x: torch.Tensor, upper: float = COLOR_MAX) -> torch.Tensor:
    """``x`` with NaN/±Inf replaced by 0 and clamped to [−upper, upper]."""
    return torch.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0).clamp(-upper, upper)


def clamp_isolated(x: torch.Tensor, factor: float = FIREFLY_FACTOR) -> torch.Tensor:
    """Each value capped at ``factor`` × the largest of its 8 neighbours (same channel; edges replicate).

    A lone sample of 1e6 among pixels of 1 becomes 16; a bright region (neighbours as bright) is untouched.
    """
    height, width = x.shape[-2:]
    padded = F.pad(x, (1, 1, 1, 1), mode="replicate")
    ring = None
    for dy in range(3):
        for dx in range(3):
            if dy == 1 and dx == 1:
                continue
            shifted = padded[..., dy : dy + height, dx : dx + width]
            ring = shifted if ring is None else torch.maximum(ring, shifted)
    return torch.minimum(x, ring * factor)


def exposure(color: torch.Tensor) -> torch.Tensor:
    """N×1×1×1 scale of each image: mean luminance clipped at its 99th percentile, else its plain mean.

    0 only for an all-black image. Fireflies do not move it (they lie above the percentile).
    """
    lum = safe(color).clamp(0.0, COLOR_MAX).mean(dim=1).flatten(1).double()
    ceiling = torch.quantile(lum, EXPOSURE_QUANTILE, dim=1, keepdim=True)
    robust = torch.minimum(lum, ceiling).mean(dim=1)
    scale = torch.where(robust > 0, robust, lum.mean(dim=1))
    return scale.float().view(-1, 1, 1, 1)


def normalize_radiance(buffers: dict[str, torch.Tensor]) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
    """Radiance buffers divided by the exposure (variances by its square), isolated fireflies clamped.

    Returns (new buffers, output scale): multiply the network's radiance by the scale. The
    exposure comes from ``buffers["exposure"]`` when given (a tiled wrapper computes it once for
    the whole frame, so every tile sees the same scale), else from ``color``. The scale is 0 for a
    black frame, whose output is then exactly black.
    """
    scale = buffers.get("exposure")
    if scale is None:
        scale = exposure(buffers["color"])
    divisor = scale.clamp_min(1e-30)
    out = dict(buffers)
    for name in ("color", "diffuse", "specular"):
        if name in buffers:
            out[name] = clamp_isolated(safe(buffers[name]).clamp(0.0, COLOR_MAX)) / divisor
            if f"{name}_var" in buffers:
                out[f"{name}_var"] = safe(buffers[f"{name}_var"]).clamp(0.0, COLOR_MAX) / divisor**2
    return out, torch.where(scale > 0, divisor, torch.zeros_like(divisor))


def to_log(x: torch.Tensor) -> torch.Tensor:
    """log(1 + max(x, 0)): the HDR compression used for network inputs and losses."""
    return torch.log1p(safe(x).clamp_min(0.0))


def from_log(y: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`to_log` for network outputs, clamped to [0, LOG_MAX] so it never overflows.

    The clamp passes gradients straight through (its backward is the identity): with a plain
    clamp a network whose outputs once fall below 0 (the first steps of a relative loss push
    every dark pixel there) gets zero gradient everywhere and stays black for good.
    """
    clamped = y.clamp(0.0, LOG_MAX)
    return torch.expm1(y + (clamped - y).detach())


def gradients(x: torch.Tensor) -> torch.Tensor:
    """Forward differences along x and y (N×2C×H×W), zero in the last column/row."""
    dx = torch.zeros_like(x)
    dy = torch.zeros_like(x)
    dx[..., :, :-1] = x[..., :, 1:] - x[..., :, :-1]
    dy[..., :-1, :] = x[..., 1:, :] - x[..., :-1, :]
    return torch.cat([dx, dy], dim=1)


def _get(buffers: dict[str, torch.Tensor], name: str, channels: int, like: torch.Tensor) -> torch.Tensor:
    value = buffers.get(name)
    if value is None:
        return like.new_zeros(like.shape[0], channels, *like.shape[2:])
    return safe(value)


def _variance_channel(var: torch.Tensor) -> torch.Tensor:
    """Mean over channels, compressed: one N×1×H×W channel that spans 1e-12..1e12 gently."""
    return torch.log1p(safe(var).clamp_min(0.0).mean(dim=1, keepdim=True))


def feature_stack(buffers: dict[str, torch.Tensor], like: torch.Tensor, log_depth_var: bool = False) -> torch.Tensor:
    """Auxiliary features with their gradients and variances: N×24×H×W (albedo, normal, log depth; x and y gradients; 3 variances).

    ``log_depth_var``: carry ``depth_var`` through the depth's log(1 + d) by the delta method
    (Var ≈ var / (1 + d)²), as the colour variances are. Off for checkpoints made before (their
    weights saw the raw variance; the configuration records the choice).
    """
    albedo = _get(buffers, "albedo", 3, like).clamp(0.0, 1.0)
    raw_depth = _get(buffers, "depth", 1, like).clamp(0.0, COLOR_MAX)
    normal = _get(buffers, "normal", 3, like).clamp(-1.0, 1.0)
    depth = torch.log1p(raw_depth)
    aux = torch.cat([albedo, normal, depth], dim=1)
    variances = [
        _variance_channel(_get(buffers, f"{name}_var", _CHANNELS[name], like)) for name in ("albedo", "normal")
    ]
    depth_var = _get(buffers, "depth_var", _CHANNELS["depth"], like)
    if log_depth_var:
        depth_var = depth_var.clamp_min(0.0) / (1.0 + raw_depth) ** 2
    variances.append(_variance_channel(depth_var))
    return torch.cat([aux, gradients(aux)] + variances, dim=1)


FEATURE_CHANNELS = 24
#: Channels of one PCN branch input: colour (3), its gradients (6), its variance (1), features (21).
PCN_INPUT_CHANNELS = 3 + 6 + 1 + FEATURE_CHANNELS


def split_lobes(buffers: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(diffuse, diffuse_var, specular, specular_var), linear; all-diffuse when the frame has no split."""
    color = safe(buffers["color"]).clamp(0.0, COLOR_MAX)
    if "diffuse" in buffers and "specular" in buffers:
        diffuse = safe(buffers["diffuse"]).clamp(0.0, COLOR_MAX)
        specular = safe(buffers["specular"]).clamp(0.0, COLOR_MAX)
        diffuse_var = _get(buffers, "diffuse_var", 3, color)
        specular_var = _get(buffers, "specular_var", 3, color)
    else:
        diffuse, specular = color, torch.zeros_like(color)
        diffuse_var, specular_var = _get(buffers, "color_var", 3, color), torch.zeros_like(color)
    return diffuse, diffuse_var.clamp_min(0.0), specular, specular_var.clamp_min(0.0)


def dark_pixels(buffers: dict[str, torch.Tensor]) -> torch.Tensor | None:
    """N×1×H×W mask of the pixels :func:`albedo_factor` leaves undemodulated (mean albedo below
    ALBEDO_MIN: emitters, background, black materials); None without an albedo buffer."""
    albedo = buffers.get("albedo")
    if albedo is None:
        return None
    return safe(albedo).clamp(0.0, 1.0).mean(dim=1, keepdim=True) < ALBEDO_MIN


def covered_fraction(mean: torch.Tensor, var: torch.Tensor, spp: torch.Tensor) -> torch.Tensor:
    """The fraction of a pixel's samples that read a value ``a``, if each read either 0 or ``a``.

    With coverage c the samples' mean is c·a and their (population) variance a²·c·(1 − c), so
    c = mean² / (mean² + σ²). ``var`` is the variance of the mean the renderer writes (the unbiased
    sample variance ÷ n), so σ² = (n − 1)·var. A pixel with no evidence (mean and variance 0, or
    one sample) reads 1: fully covered.
    """
    sigma2 = (spp - 1.0).clamp_min(0.0) * safe(var).clamp_min(0.0)
    mean2 = safe(mean).square()
    total = mean2 + sigma2
    return torch.where(total > 0, mean2 / total.clamp_min(1e-30), torch.ones_like(total))


def partly_background(buffers: dict[str, torch.Tensor]) -> torch.Tensor | None:
    """N×1×H×W mask of the pixels a surface covers only in part, the rest being background or an
    emitter seen directly; None without ``spp``, albedo, depth and their variances.

    A sample that misses every surface reads albedo 0 and depth 0, so at a silhouette before the
    background both buffers are two-valued with the same coverage: :func:`covered_fraction` of the
    albedo (its three channels summed, their deviations added: the channels vary together) and of
    the depth both fall below COVER_MIN. Demodulation fails there: the pixel's radiance is mostly
    the background's, its albedo a fraction of the surface's, and their quotient (7× the lit wall's
    on Mitsuba's two-sided Cornell box, at albedo 0.12 of 0.49) spreads through the kernel taps
    that reach it, into the surface's own channels too. A texture edge (albedo varies, depth does
    not) and a depth edge between two surfaces (depth varies, albedo need not) read as covered.

    Pitfalls: at 1 spp there is no variance and no pixel is found (the rule is then today's
    without it); a black material before the background has no albedo evidence and is found
    only when its depth is, which is harmless (its diffuse is 0).
    """
    spp = buffers.get("spp")
    names = ("albedo", "albedo_var", "depth", "depth_var")
    if spp is None or any(name not in buffers for name in names):
        return None
    spp = safe(spp)
    albedo = safe(buffers["albedo"]).clamp(0.0, 1.0)
    albedo_sd = safe(buffers["albedo_var"]).clamp_min(0.0).sqrt().sum(dim=1, keepdim=True)
    albedo_cover = covered_fraction(albedo.sum(dim=1, keepdim=True), albedo_sd.square(), spp)
    depth_cover = covered_fraction(buffers["depth"][:, :1], buffers["depth_var"][:, :1], spp)
    return (albedo_cover < COVER_MIN) & (depth_cover < COVER_MIN) & ~dark_pixels(buffers)


def albedo_factor(buffers: dict[str, torch.Tensor], like: torch.Tensor) -> torch.Tensor:
    """albedo + ε, the demodulation divisor; 1 where the albedo is below ALBEDO_MIN or absent.

    Emitters and background pixels have albedo 0 but carry their emission in ``diffuse``:
    divided by ε a light of 20 becomes 6300, and any kernel weight that spills it onto a
    neighbour (remodulated by that neighbour's albedo) paints a bright halo. Those pixels are
    left undemodulated; so is a zero-albedo material, whose diffuse is 0 anyway.
    """
    albedo = buffers.get("albedo")
    if albedo is None:
        return torch.ones_like(like)
    albedo = safe(albedo).clamp(0.0, 1.0)
    return torch.where(dark_pixels(buffers), torch.ones_like(albedo), albedo + ALBEDO_EPS)


def pcn_inputs(buffers: dict[str, torch.Tensor], log_depth_var: bool = False) -> dict[str, torch.Tensor]:
    """Both branches' inputs for DPCN/KPCN.

    Returns ``diffuse_in``/``specular_in`` (N×PCN_INPUT_CHANNELS×H×W), ``diffuse_lin`` (demodulated
    diffuse, linear), ``specular_log`` (log(1 + specular)) and ``albedo_factor`` (albedo + ε).
    """
    diffuse, diffuse_var, specular, specular_var = split_lobes(buffers)
    factor = albedo_factor(buffers, diffuse)
    diffuse_lin = diffuse / factor
    diffuse_log = torch.log1p(diffuse_lin)
    specular_log = torch.log1p(specular)
    # Delta method: Var[log(1 + X / a)] ≈ Var[X] / (a (1 + X / a))² = Var[X] / (a + X)².
    diffuse_var_log = diffuse_var / (factor + diffuse) ** 2
    specular_var_log = specular_var / (1.0 + specular) ** 2
    features = feature_stack(buffers, diffuse, log_depth_var)
    diffuse_in = torch.cat([diffuse_log, gradients(diffuse_log), _variance_channel(diffuse_var_log), features], dim=1)
    specular_in = torch.cat(
        [specular_log, gradients(specular_log), _variance_channel(specular_var_log), features], dim=1
    )
    return {
        "diffuse_in": diffuse_in,
        "specular_in": specular_in,
        "diffuse_lin": diffuse_lin,
        "diffuse_log": diffuse_log,
        "specular_log": specular_log,
        "albedo_factor": factor,
    }


#: Input channels of the recurrent autoencoder: colour (3), normal (3), depth (1), roughness (1).
RAE_INPUT_CHANNELS = 8
#: With view-space normals (Chaitanya et al.'s 7 inputs): colour (3), normal x/y in view space (2), depth, roughness.
RAE_VIEW_INPUT_CHANNELS = 7


def camera_axes(position: torch.Tensor, depth: torch.Tensor, ridge: float = 1e-6) -> torch.Tensor:
    """Per image, the camera's right, down and forward unit vectors in world space: N×3×3 (rows).

    Found from the buffers alone (no camera record needed, crops and flips included): linear
    camera-space depth is z = f·P − f·O for every hit P, so a least-squares fit of z on [P, 1]
    gives the forward axis f; and a pinhole maps a hit to pixel x with x·z an affine function of
    P, so fitting x·z (and y·z) on [P, 1] gives a vector whose part orthogonal to f is the right
    (down) axis, whatever the field of view and wherever the crop lies in the frame. Misses
    (depth 0) are left out. An image with fewer than 4 hits or coplanar hits (one flat wall) has
    no unique fit: the ridge term then keeps the solve finite and an axis that comes out zero
    stays zero, so its view-space normal channels are 0 (as for a miss). Pixel y grows downward.
    """
    n, _, h, w = position.shape
    p = safe(position).double().flatten(2).transpose(1, 2)  # N×HW×3
    z = safe(depth).double().flatten(1)  # N×HW
    hit = (z > 0).double()
    count = hit.sum(dim=1).clamp_min(1.0)
    mean = (p * hit[..., None]).sum(dim=1) / count[:, None]
    centred = (p - mean[:, None]) * hit[..., None]
    scale = torch.sqrt((centred**2).sum(dim=(1, 2)) / count).clamp_min(1e-12)  # one scalar per image
    x = torch.cat([centred / scale[:, None, None], hit[..., None]], dim=2)  # N×HW×4, misses all zero
    gram = x.transpose(1, 2) @ x + ridge * torch.eye(4, dtype=x.dtype, device=x.device)
    ys, xs = torch.meshgrid(
        torch.arange(h, dtype=x.dtype, device=x.device), torch.arange(w, dtype=x.dtype, device=x.device), indexing="ij"
    )
    targets = torch.stack([z, xs.flatten()[None] * z, ys.flatten()[None] * z], dim=2) * hit[..., None]  # N×HW×3
    solution = torch.linalg.solve(gram, x.transpose(1, 2) @ targets)[:, :3]  # N×3(coeff)×3(target)
    forward = F.normalize(solution[..., 0], dim=1, eps=1e-12)
    right = solution[..., 1] - (solution[..., 1] * forward).sum(dim=1, keepdim=True) * forward
    right = F.normalize(right, dim=1, eps=1e-12)
    down = solution[..., 2] - (solution[..., 2] * forward).sum(dim=1, keepdim=True) * forward
    down = down - (down * right).sum(dim=1, keepdim=True) * right
    down = F.normalize(down, dim=1, eps=1e-12)
    axes = torch.stack([right, down, forward], dim=1)
    enough = (hit.sum(dim=1) >= 4).view(n, 1, 1)
    return torch.where(enough & torch.isfinite(axes), axes, torch.zeros_like(axes)).float()


def view_normals(buffers: dict[str, torch.Tensor], like: torch.Tensor) -> torch.Tensor:
    """N×2×H×W: the shading normal's right and down components in the camera's frame (:func:`camera_axes`).

    Zeros when the frame has no position or depth buffer, and at misses (normal 0 there).
    """
    if "position" not in buffers or "depth" not in buffers:
        return like.new_zeros(like.shape[0], 2, *like.shape[2:])
    axes = camera_axes(buffers["position"], buffers["depth"])[:, :2]  # N×2×3
    normal = _get(buffers, "normal", 3, like).clamp(-1.0, 1.0)
    return torch.einsum("nkc,nchw->nkhw", axes, normal)


def rae_inputs(
    buffers: dict[str, torch.Tensor], demodulate: bool, view_space: bool = False
) -> tuple[torch.Tensor, torch.Tensor]:
    """(network input, albedo factor or ones): log colour (demodulated if asked), normal, depth, roughness.

    N×8×H×W with the world-space normal (3); N×7×H×W with ``view_space`` (the paper's inputs: the
    normal's two view-space components, :func:`view_normals`).
    """
    color = safe(buffers["color"]).clamp(0.0, COLOR_MAX)
    factor = albedo_factor(buffers, color) if demodulate else torch.ones_like(color)
    if view_space:
        normal = view_normals(buffers, color)
    else:
        normal = _get(buffers, "normal", 3, color).clamp(-1.0, 1.0)
    depth = torch.log1p(_get(buffers, "depth", 1, color).clamp(0.0, COLOR_MAX))
    roughness = _get(buffers, "roughness", 1, color).clamp(0.0, 1.0)
    return torch.cat([torch.log1p(color / factor), normal, depth, roughness], dim=1), factor


def frame_tensors(frame, names=("color",) + OPTIONAL_BUFFERS + ("position",)) -> dict[str, torch.Tensor]:
    """The frame's buffers among ``names`` as 1×C×H×W float32 tensors (copies: frames are read-only),
    and its sample count as ``spp`` (1×1×1×1) when the frame knows it."""
    out = {}
    for name in names:
        if name in frame.buffers:
            array = np.asarray(frame.buffers[name], dtype=np.float32)
            out[name] = torch.from_numpy(np.ascontiguousarray(np.moveaxis(array, -1, 0)).copy())[None]
    if getattr(frame, "spp", 0) > 0:
        out["spp"] = torch.full((1, 1, 1, 1), float(frame.spp))
    return out


def to_image(tensor: torch.Tensor) -> np.ndarray:
    """1×3×H×W tensor → H×W×3 float32 numpy array, finite and non-negative."""
    image = safe(tensor.detach()[0]).clamp(0.0, COLOR_MAX)
    return np.ascontiguousarray(image.permute(1, 2, 0).numpy(), dtype=np.float32)
