"""Spatial metrics of one frame: ``metric(pred, ref) -> float`` and ``metric_map(pred, ref) -> H×W``.

Inputs are H×W×3 linear HDR radiance (float or int arrays), prediction first, reference second.
Scalars are float64 means; maps are H×W float64 (channels averaged). A prediction with NaN/Inf
gives the metric's worst value (``validation``'s policy); a non-finite reference, mismatched
shapes or a wrong layout are a ``ValueError``.

Each metric's entry (direction, domain, worst value for a non-finite prediction, aggregation,
floor) is declared once, in :data:`METRICS` at the end of this module; :data:`WORST` is derived
from it.

Notes
-----
* relMSE = mean((p−r)² / (r² + 0.01)) and SMAPE = mean(|p−r| / (|p| + |r| + 0.01)) per channel
  (docs/architecture.md). ε is absolute, in radiance units: errors on very dark images (radiance ≪ 0.1) are
  divided by ≈ ε rather than by r², so relMSE is *not* scale-invariant there.
* "Tone-mapped" means :func:`denoisebench.metrics.tonemap.tonemap` (clamp, Reinhard, sRGB OETF)
  applied to both images; PSNR and SSIM then use data_range = 1.
* SSIM is scikit-image's ``structural_similarity`` with ``gaussian_weights=True, sigma=1.5,
  use_sample_covariance=False, data_range=1, channel_axis=-1`` (Wang et al. 2004). Its 11-tap
  window needs H, W ≥ 11: smaller images are a ``ValueError``. The scalar is scikit-image's (mean
  over the map without its 5-pixel border); ``ssim_map`` is the full map averaged over channels.
* HDR-FLIP is flip-evaluator's ``evaluate(ref, test, "HDR")`` on float32 copies with negatives
  clamped to 0 (FLIP wants non-negative HDR input) and values above float32's range clamped to
  its maximum. The library calls ``exit()`` on an all-black reference (its automatic start exposure
  becomes larger than its stop exposure): when the reference's maximum luminance is below 1e-6 we
  pass the exposures FLIP would compute with both the maximum and the median luminance floored
  at float32 epsilon (start = stop, every exposure saturates a non-black prediction). The mean
  is taken in float64 from the map (the library's own mean sums across threads without a
  reduction).
* ΔE2000: linear HDR is first tone-mapped with the linear stage of the documented tone map,
  ``reinhard(x)`` (clamp, c/(1+c)), which is read as *linear* sRGB: ``colour.RGB_to_XYZ(...,
  "sRGB", apply_cctf_decoding=False)`` (no chromatic adaptation, D65), then ``XYZ_to_Lab`` with
  the sRGB whitepoint (CIE 1931 2° D65) and ``delta_E(..., method="CIE 2000")``. Computed under
  colour's "reference" domain-range scale whatever the caller set globally.
"""

from __future__ import annotations

import functools
import math
import sys
import warnings

import numpy as np

from denoisebench.metrics.floors.closed_form import EPS_RELMSE, mse_floor, relmse_floor
from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.tonemap import reinhard, tonemap
from denoisebench.metrics.validation import Checked, MetricNotApplicable, check_pair

# Lazy imports: scikit-image, colour-science (0.9 s) and flip-evaluator are imported by the
# metric that needs each, so that the metric registry stays cheap to import.

__all__ = [
    "EPS_RELMSE",
    "EPS_SMAPE",
    "SSIM_SIGMA",
    "SSIM_MIN_SIZE",
    "mse",
    "mse_map",
    "relmse",
    "relmse_map",
    "smape",
    "smape_map",
    "l1",
    "l1_map",
    "psnr",
    "ssim",
    "ssim_map",
    "flip",
    "flip_map",
    "deltae2000",
    "deltae2000_map",
    "linear_srgb_to_lab",
    "delta_e2000_lab",
    "METRICS",
    "WORST",
]

EPS_SMAPE = 0.01
SSIM_SIGMA = 1.5
SSIM_MIN_SIZE = 11  # 2 * int(3.5 * 1.5 + 0.5) + 1: scikit-image's Gaussian window
FLIP_BLACK_LUMINANCE = 1e-6  # below this maximum luminance the reference counts as black for FLIP
_F32_MAX = float(np.finfo(np.float32).max)
_F32_EPS = float(np.finfo(np.float32).eps)
_REC709_LUMINANCE = np.array([0.2126, 0.7152, 0.0722], dtype=np.float32)  # FLIP's weights


# --------------------------------------------------------------------------- pixel-wise errors


def _pixelwise_map(c: Checked, per_value, worst: float) -> np.ndarray:
    """H×W map of ``per_value(p, r)`` averaged over channels; ``worst`` where pred is non-finite."""
    pred = c.pred
    if c.nonfinite_count:
        pred = np.where(c.bad[..., None], c.ref, pred)
    p = pred.astype(np.float64, copy=False)
    r = c.ref.astype(np.float64, copy=False)
    with np.errstate(over="ignore", invalid="ignore"):
        m = per_value(p, r).mean(axis=-1)
    if c.nonfinite_count:
        m[c.bad] = worst
    return m


def _sq(p, r):
    return np.square(p - r)


def _rel_sq(p, r):
    return np.square(p - r) / (np.square(r) + EPS_RELMSE)


def _smape(p, r):
    return np.abs(p - r) / (np.abs(p) + np.abs(r) + EPS_SMAPE)


def _abs(p, r):
    return np.abs(p - r)


def mean_of_map(pred, ref, map_of, worst: float) -> float:
    """A frame's score as the mean of its per-pixel map ``map_of(check_pair(pred, ref))``; ``worst``
    when the prediction has a non-finite value.

    Notes
    -----
    Validation's policy: a NaN or Inf in the prediction gives the worst score, never a mean over the
    finite pixels (a broken denoiser cannot average its failures away).
    """
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return worst
    return float(np.mean(map_of(c)))


def _scalar(c: Checked, per_value, name: str) -> float:
    if c.nonfinite_count:
        return WORST[name]
    return float(np.mean(_pixelwise_map(c, per_value, WORST[name])))


def mse(pred, ref) -> float:
    """Mean squared error over all pixels and channels, linear HDR. Perfect 0; lower is better."""
    return _scalar(check_pair(pred, ref), _sq, "mse")


def mse_map(pred, ref) -> np.ndarray:
    """Per-pixel squared error averaged over channels (H×W)."""
    return _pixelwise_map(check_pair(pred, ref), _sq, WORST["mse"])


def relmse(pred, ref) -> float:
    """Relative MSE ``mean((p−r)² / (r² + 0.01))`` per channel, linear HDR. Lower is better."""
    return _scalar(check_pair(pred, ref), _rel_sq, "relmse")


def relmse_map(pred, ref) -> np.ndarray:
    """Per-pixel ``(p−r)² / (r² + 0.01)`` averaged over channels (H×W)."""
    return _pixelwise_map(check_pair(pred, ref), _rel_sq, WORST["relmse"])


def smape(pred, ref) -> float:
    """SMAPE ``mean(|p−r| / (|p| + |r| + 0.01))`` per channel, linear HDR, in [0, 1). Lower is better."""
    return _scalar(check_pair(pred, ref), _smape, "smape")


def smape_map(pred, ref) -> np.ndarray:
    """Per-pixel SMAPE term averaged over channels (H×W)."""
    return _pixelwise_map(check_pair(pred, ref), _smape, WORST["smape"])


def l1(pred, ref) -> float:
    """Mean absolute error over pixels and channels, linear HDR. Lower is better."""
    return _scalar(check_pair(pred, ref), _abs, "l1")


def l1_map(pred, ref) -> np.ndarray:
    """Per-pixel absolute error averaged over channels (H×W)."""
    return _pixelwise_map(check_pair(pred, ref), _abs, WORST["l1"])


# --------------------------------------------------------------------------- tone-mapped scores


def psnr(pred, ref) -> float:
    """PSNR in dB of the tone-mapped images, peak 1: ``10·log10(1 / MSE)``. Higher is better.

    Identical images give ``+inf``; since tone-mapped values lie in [0, 1), PSNR ≥ 0 dB.
    Matches ``skimage.metrics.peak_signal_noise_ratio(tonemap(ref), tonemap(pred), data_range=1)``.
    """
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return WORST["psnr"]
    err = float(np.mean(np.square(tonemap(c.pred) - tonemap(c.ref))))
    if err == 0.0:
        return math.inf
    return 10.0 * math.log10(1.0 / err)


def _ssim_size_check(c: Checked) -> None:
    h, w = c.ref.shape[:2]
    if min(h, w) < SSIM_MIN_SIZE:
        raise MetricNotApplicable(
            f"SSIM needs images of at least {SSIM_MIN_SIZE}×{SSIM_MIN_SIZE} pixels "
            f"(its Gaussian window, σ = {SSIM_SIGMA}), got {h}×{w}"
        )


def _ssim(c: Checked, full: bool):
    _ssim_size_check(c)
    from skimage.metrics import structural_similarity

    return structural_similarity(
        tonemap(c.pred),
        tonemap(c.ref),
        gaussian_weights=True,
        sigma=SSIM_SIGMA,
        use_sample_covariance=False,
        data_range=1.0,
        channel_axis=-1,
        full=full,
    )


def ssim(pred, ref) -> float:
    """Mean SSIM of the tone-mapped images (scikit-image, Gaussian σ = 1.5, data_range = 1).

    Perfect 1; higher is better; in [-1, 1]. Needs H, W ≥ 11 (``ValueError`` otherwise).
    """
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        _ssim_size_check(c)
        return WORST["ssim"]
    return float(_ssim(c, full=False))


def ssim_map(pred, ref) -> np.ndarray:
    """Full SSIM map (H×W, channels averaged; borders included, unlike the scalar)."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        _ssim_size_check(c)
        return np.full(c.ref.shape[:2], WORST["ssim"])
    _, s = _ssim(c, full=True)
    return s.mean(axis=-1).astype(np.float64)


# --------------------------------------------------------------------------- HDR-FLIP


@functools.cache
def _flip_xmax() -> float:
    """FLIP's ``xMax`` (tone-mapped 0.85 pre-image, ACES): start exposure of a luminance-1 image."""
    import flip_evaluator

    one = np.ones((1, 1, 3), dtype=np.float32)
    _, _, params = flip_evaluator.evaluate(one, one, "HDR", applyMagma=False, computeMeanError=False)
    lum = float(one[0, 0] @ _REC709_LUMINANCE)
    return float(2.0 ** params["startExposure"]) * lum


def _flip_input(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.clip(a, 0.0, _F32_MAX), dtype=np.float32)


def _flip_parameters(ref32: np.ndarray, ppd) -> dict:
    params: dict = {}
    if ppd is not None:
        ppd = float(ppd)
        if not (math.isfinite(ppd) and ppd > 0):
            raise ValueError(f"FLIP's pixels per degree must be finite and positive, got {ppd}")
        params["ppd"] = ppd
    # Luminance ≥ 0.0722 · max channel, so only a dim reference needs its luminance computed.
    if 0.0722 * float(ref32.max()) < FLIP_BLACK_LUMINANCE:
        lum = (ref32.reshape(-1, 3) @ _REC709_LUMINANCE).astype(np.float64)
        y_max = float(lum.max())
        if y_max < FLIP_BLACK_LUMINANCE:
            mid = lum.size // 2  # FLIP takes the upper median (nth_element at size/2)
            y_median = float(np.partition(lum, mid)[mid])
            x_max = _flip_xmax()
            params["startExposure"] = math.log2(x_max / max(y_max, _F32_EPS))
            params["stopExposure"] = math.log2(x_max / max(y_median, _F32_EPS))
    return params


def _flip(c: Checked, ppd) -> np.ndarray:
    import flip_evaluator

    r = _flip_input(c.ref)
    p = _flip_input(c.pred)
    params = _flip_parameters(r, ppd)
    error_map, _, _ = flip_evaluator.evaluate(r, p, "HDR", applyMagma=False, computeMeanError=False, parameters=params)
    return error_map[..., 0]


def flip(pred, ref, ppd: float | None = None) -> float:
    """Mean HDR-FLIP error (flip-evaluator, linear HDR input), in [0, 1]. Lower is better.

    ``ppd``: pixels per degree (FLIP's default 67 when None). See the module Notes for the
    clamping and the black-reference case.
    """
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return WORST["flip"]
    return float(np.mean(_flip(c, ppd), dtype=np.float64))


def flip_map(pred, ref, ppd: float | None = None) -> np.ndarray:
    """Per-pixel HDR-FLIP error (H×W, float32 from the library)."""
    c = check_pair(pred, ref)
    if c.nonfinite_count:
        return np.full(c.ref.shape[:2], WORST["flip"])
    return _flip(c, ppd)


# --------------------------------------------------------------------------- ΔE2000


@functools.cache
def _colour():
    """colour-science, imported without OpenImageIO.

    colour's ``colour.io`` imports OpenImageIO where it is installed (the OIDN toolkit's peer check
    installs it) and keeps its ``TypeDesc`` objects in module globals, which outlive the interpreter's
    teardown: nanobind then prints ``leaked N instances!`` and ~20 more lines at every exit. ΔE2000 needs
    none of colour's image I/O, so OpenImageIO is masked while colour is imported (colour then takes it
    for missing) and left importable for anyone else afterwards.
    """
    masked = "OpenImageIO" not in sys.modules
    if masked:
        sys.modules["OpenImageIO"] = None  # an import of it raises ImportError meanwhile
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "Matplotlib related API features are not available"
            import colour
    finally:
        if masked and sys.modules.get("OpenImageIO", 0) is None:
            del sys.modules["OpenImageIO"]
    return colour


def linear_srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIE Lab (D65, L in [0, 100]) of *linear* sRGB values (no decoding), via colour-science."""
    colour = _colour()
    with colour.domain_range_scale("reference"):
        xyz = colour.RGB_to_XYZ(rgb, "sRGB", apply_cctf_decoding=False)
        return colour.XYZ_to_Lab(xyz, colour.RGB_COLOURSPACES["sRGB"].whitepoint)


def delta_e2000_lab(lab1: np.ndarray, lab2: np.ndarray) -> np.ndarray:
    """CIEDE2000 between Lab arrays (colour-science ``delta_E(..., method="CIE 2000")``)."""
    colour = _colour()
    with colour.domain_range_scale("reference"):
        return colour.delta_E(lab1, lab2, method="CIE 2000")


def _deltae_map(c: Checked) -> np.ndarray:
    pred = np.where(c.bad[..., None], c.ref, c.pred) if c.nonfinite_count else c.pred
    m = np.asarray(delta_e2000_lab(linear_srgb_to_lab(reinhard(pred)), linear_srgb_to_lab(reinhard(c.ref))))
    if c.nonfinite_count:
        m = m.copy()
        m[c.bad] = WORST["deltae2000"]
    return m


def deltae2000(pred, ref) -> float:
    """Mean CIEDE2000 after the Reinhard stage of the tone map (see Notes). Lower is better."""
    return mean_of_map(pred, ref, _deltae_map, WORST["deltae2000"])


def deltae2000_map(pred, ref) -> np.ndarray:
    """Per-pixel CIEDE2000 (H×W); +inf at pixels with a non-finite channel."""
    return _deltae_map(check_pair(pred, ref))


# --------------------------------------------------------------------------- entries

METRICS: tuple[Metric, ...] = (
    Metric(
        name="mse",
        fn=mse,
        map_fn=mse_map,
        higher_is_better=False,
        domain="linear",
        kind="spatial",
        worst=math.inf,
        perfect=0.0,
        description="mean squared error",
        aggregate="geomean",
        floor_fn=mse_floor,
    ),
    Metric(
        name="relmse",
        fn=relmse,
        map_fn=relmse_map,
        higher_is_better=False,
        domain="linear",
        kind="spatial",
        worst=math.inf,
        perfect=0.0,
        description="mean((p-r)^2 / (r^2 + 0.01))",
        floor_fn=relmse_floor,
    ),
    Metric(
        name="smape",
        fn=smape,
        map_fn=smape_map,
        higher_is_better=False,
        domain="linear",
        kind="spatial",
        worst=1.0,  # each term is < 1
        perfect=0.0,
        description="mean(|p-r| / (|p| + |r| + 0.01))",
    ),
    Metric(
        name="l1",
        fn=l1,
        map_fn=l1_map,
        higher_is_better=False,
        domain="linear",
        kind="spatial",
        worst=math.inf,
        perfect=0.0,
        description="mean absolute error",
        aggregate="geomean",
    ),
    Metric(
        name="psnr",
        fn=psnr,
        higher_is_better=True,
        domain="tonemapped",
        kind="spatial",
        worst=0.0,  # tone-mapped values lie in [0, 1): MSE ≤ 1
        perfect=math.inf,
        description="PSNR of tone-mapped images, peak 1",
        unit="dB",
    ),
    Metric(
        name="ssim",
        fn=ssim,
        map_fn=ssim_map,
        higher_is_better=True,
        domain="tonemapped",
        kind="spatial",
        worst=-1.0,
        perfect=1.0,
        description="SSIM (scikit-image, Gaussian sigma 1.5, data_range 1)",
    ),
    Metric(
        name="flip",
        fn=flip,
        map_fn=flip_map,
        higher_is_better=False,
        domain="linear",
        kind="spatial",
        worst=1.0,  # FLIP lies in [0, 1]
        perfect=0.0,
        description="HDR-FLIP (flip-evaluator)",
    ),
    Metric(
        name="deltae2000",
        fn=deltae2000,
        map_fn=deltae2000_map,
        higher_is_better=False,
        domain="reinhard",
        kind="spatial",
        worst=math.inf,
        perfect=0.0,
        description="CIEDE2000 (colour-science) of Reinhard-mapped linear sRGB",
    ),
)

#: Worst value of each metric, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
