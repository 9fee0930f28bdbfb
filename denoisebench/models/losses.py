"""Training losses (torch) for the learned denoisers, in the log(1 + x) domain unless stated.

* :func:`spatial_l1`: L_s, mean |log(1+p) − log(1+r)| (``--loss log``, the default); with
  ``--loss relative`` plus :func:`relative_l1`, mean |p−r|/(|r|+0.01): the log domain barely sees a
  dark pixel that is 10× too bright, which relMSE (the benchmark's figure) weighs heavily.
* :func:`gradient_l1`: L_g, HFEN-style: L1 between Laplacian-of-Gaussian responses (σ = 1.5,
  15×15, zero-sum: MATLAB's ``fspecial('log', 15, 1.5)``, the kernel ``denoisebench.metrics`` uses).
* :func:`temporal_l1`: L_t, mean |(p_t − p_{t−1}) − (r_t − r_{t−1})|.
* :func:`rae_sequence_loss`: Chaitanya et al.'s 0.8·L_s + 0.1·L_g + 0.1·L_t over a K-frame
  sequence with rising per-frame weights (:func:`frame_weights`).
* :func:`pcn_loss`: L1 on the combined colour plus L1 on each branch's log output against the
  reference lobes; ``lobes`` drops the colour term (Bako et al. train each branch on its own lobe);
  ``exposure`` is ``log`` in the network's own range (everything divided by the exposure the model
  normalised its input by, ``out["exposure"]``).
* :func:`relmse_loss`: relative MSE of linear radiance, LBF's training loss (Kalantari et al.).
* :func:`relmse`: the validation figure, mean((p−r)²/(r²+0.01)) as docs/architecture.md defines it (linear).

Notes
-----
* The log domain keeps a firefly of 1e6 from dominating a batch and keeps gradients finite;
  every input is passed through :func:`~denoisebench.models.features.safe` first, so NaN/Inf in a
  reference cannot reach the optimiser.
* The LoG convolution pads by replication: a flat border then has zero response, as it should.
* ``log`` is not scale-invariant: below radiance 1, log(1 + x) ≈ x, so a scene of radiance 0.01 gives
  a hundredth of the gradient of a scene of radiance 1 and a direct predictor (DPCN) is hardly
  trained on dark scenes; on the 40-scene full-transport set DPCN then missed each scene by a
  factor of its own (val relMSE 1820). ``exposure`` compares log(1 + x / exposure), the range the
  network sees, so every frame counts alike whatever its brightness. KPCN's output is a convex
  combination of its input and cannot miss the scale.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch.nn import functional as F

from denoisebench.models.features import safe, to_log

LOSS_WEIGHTS = {"spatial": 0.8, "gradient": 0.1, "temporal": 0.1}
RELMSE_EPS = 0.01


def log_kernel(sigma: float = 1.5, size: int = 15) -> torch.Tensor:
    """Zero-sum Laplacian of Gaussian (fspecial('log')), size×size float32."""
    half = (size - 1) / 2.0
    y, x = np.mgrid[-half : half + 1, -half : half + 1]
    r2 = x * x + y * y
    gauss = np.exp(-r2 / (2.0 * sigma * sigma))
    gauss /= gauss.sum()
    kernel = gauss * (r2 - 2.0 * sigma * sigma) / sigma**4
    kernel -= kernel.mean()
    return torch.from_numpy(kernel.astype(np.float32))


_LOG_KERNEL = log_kernel()


def laplacian_of_gaussian(x: torch.Tensor) -> torch.Tensor:
    """Per-channel LoG response of N×C×H×W ``x`` (same size, replicate padding)."""
    channels = x.shape[1]
    kernel = _LOG_KERNEL.to(x).expand(channels, 1, *_LOG_KERNEL.shape)  # x's dtype and device
    pad = _LOG_KERNEL.shape[-1] // 2
    padded = F.pad(x, (pad, pad, pad, pad), mode="replicate")
    return F.conv2d(padded, kernel, groups=channels)


def spatial_l1(pred: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    return (to_log(pred) - to_log(ref)).abs().mean()


def relative_l1(pred: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """mean(|p − r| / (|r| + 0.01)), linear: relMSE's weighting at first power, so dark pixels count."""
    pred, ref = safe(pred), safe(ref)
    return ((pred - ref).abs() / (ref.abs() + RELMSE_EPS)).mean()


def relmse_loss(pred: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """mean((p − r)² / (r² + 0.01)), linear: the relative MSE Kalantari et al. train LBF with."""
    pred, ref = safe(pred), safe(ref)
    return ((pred - ref) ** 2 / (ref * ref + RELMSE_EPS)).mean()


#: Spatial loss by name (``--loss``): "log" compares log(1 + x); "relative" adds :func:`relative_l1`;
#: "relmse" is :func:`relmse_loss` (LBF's). PCN's "lobes" (the paper's separate diffuse/specular L1)
#: is handled by :func:`pcn_loss`.
SPATIAL = {
    "log": spatial_l1,
    "relative": lambda pred, ref: spatial_l1(pred, ref) + relative_l1(pred, ref),
    "relmse": relmse_loss,
}


def gradient_l1(pred: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    return (laplacian_of_gaussian(to_log(pred)) - laplacian_of_gaussian(to_log(ref))).abs().mean()


def temporal_l1(pred: torch.Tensor, prev_pred: torch.Tensor, ref: torch.Tensor, prev_ref: torch.Tensor) -> torch.Tensor:
    dp = to_log(pred) - to_log(prev_pred)
    dr = to_log(ref) - to_log(prev_ref)
    return (dp - dr).abs().mean()


def frame_weights(frames: int) -> torch.Tensor:
    """Rising weights for a K-frame sequence, summing to 1.

    A half Gaussian ending at the last frame, σ = K/3: for K = 7 the relative weights are
    0.04, 0.11, 0.24, 0.43, 0.64, 0.89, 1 (the paper's rise from ~0.01 to 1 over 7 frames), so
    early frames, which have seen little history, count little.
    """
    k = torch.arange(frames, dtype=torch.float32)
    sigma = max(frames / 3.0, 1e-6)
    weights = torch.exp(-0.5 * ((k - (frames - 1)) / sigma) ** 2)
    return weights / weights.sum()


def rae_sequence_loss(
    preds: list[torch.Tensor], refs: list[torch.Tensor], kind: str = "log"
) -> dict[str, torch.Tensor]:
    """0.8·L_s + 0.1·L_g + 0.1·L_t, each a weighted sum over frames (L_t from the second frame on)."""
    weights = frame_weights(len(preds))
    spatial_fn = SPATIAL[kind]
    spatial = sum(w * spatial_fn(p, r) for w, p, r in zip(weights, preds, refs))
    gradient = sum(w * gradient_l1(p, r) for w, p, r in zip(weights, preds, refs))
    temporal = (
        sum(weights[t] * temporal_l1(preds[t], preds[t - 1], refs[t], refs[t - 1]) for t in range(1, len(preds)))
        if len(preds) > 1
        else torch.zeros(())
    )
    total = (
        LOSS_WEIGHTS["spatial"] * spatial + LOSS_WEIGHTS["gradient"] * gradient + LOSS_WEIGHTS["temporal"] * temporal
    )
    return {"loss": total, "spatial": spatial, "gradient": gradient, "temporal": temporal}


#: pcn_loss kinds beyond SPATIAL's.
PCN_KINDS = ("lobes", "exposure")


def _exposed(out: dict[str, torch.Tensor], batch: dict[str, torch.Tensor]) -> tuple[dict, dict]:
    """``out``'s and ``batch``'s radiance divided by the model's exposure (``out["exposure"]``, N×1×1×1).

    A black input (exposure 0, whose output is black) is compared unscaled: dividing its reference
    by ~0 would add a constant of ~70 to the loss that no weight can change."""
    scale = out["exposure"].detach()
    scale = torch.where(scale > 0, scale, torch.ones_like(scale))
    names = ("color", "diffuse", "specular")
    exposed_out = {name: out[name] / scale for name in names if name in out}
    refs = ("reference", "reference_diffuse", "reference_specular")
    exposed_batch = {name: batch[name] / scale for name in refs if name in batch}
    return exposed_out, exposed_batch


def pcn_loss(
    out: dict[str, torch.Tensor], batch: dict[str, torch.Tensor], kind: str = "log"
) -> dict[str, torch.Tensor]:
    """Spatial loss (SPATIAL[kind]) on colour, plus log L1 on each branch against its reference lobe when the batch has it.

    ``kind="lobes"`` is Bako et al.'s recipe: only the two branch losses (L1 of log(1 + x) of each
    lobe; the branches have separate weights, so the sum trains each on its own lobe), no colour
    term. A batch without reference lobes falls back to the log L1 of the colour.
    ``kind="exposure"`` is ``log`` after dividing prediction and references by ``out["exposure"]``
    (the PCN's input exposure): scale-invariant, see the module Notes.
    """
    if kind == "exposure":
        out, batch = _exposed(out, batch)
        kind = "log"
    if kind == "lobes":
        if "reference_diffuse" in batch and "reference_specular" in batch:
            diffuse = spatial_l1(out["diffuse"], batch["reference_diffuse"])
            specular = spatial_l1(out["specular"], batch["reference_specular"])
            return {"diffuse": diffuse, "specular": specular, "loss": diffuse + specular}
        kind = "log"
    color = SPATIAL[kind](out["color"], batch["reference"])
    total = color
    parts = {"color": color}
    if "reference_diffuse" in batch and "reference_specular" in batch:
        diffuse = spatial_l1(out["diffuse"], batch["reference_diffuse"])
        specular = spatial_l1(out["specular"], batch["reference_specular"])
        total = total + diffuse + specular
        parts.update(diffuse=diffuse, specular=specular)
    parts["loss"] = total
    return parts


def relmse(pred: torch.Tensor, ref: torch.Tensor) -> float:
    """mean((p − r)² / (r² + 0.01)) over every value, linear radiance (docs/architecture.md's relMSE): the value of
    :func:`relmse_loss`, computed in float64 (a sum over whole validation frames)."""
    value = relmse_loss(pred.double(), ref.double()).item()
    return value if math.isfinite(value) else math.inf
