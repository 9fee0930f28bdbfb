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
   ``k = 100 cd/m² / key`` where ``key = exp(mean(log Y))`` is the log-average (Reinhard's "key")
   of the reference's Rec.709 luminance ``Y = 0.2126 R + 0.7152 G + 0.0722 B`` over the **lit**
   pixels of every frame: those with ``Y > 1e-3 · mean(Y)``; black and near-black pixels are left
   out (black stays black at any exposure, so it must not set one). The typical lit surface of
   the reference is thus shown at ~100 cd/m²; every denoiser of a sequence gets the same ``k``,
   so one prediction's score never depends on another's. An all-black reference (mean 0) uses
   ``k = 100``. Pitfall: the key is a geometric mean, so a small bright emitter barely moves it (a
   plain mean would darken the whole scene to make room for it); highlights above 15× the key
   clip at the display's peak.

   Why black pixels do not count: floored at 1/1000 of the mean and counted, a reference with a
   black background got a key far too low. Measured on depth_of_field_900 (80 px, 8
   frames, 1024-spp reference, 31 % of its pixels black; ``tests/metrics/field/test_cvvdp.py``
   reproduces the case): k = 24 849 instead of 3220, the median surface at 490 cd/m² instead of
   ~65, and the 1-spp outputs of cross_bilateral / rae scored −39.0 / −18.9 JOD (the demo's
   −19.2 / −21.9) against the noisy input's −0.09; with the lit key −16.2 / −4.1 against +0.35
   (oidn +1.5). What is left is the outputs, not the viewing: at 1 spp most of the input's
   pixels are black (its median is 0) and cross_bilateral's range kernel keeps them black (its
   median pixel is 0.1 % of the reference's, its mean luminance 1.4 %; rae's mean 38 %), while
   the noisy input's sparse bright samples carry the right mean. A global darkening alone would
   cost little (the reference × 0.014 scores 8.3 JOD: contrast constancy); a mostly black image
   where the reference is textured costs a lot. tPSNR cannot see it: a dark, steady output has
   small frame differences (cross_bilateral 25.2 dB against the input's 14.2). The frame size
   is not the cause: 75, 30 and 15 pixels per degree give −16.2 / −16.2 / −16.1 JOD for
   cross_bilateral and −4.1 / −4.1 / −4.0 for rae. :func:`luminance_ratio` states the darkening
   so that a report can say why a score is that low.
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
unit), 8 frames of 32² or 64² at 30 fps (``tests/metrics/field/test_cvvdp.py`` holds the predictions):
brightness alternating ±15 % frame to frame → 5.2 JOD while the same +15 % held static → 10.0
(the model's contrast constancy ignores a steady global gain); Gaussian noise σ = 0.03 → 9.9,
σ = 0.1 → 9.2–9.3 (new noise every frame) and 9.1 (the same noise in every frame). With a plain
×100 cd/m² scale instead of the key the flicker case scored 6.7: brighter display, more
visible flicker.

Viewing conditions: :func:`viewing_conditions` gives the display, its pixels per degree, the
visual angle a frame spans and, for a reference, the exposure and how much of it clips, as plain
numbers and one sentence, for run records and reports.

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

from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.torch_threads import one_torch_thread
from denoisebench.metrics.validation import check_sequences

# Lazy imports: torch (1 s) and pycvvdp are imported when cvvdp is computed, so that the
# metric registry stays cheap to import.

__all__ = [
    "DISPLAY",
    "DISPLAY_DESCRIPTION",
    "FPS",
    "TARGET_KEY_CD_M2",
    "METRICS",
    "WORST",
    "cvvdp",
    "exposure_from_reference",
    "load_pycvvdp",
    "luminance_ratio",
    "viewing_conditions",
]

DISPLAY = "standard_hdr_linear"
DISPLAY_DESCRIPTION = (
    "cvvdp 'standard_hdr_linear': 30-inch 4K HDR monitor, peak 1500 cd/m^2, contrast 1e6, 10 lux, "
    "viewed from 2 display heights (75.4 ppd); exposure maps the log-average luminance of the reference's lit pixels "
    "to 100 cd/m^2"
)
FPS = 30.0
TARGET_KEY_CD_M2 = 100.0
KEY_FLOOR = 1e-3  # pixels at or below this × the reference's mean luminance are left out of the key
#: ``DISPLAY``'s model in cvvdp 0.5.7's display_models.json (tests/metrics/field/test_cvvdp.py checks them
#: against the package): resolution, diagonal, viewing distance, peak, contrast, ambient light, and
#: the pixels per degree at the centre that pycvvdp's display geometry computes from them.
DISPLAY_MODEL = {
    "resolution": (3840, 2160),
    "diagonal_inches": 30.0,
    "distance_m": 0.7472,
    "peak_cd_m2": 1500.0,
    "contrast": 1e6,
    "ambient_lux": 10.0,
    "reflectivity": 0.005,
    "ppd": 75.40,
}

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


def _luminance(seq) -> np.ndarray:
    return np.maximum(np.asarray(seq, dtype=np.float64)[..., :3] @ _REC709_Y, 0.0)


def _key(y: np.ndarray) -> tuple[float | None, float]:
    """(log-average luminance of the lit pixels, their fraction); (None, 0) for a black reference."""
    mean = float(y.mean())
    if not (mean > 0.0 and math.isfinite(mean)):
        return None, 0.0
    lit = y[y > KEY_FLOOR * mean]
    return math.exp(float(np.log(lit).mean())), lit.size / y.size


def exposure_from_reference(ref_seq) -> float:
    """cd/m² per unit of radiance for a sequence: ``100 / key`` of the reference's lit pixels (module Notes)."""
    key, _ = _key(_luminance(ref_seq))
    return TARGET_KEY_CD_M2 if key is None else TARGET_KEY_CD_M2 / key


def luminance_ratio(pred_seq, ref_seq) -> float | None:
    """Mean Rec.709 luminance of the prediction over the reference's (1: no light lost or added).

    None for a black reference. A denoiser whose output is much darker than its reference (energy
    lost from a sparse low-spp input) scores far below zero JOD although its tPSNR may be good.
    """
    c = check_sequences(pred_seq, ref_seq, min_frames=1)
    ref_mean = float(_luminance(c.ref).mean())
    if not ref_mean > 0:
        return None
    return float(_luminance(np.where(np.isfinite(c.pred), c.pred, 0.0)).mean()) / ref_mean


def viewing_conditions(ref_seq=None) -> dict:
    """What cvvdp's viewer sees: display, pixels per degree and, for a reference, exposure and field of view.

    Returns plain numbers (JSON-ready) and ``"text"``, one sentence for a report. With ``ref_seq``
    (T×H×W×3 or H×W×3): ``frame_px`` (W, H), ``field_deg`` (the frame's width and height in
    degrees of visual angle at the display's ppd), ``exposure`` (cd/m² per unit radiance),
    ``key`` (the lit pixels' log-average radiance), ``lit_fraction``, and ``clipped_fraction``
    (reference pixels whose ``exposure · Y`` exceeds the display's peak).
    """
    d = DISPLAY_MODEL
    black = d["peak_cd_m2"] / d["contrast"] + d["ambient_lux"] / math.pi * d["reflectivity"]
    out = {
        "display": DISPLAY,
        "description": DISPLAY_DESCRIPTION,
        "resolution": list(d["resolution"]),
        "ppd": d["ppd"],
        "peak_cd_m2": d["peak_cd_m2"],
        "black_cd_m2": black,
        "ambient_lux": d["ambient_lux"],
        "fps": FPS,
        "target_key_cd_m2": TARGET_KEY_CD_M2,
    }
    text = (
        f"cvvdp display {DISPLAY} (30-inch 4K HDR, peak {d['peak_cd_m2']:.0f} cd/m², {d['ambient_lux']:.0f} lux, "
        f"{d['ppd']:.1f} pixels per degree), {FPS:.0f} fps"
    )
    if ref_seq is not None:
        ref = np.asarray(ref_seq, dtype=np.float64)
        if ref.ndim == 3:
            ref = ref[None]
        if ref.ndim != 4 or ref.shape[-1] < 3:
            raise ValueError(f"the reference must be T×H×W×3 or H×W×3, got shape {ref.shape}")
        y = _luminance(ref)
        key, lit = _key(y)
        k = TARGET_KEY_CD_M2 if key is None else TARGET_KEY_CD_M2 / key
        h, w = ref.shape[1:3]
        out.update(
            frame_px=[int(w), int(h)],
            field_deg=[w / d["ppd"], h / d["ppd"]],
            exposure=k,
            key=key,
            lit_fraction=lit,
            clipped_fraction=float(np.mean(k * y > d["peak_cd_m2"])),
        )
        text += (
            f"; a {w}×{h} frame spans {w / d['ppd']:.2f}°×{h / d['ppd']:.2f}°; exposure {k:.4g} cd/m² per unit "
            f"(the lit {100 * lit:.0f} % of the reference's pixels average {TARGET_KEY_CD_M2:.0f} cd/m², "
            f"{100 * out['clipped_fraction']:.1f} % clip at the peak)"
        )
    out["text"] = text
    return out


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
        return WORST["cvvdp"]
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


METRICS: tuple[Metric, ...] = (
    Metric(
        name="cvvdp",
        fn=cvvdp,
        higher_is_better=True,
        domain="linear",
        kind="temporal",
        worst=-math.inf,  # JOD is unbounded below
        perfect=10.0,
        description="ColorVideoVDP (cvvdp) at 30 fps: " + DISPLAY_DESCRIPTION,
        unit="JOD",
    ),
)

#: Worst value, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
