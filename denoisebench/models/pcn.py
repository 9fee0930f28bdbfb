"""DPCN and KPCN after Bako et al. 2017, "Kernel-Predicting Convolutional Networks for Denoising
Monte Carlo Renderings" (SIGGRAPH 2017).

Two branches with identical architecture and separate weights: one for the demodulated diffuse
lobe, one for the log specular lobe (inputs from :func:`~denoisebench.models.features.pcn_inputs`).
Each branch is a plain stack of ``layers`` convolutions of ``channels`` channels and ``kernel``×``kernel``
support with ReLU between them (the paper: 9 × 100 × 5×5).

* **DPCN** (direct prediction): the last layer outputs the denoised colour of its branch, in the
  log domain the network sees (log(1 + demodulated diffuse), log(1 + specular)). With
  ``bound_output`` (our deviation, in the small and paper configurations) that output is capped by
  the brightest noisy value of the lobe within the ``kernel_size`` window: nothing KPCN could
  produce from the same window is refused, and an unseen input can no longer send a pixel to e^30.
  The cap is straight-through in training (gradient of the uncapped output), else a pixel above it
  gets no gradient and can never come back down. With ``log_offset`` ε > 0 (off in every named
  configuration; ``train --set log_offset=0.01``) the head's output is read as log(x + ε) of the
  normalised lobe instead of log(1 + x): a head error of 0.1 then moves a pixel at 1% of the exposure
  by ~20%, not by ~1000% (log(1 + x) is linear near 0, where relMSE weighs most).
* **KPCN** (kernel prediction): the last layer outputs ``kernel_size²`` (21² = 441) logits per pixel,
  softmax-normalised into a non-negative kernel summing to one that is applied to the branch's noisy
  buffer (demodulated diffuse, log specular) around the pixel.

Then diffuse is remodulated by albedo + ε, specular exponentiated, and the two are added. Our
deviation: where the demodulated domain cannot be trusted (pixels of no albedo; channels of albedo
below ``ALBEDO_TRUSTED``, mostly partly covered silhouettes) KPCN filters the rendered diffuse over
taps of the same class only, and DPCN keeps the rendered diffuse at pixels of no albedo
(:meth:`PCN._kernel_diffuse`; found on third-party scenes, docs/study.md).

Notes
-----
* Softmax overflow: logits are made finite and clamped to ±LOGIT_MAX before
  :func:`torch.softmax` (which subtracts the per-pixel maximum), so extreme inputs give a valid
  kernel, never NaN.
* The kernel is applied in two ways with the same sums. While autograd records (training):
  ``unfold`` in bands of rows (at most UNFOLD_BYTES of neighbourhoods at once; the whole
  N×3·441×H·W intermediate would need 5 GB at one megapixel), because an offset-by-offset loop
  is ten times slower to differentiate. Otherwise (inference): one in-place multiply-add per
  offset over shifted views, which writes nothing of that size and is ~10× faster on a CPU.
* The noisy buffer is padded by replication for the kernel, so images smaller than the kernel
  (odd sizes down to 1×1) work.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable

import torch
from torch import nn
from torch.nn import functional as F

from denoisebench.models.features import LOG_MAX as LOG_MAX_OUTPUT
from denoisebench.models.features import (
    PCN_INPUT_CHANNELS,
    dark_pixels,
    from_log,
    normalize_radiance,
    partly_background,
    pcn_inputs,
    safe,
    split_lobes,
)

#: A diffuse channel whose albedo is below this is filtered in the rendered domain, over taps of low
#: albedo only (KPCN; PCN._kernel_diffuse): its quotient is mostly what lies around a partly covered
#: pixel ÷ a small albedo.
ALBEDO_TRUSTED = 0.1
#: Logits beyond this carry no extra information (exp(±50) spans every float32 ratio) and keep softmax finite.
LOGIT_MAX = 50.0

#: Bako et al.'s branch: 9 layers of 100 channels, 5×5, Xavier-initialised; 21×21 kernels for KPCN.
PAPER_CONFIG = {
    "layers": 9,
    "channels": 100,
    "kernel": 5,
    "kernel_size": 21,
    "init": "xavier",
    "log_depth_var": True,
    "bound_output": True,
}

# DPCN and KPCN share every configuration (depth, width, receptive field, initialisation), so the
# lecture's comparison (KPCN converges faster) compares the output form alone
# (bench/pcn_convergence.py). The small branch must *see* as far as KPCN's kernel reaches: five
# 5×5 layers give a 21-pixel receptive field, the 21×21 kernel's (five 3×3 layers saw 11 pixels
# and could not tell which of the outer taps to trust). The 1×1 head keeps the 24 → 441 logits
# layer cheap. The shipped dpcn_small.pt predates this (5 layers of 3×3, default init): its
# checkpoint records that shape, so it still loads and scores as before. Why those weights and not
# this configuration's: weights/dpcn_small.log.md (the runs that failed and the one that worked).
# Torch's default initialisation in the small configuration (the shipped kpcn_small.pt's; on
# the unit tests' toy batch Xavier's larger start made KPCN's first steps at lr 5e-3 overshoot).
SMALL_CONFIG = {
    "layers": 6,
    "channels": 24,
    "kernel": 5,
    "kernel_size": 21,
    "head_kernel": 1,
    "log_depth_var": True,
    "bound_output": True,
}

DPCN_CONFIGS = {"paper": dict(PAPER_CONFIG), "small": dict(SMALL_CONFIG)}
KPCN_CONFIGS = {"paper": dict(PAPER_CONFIG), "small": dict(SMALL_CONFIG)}

#: Weight initialisations: torch's default (Kaiming-uniform, what the first shipped weights used)
#: or Xavier/Glorot uniform with zero biases (the paper's).
INITS = ("default", "xavier")


def receptive_field(config: dict) -> int:
    """Side in pixels of the square a branch's output pixel sees (not counting input gradients)."""
    head = config.get("head_kernel") or config["kernel"]
    return 2 * ((config["layers"] - 1) * (config["kernel"] // 2) + head // 2) + 1


def conv_stack(
    in_channels: int,
    out_channels: int,
    layers: int,
    channels: int,
    kernel: int,
    head_kernel: int | None = None,
    init: str = "default",
) -> nn.Sequential:
    """``layers`` convolutions with ReLU between (none after the last), 'same' zero padding.

    The last convolution has ``head_kernel``×``head_kernel`` support (default: ``kernel``);
    ``init`` is one of :data:`INITS`.
    """
    if init not in INITS:
        raise ValueError(f"init must be one of {', '.join(INITS)} (got {init!r})")
    if layers < 2:
        raise ValueError(f"a PCN branch needs at least 2 layers (got {layers})")
    modules: list[nn.Module] = []
    width = in_channels
    for _ in range(layers - 1):
        modules += [nn.Conv2d(width, channels, kernel, padding=kernel // 2), nn.ReLU(inplace=True)]
        width = channels
    head = kernel if head_kernel is None else head_kernel
    modules.append(nn.Conv2d(width, out_channels, head, padding=head // 2))
    if init == "xavier":
        with torch.no_grad():
            for module in modules:
                if isinstance(module, nn.Conv2d):
                    nn.init.xavier_uniform_(module.weight)
                    module.bias.zero_()
    return nn.Sequential(*modules)


#: Bytes of unfolded neighbourhoods held at once by the unfold path of :func:`apply_kernels`.
UNFOLD_BYTES = 256 * 2**20


def apply_kernels(noisy: torch.Tensor, weights: torch.Tensor, size: int) -> torch.Tensor:
    """Per-pixel filtering: out[p] = Σ_k weights[k, p] · noisy[p + offset_k], offsets over size×size.

    ``noisy`` N×C×H×W, ``weights`` N×size²×H×W (row-major offsets, dy then dx, as ``unfold`` orders them).
    Borders are replicated. Two ways to the same sums (see the module Notes): ``unfold`` in bands
    when autograd records (fast to differentiate), one multiply-add per offset otherwise (fast
    forward, nothing of size C·size²·H·W written).
    """
    radius = size // 2
    padded = F.pad(noisy, (radius, radius, radius, radius), mode="replicate")
    if torch.is_grad_enabled() and (noisy.requires_grad or weights.requires_grad):
        return _apply_unfolded(padded, weights, size)
    return _apply_shifted(padded, weights, size)


def _apply_shifted(padded: torch.Tensor, weights: torch.Tensor, size: int) -> torch.Tensor:
    height, width = weights.shape[-2:]
    out = torch.zeros(padded.shape[:2] + (height, width), dtype=padded.dtype, device=padded.device)
    for k in range(size * size):
        dy, dx = divmod(k, size)
        out.addcmul_(padded[:, :, dy : dy + height, dx : dx + width], weights[:, k : k + 1])
    return out


def _apply_unfolded(padded: torch.Tensor, weights: torch.Tensor, size: int) -> torch.Tensor:
    batch, channels = padded.shape[:2]
    height, width = weights.shape[-2:]
    radius = size // 2
    row_bytes = batch * channels * size * size * width * padded.element_size()
    band = max(1, min(height, UNFOLD_BYTES // max(row_bytes, 1)))
    bands = []
    for top in range(0, height, band):
        rows = min(band, height - top)
        window = padded[:, :, top : top + rows + 2 * radius]
        patches = F.unfold(window, size).view(batch, channels, size * size, rows * width)
        kernel = weights[:, :, top : top + rows].reshape(batch, 1, size * size, rows * width)
        bands.append((patches * kernel).sum(dim=2).view(batch, channels, rows, width))
    return bands[0] if len(bands) == 1 else torch.cat(bands, dim=2)


def softmax_kernels(logits: torch.Tensor) -> torch.Tensor:
    """Softmax over the kernel dimension (1) of finite, clamped logits: ≥ 0 and summing to 1 per pixel.

    Without autograd recording, ``logits`` is overwritten (it becomes the result)."""
    if torch.is_grad_enabled() and logits.requires_grad:
        return torch.softmax(safe(logits, LOGIT_MAX), dim=1)
    # inference: the same clean-up in place (the logits are size² channels, the largest tensor here)
    # and torch.softmax's steps in place (it is ~1.5x slower over a strided channel axis on a CPU)
    logits = torch.nan_to_num_(logits, nan=0.0, posinf=0.0, neginf=0.0).clamp_(-LOGIT_MAX, LOGIT_MAX)
    weights = logits.sub_(logits.amax(dim=1, keepdim=True)).exp_()
    return weights.div_(weights.sum(dim=1, keepdim=True))


class PCN(nn.Module):
    """A two-branch pixel network; ``mode`` is ``"direct"`` (DPCN) or ``"kernel"`` (KPCN).

    ``forward(buffers)`` takes N×C×H×W tensors by buffer name and returns a dict with ``color``,
    ``diffuse`` and ``specular`` (linear radiance, N×3×H×W), ``exposure`` (N×1×1×1, what the input
    was divided by; the ``exposure`` loss reads it) and ``kernels`` (KPCN only,
    N×2×size²×H×W: diffuse and specular branch; unless ``return_kernels`` is off).
    """

    def __init__(
        self,
        mode: str,
        layers: int,
        channels: int,
        kernel: int,
        kernel_size: int = 21,
        head_kernel: int | None = None,
        init: str = "default",
        log_depth_var: bool = False,
        bound_output: bool = False,
        log_offset: float = 0.0,
    ):
        super().__init__()
        #: DPCN: with log_offset ε > 0 the head outputs log(x + ε) of the normalised lobe instead of
        #: log(1 + x), so that dark pixels keep relative precision (0: log(1 + x), old checkpoints)
        self.log_offset = float(log_offset)
        if self.log_offset < 0:
            raise ValueError(f"log_offset must be >= 0 (got {log_offset})")
        #: depth_var through log(1 + d) like the depth itself (features.feature_stack); False in old checkpoints
        self.log_depth_var = bool(log_depth_var)
        #: DPCN: each lobe's log output is capped by the largest noisy value of that lobe within the
        #: kernel_size window (what KPCN's convex combination obeys by construction); False in old checkpoints
        #: (KPCN: accepted for the shared configurations and off: a kernel's output is already a convex
        #: combination of the noisy window)
        self.bound_output = bool(bound_output) and mode == "direct"
        if mode not in ("direct", "kernel"):
            raise ValueError(f"mode must be 'direct' or 'kernel', not {mode!r}")
        if kernel_size % 2 != 1:
            raise ValueError(f"kernel_size must be odd (got {kernel_size})")
        self.mode = mode
        #: whether ``forward`` returns KPCN's kernels (tests and training read them; inference
        #: wrappers turn this off: stacking 2·size² planes per pixel costs as much as the softmax)
        self.return_kernels = True
        self.kernel_size = kernel_size
        out_channels = 3 if mode == "direct" else kernel_size * kernel_size
        self.diffuse = conv_stack(PCN_INPUT_CHANNELS, out_channels, layers, channels, kernel, head_kernel, init)
        self.specular = conv_stack(PCN_INPUT_CHANNELS, out_channels, layers, channels, kernel, head_kernel, init)
        if mode == "direct":
            # Radiance is normalised to mean 1 (features.normalize_radiance): start at log(1 + 1), not at black.
            with torch.no_grad():
                for branch in (self.diffuse, self.specular):
                    branch[-1].bias.fill_(math.log(1.0 + self.log_offset) if self.log_offset else math.log(2.0))
        if mode == "kernel":
            # Start near the identity: a centre-tap bias of log(size² − 1) gives the centre half the
            # weight. A near-uniform 21×21 start would smear emitters over their neighbours, and
            # the first hundreds of steps would go to unlearning that.
            with torch.no_grad():
                centre = (kernel_size * kernel_size) // 2
                for branch in (self.diffuse, self.specular):
                    branch[-1].bias[centre] += math.log(kernel_size * kernel_size - 1)

    def _branch(
        self, net: nn.Module, inputs: torch.Tensor, noisy: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        out = net(inputs)
        if self.mode == "direct":
            if self.bound_output:
                size = self.kernel_size
                cap = F.max_pool2d(noisy.max(dim=1, keepdim=True).values, size, 1, size // 2)  # log(1 + x)
                if self.log_offset:
                    cap = torch.log(torch.expm1(cap) + self.log_offset)
                bounded = torch.minimum(out, cap)
                # straight through: the forward value is bounded, the gradient is the unbounded output's
                # (a plain minimum passes none where the cap binds, and a head that drifted above the cap
                # stayed there: training loss rose 0.42 → 1.0 over 2000 steps, val relMSE 409)
                out = out + (bounded - out).detach() if out.requires_grad else bounded
            return out, None
        kernels = softmax_kernels(out)
        return apply_kernels(noisy, kernels, self.kernel_size), kernels

    def _from_offset_log(self, y: torch.Tensor) -> torch.Tensor:
        """exp(y) − ε, y clamped to [log ε, LOG_MAX] with a straight-through gradient (as from_log)."""
        clamped = y.clamp(math.log(self.log_offset), LOG_MAX_OUTPUT)
        return (torch.exp(y + (clamped - y).detach()) - self.log_offset).clamp_min(0.0)

    def _kernel_diffuse(self, buffers: dict[str, torch.Tensor], prepared: dict, kd: torch.Tensor) -> torch.Tensor:
        """``diffuse`` where the demodulated domain cannot be trusted, filtered without it.

        Pixels of no albedo (emitters, background, black materials: :func:`~.features.dark_pixels`)
        are not demodulated (:func:`~.features.albedo_factor`), so a branch output there is a value
        of the demodulated domain (an irradiance, radiance ÷ albedo) taken from lit neighbours and
        remodulated by 1: on a black rough-plastic sphere beside a grey floor (Mitsuba's
        bsdf_roughplastic_ggx) that painted the floor's irradiance onto the sphere at 15× the
        reference. A channel of low albedo (below ``ALBEDO_TRUSTED``; often a pixel a surface only
        partly covers, at a silhouette before a bright background) is demodulated, but its quotient
        is mostly the background ÷ a small albedo, and the kernel taps that reach it spread it: 15×
        a lit wall's on Mitsuba's two-sided Cornell box, 6× on usd-wg's ambulance.

        KPCN therefore splits its diffuse kernel per channel into classes, each filtered over taps of
        its own class only and renormalised (a pixel with no tap of its class keeps its own value):
        trusted channels in the demodulated domain; low-albedo channels, pixels of no albedo and
        pixels partly covering the background (:func:`~.features.partly_background`, which needs the
        frame's ``spp``; the albedo threshold alone misses them above 0.1) each in the rendered
        (radiance) domain. DPCN, whose head has no kernel, keeps the rendered diffuse at pixels of no
        albedo. The shipped kpcn at 4 spp, relMSE geometric mean: 15 third-party scenes 0.0325 →
        0.0233, the 13 families' test split 0.0271 → 0.0265 (docs/study.md); the partly-covered class
        then took the third-party scenes' relmse_robust from 0.974 to 0.929 of cross_bilateral's, and
        Mitsuba's two-sided Cornell box from 2.04 to 1.57 (docs/study.md)."""
        lin, factor, size = prepared["diffuse_lin"], prepared["albedo_factor"], self.kernel_size
        dark = dark_pixels(buffers)
        trusted = None if dark is None else (safe(buffers["albedo"]).clamp(0.0, 1.0) >= ALBEDO_TRUSTED) & ~dark
        partial = partly_background(buffers)
        if partial is not None and bool(partial.any()):
            trusted = trusted & ~partial
        else:
            partial = None
        if trusted is None or bool(trusted.all()):
            return apply_kernels(lin, kd, size) * factor  # one kernel over every tap
        rendered = split_lobes(buffers)[0]

        def restricted(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
            mask = mask.to(values.dtype).expand_as(values)
            weight = apply_kernels(mask, kd, size)
            filtered = apply_kernels(values * mask, kd, size) / weight.clamp_min(1e-6)
            return torch.where(weight > 1e-6, filtered, values)

        out = restricted(lin, trusted) * factor  # lin: the rendered diffuse ÷ factor (pcn_inputs)
        out = torch.where(dark, restricted(rendered, dark), out)
        weak = ~trusted & ~dark if partial is None else ~trusted & ~dark & ~partial
        out = torch.where(weak, restricted(rendered, weak), out)
        return out if partial is None else torch.where(partial, restricted(rendered, partial), out)

    def forward(self, buffers: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        buffers, scale = normalize_radiance(buffers)
        prepared = pcn_inputs(buffers, self.log_depth_var)
        factor = prepared["albedo_factor"]
        decode = from_log if self.mode != "direct" or not self.log_offset else self._from_offset_log
        if self.mode == "direct":
            diffuse_log, kd = self._branch(self.diffuse, prepared["diffuse_in"], prepared["diffuse_log"])
            diffuse = decode(diffuse_log) * factor
            dark = dark_pixels(buffers)  # no kernel to restrict: the rendered diffuse (_kernel_diffuse)
            if dark is not None and bool(dark.any()):
                diffuse = torch.where(dark, split_lobes(buffers)[0], diffuse)
        else:
            kd = softmax_kernels(self.diffuse(prepared["diffuse_in"]))
            diffuse = self._kernel_diffuse(buffers, prepared, kd)
        specular_log, ks = self._branch(self.specular, prepared["specular_in"], prepared["specular_log"])
        specular = decode(specular_log)
        diffuse, specular = diffuse * scale, specular * scale
        out = {"color": diffuse + specular, "diffuse": diffuse, "specular": specular, "exposure": scale}
        if kd is not None and self.return_kernels:
            out["kernels"] = torch.stack([kd, ks], dim=1)  # N×2×size²×H×W
        return out


def _builder(mode: str, without: tuple[str, ...] = ()) -> Callable[..., PCN]:
    """A builder of ``PCN(mode, ...)`` that takes PCN's own parameters less ``mode`` and ``without``.

    Notes
    -----
    ``training_options.apply_overrides`` reads a builder's signature to know which ``--set`` keys a model
    takes, so the builder carries PCN's signature (one parameter list to keep, not three) and refuses
    a parameter it leaves out with the TypeError a plain function would raise.
    """
    signature = inspect.signature(PCN)
    parameters = [p for name, p in signature.parameters.items() if name != "mode" and name not in without]
    signature = signature.replace(parameters=parameters, return_annotation="PCN")

    def build(*args, **kwargs) -> PCN:
        signature.bind(*args, **kwargs)
        return PCN(mode, *args, **kwargs)

    build.__signature__ = signature
    build.__name__ = build.__qualname__ = f"make_{'dpcn' if mode == 'direct' else 'kpcn'}"
    return build


#: DPCN from PCN's parameters.
make_dpcn = _builder("direct")
#: KPCN from PCN's parameters less ``log_offset`` (DPCN's log domain; a kernel's output has none).
make_kpcn = _builder("kernel", without=("log_offset",))
