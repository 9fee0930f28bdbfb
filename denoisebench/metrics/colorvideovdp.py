"""ColorVideoVDP (``cvvdp``): perceived difference of a video, in JOD, from the ``cvvdp`` package.

ColorVideoVDP (Mantiuk et al., SIGGRAPH 2024; package ``cvvdp``, module ``pycvvdp``) models how
visible the differences between a test video and a reference video are to a viewer of a given
display, flicker included: its temporal channels are the only part of our metric set that says
how *visible* a frame-to-frame change is. Its unit is the JOD (just-objectionable difference):
10 = indistinguishable from the reference, each unit lower ≈ 75 % of viewers preferring the
reference once more. Higher is better; the scale is unbounded below.

The mapping from our data to what the model sees (it needs absolute photometric units)
-----------------------------------------------------------------------------------------
1. **Colour**: our radiance is linear Rec.709/sRGB RGB, passed as the model's ``BT.709-linear``
   colour space (no tone map, no encoding). Negative prediction values are clamped to 0 (a
   display emits no negative light).
2. **Exposure** ``k`` (cd/m² per unit of radiance), one per sequence, **from the reference only**:
   ``k = 100 cd/m² / key`` where ``key = exp(mean(log(max(Y, 1e-3 · mean(Y)))))`` is the
   log-average (Reinhard's "key") of the reference's Rec.709 luminance ``Y = 0.2126 R + 0.7152 G
   + 0.0722 B`` over every pixel of every frame, each luminance floored at 1/1000 of the mean
   (so black pixels do not drive the key to 0). The typical surface of the reference is thus
   shown at ~100 cd/m²; every denoiser of a sequence gets the same ``k``, so one prediction's
   score never depends on another's. An all-black reference (mean 0) uses ``k = 100``.
   Pitfall: the key is a geometric mean, so a small bright emitter barely moves it (a plain mean
   would darken the whole scene to make room for it); highlights above 15× the key clip at the
   display's peak.
3. **Display** (``DISPLAY``): cvvdp's own ``standard_hdr_linear`` model: a 30-inch 3840×2160
   HDR monitor, peak 1500 cd/m², contrast 10⁶:1, 10 lux ambient light (reflectivity 0.005), seen
   from 2 display heights (0.747 m) → 75.4 pixels per degree. The display clips ``k·RGB`` to
   [0.005, 1500] cd/m² and adds the reflected ambient light. A 128-pixel image thus spans
   ~1.7° of visual angle: small, so coarse spatial bands are missing and most of the score comes
   from fine detail and temporal change.
4. **Frame rate**: ``fps`` (default 30). At 30 fps the eye integrates part of frame-independent
   noise over time, so static noise scores *lower* than dynamic noise of the same σ; the model's
   temporal channels need ≥ 250 ms of video, and cvvdp pads the start by replicating frame 0.

Measured with this mapping on a textured static reference (mean 0.5, key → ≈ 230 cd/m² per
unit), 8 frames of 32² or 64² at 30 fps (``tests/test_metrics_cvvdp.py`` holds the predictions):
brightness alternating ±15 % frame to frame → 5.2 JOD while the same +15 % held static → 10.0
(the model's contrast constancy ignores a steady global gain); Gaussian noise σ = 0.03 → 9.9,
σ = 0.1 → 9.2–9.3 (new noise every frame) and 9.1 (the same noise in every frame). With a plain
×100 cd/m² scale instead of the key the flicker case scored 6.7: brighter display, more
visible flicker.

Runs offline on the CPU (the model's data ship in the package), on one torch thread
(:mod:`.torch_threads`: 20× less CPU than two threads here). ``bench/field_metrics_speed.py``
measures seconds per megapixel-frame: ≈ 3–4 s at 128² on one busy core (0.16 s for a 3-frame
128² sequence, 0.40 s for 8 frames; the first call adds ≈ 5 s to import and load the model).

Installing: ``cvvdp`` 0.5.7 imports ``torchvision``; the registry's torchvision 0.28.0 (the one
built for torch 2.13.0) is a CUDA build whose compiled operators cannot load into the CPU torch,
and its import then fails at two unguarded fake-kernel registrations (``torchvision::nms``,
``torchvision::qnms``: "operator ... does not exist"). :func:`load_pycvvdp` retries the import
after declaring those two operator schemas without a kernel; cvvdp uses only torchvision's
pure-Python parts (``transforms.GaussianBlur``, ``ops.MLP``), and calling ``nms`` would still
fail loudly. Where torchvision's operators load, nothing is declared.
"""

from __future__ import annotations

import logging
import math
import sys
import threading
import warnings
from contextlib import contextmanager

import numpy as np

from denoisebench.metrics.torch_threads import one_torch_thread
from denoisebench.metrics.validation import check_sequences

__all__ = [
    "DISPLAY",
    "DISPLAY_DESCRIPTION",
    "FPS",
    "TARGET_KEY_CD_M2",
    "WORST",
    "cvvdp",
    "exposure_from_reference",
    "load_pycvvdp",
]

DISPLAY = "standard_hdr_linear"
DISPLAY_DESCRIPTION = (
    "cvvdp 'standard_hdr_linear': 30-inch 4K HDR monitor, peak 1500 cd/m^2, contrast 1e6, 10 lux, "
    "viewed from 2 display heights (75.4 ppd); exposure maps the reference's log-average luminance "
    "to 100 cd/m^2"
)
FPS = 30.0
TARGET_KEY_CD_M2 = 100.0
KEY_FLOOR = 1e-3  # luminance floor of the key, relative to the reference's mean luminance
WORST = -math.inf  # JOD is unbounded below; a non-finite prediction gets -inf

_REC709_Y = np.array([0.2126, 0.7152, 0.0722])
_LOCK = threading.Lock()
_MODEL = None


def load_pycvvdp():
    """Import and return the ``pycvvdp`` module (see the module docstring for the torchvision fix).

    Raises ``RuntimeError`` with the install line when the package is missing.
    """
    if "pycvvdp" in sys.modules:
        return sys.modules["pycvvdp"]
    try:
        import pycvvdp  # noqa: F401
    except ModuleNotFoundError as exc:
        raise RuntimeError(
            f"the cvvdp metric needs the 'cvvdp' package ({exc}); run `make setup` "
            "(it installs requirements-nodeps.txt with pip --no-deps)"
        ) from None
    except RuntimeError as exc:
        if "torchvision::" not in str(exc) or "does not exist" not in str(exc):
            raise
        import torch

        for name in [n for n in sys.modules if n == "torchvision" or n.startswith(("torchvision.", "pycvvdp"))]:
            del sys.modules[name]
        schema = "(Tensor dets, Tensor scores, float iou_threshold) -> Tensor"
        for op in ("nms", "qnms"):
            if not hasattr(torch.ops.torchvision, op):
                torch.library.define(f"torchvision::{op}", schema)
        import pycvvdp  # noqa: F401
    return sys.modules["pycvvdp"]


def _model():
    global _MODEL
    with _LOCK:
        if _MODEL is None:
            import torch

            pycvvdp = load_pycvvdp()
            _MODEL = pycvvdp.cvvdp(display_name=DISPLAY, quiet=True, device=torch.device("cpu"))
        return _MODEL


def exposure_from_reference(ref_seq) -> float:
    """cd/m² per unit of radiance for a sequence: ``100 / key`` of the reference (module Notes)."""
    ref = np.asarray(ref_seq, dtype=np.float64)
    y = np.maximum(ref[..., :3] @ _REC709_Y, 0.0)
    mean = float(y.mean())
    if not (mean > 0.0 and math.isfinite(mean)):
        return TARGET_KEY_CD_M2
    key = math.exp(float(np.log(np.maximum(y, KEY_FLOOR * mean)).mean()))
    return TARGET_KEY_CD_M2 / key


def cvvdp(pred_seq, ref_seq, *, fps: float = FPS) -> float:
    """ColorVideoVDP JOD of a predicted sequence against its reference (T×H×W×3 linear radiance).

    Higher is better, 10 = no visible difference. One exposure from the reference for both
    (``exposure_from_reference``), the ``standard_hdr_linear`` display, ``fps`` frames per second.
    A prediction with NaN/Inf gives ``-inf``.
    """
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a finite number > 0, got {fps!r}")
    if c.nonfinite_count:
        return WORST
    import torch

    k = exposure_from_reference(c.ref)
    # Scaled in float64 (float32 radiance near its maximum times k would overflow), then capped:
    # the model computes in float32 and the display clips at 1500 cd/m² anyway.
    cap = 1e30
    test = torch.from_numpy(np.clip(c.pred.astype(np.float64) * k, 0.0, cap).astype(np.float32))
    ref = torch.from_numpy(np.clip(c.ref.astype(np.float64) * k, 0.0, cap).astype(np.float32))
    model = _model()
    with one_torch_thread(), _quiet(), torch.no_grad():
        jod, _stats = model.predict(test, ref, dim_order="FHWC", frames_per_second=float(fps))
    return float(jod)


@contextmanager
def _quiet():
    """Silence pycvvdp's root-logger warnings (e.g. "mean color value is less than 1" for a dark
    scene, which our exposure already handles) and Python warnings during a call; restore after."""
    previous = logging.root.manager.disable
    logging.disable(max(previous, logging.WARNING))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(previous)
