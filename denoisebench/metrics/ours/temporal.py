"""Temporal (flicker) metrics of a sequence: T×H×W×3 arrays or lists of H×W×3 frames, T ≥ 2.

Each metric's entry (direction, domain, worst value for a non-finite prediction, aggregation,
context keywords, floor) is declared once, in :data:`METRICS` at the end of this module;
:data:`WORST` is derived from it.

Notes
-----
* ``temporal_l1`` = mean over pairs t = 1..T−1, pixels and channels of
  ``|(p_t − p_{t−1}) − (r_t − r_{t−1})|``, pooled (every valid pixel of every pair weighs the
  same). It is 0 when p = r and when p = r + c for a constant c.
* ``temporal_l1_warped``: the same with frame t−1 warped to frame t by frame t's motion buffer.
  Motion convention (docs/architecture.md): ``motion[t]`` is H×W×2, (x, y) in pixels from a pixel of frame t
  to where its surface point was in frame t−1. Pixel (row i, col j) has its centre at
  (x = j + 0.5, y = i + 0.5); its previous position is (j + 0.5 + mx, i + 0.5 + my) and the
  warped frame samples frame t−1 there **bilinearly** (edge-clamped within the outer half pixel).
  ``motion[0]`` is unused but must be given (one buffer per frame, like ``Frame.buffers``).
  Since warping is linear and its weights sum to 1, p = r + c still gives 0.
* Disocclusion (pixels left out of the mean):
  1. the previous position falls outside the image rectangle [0, W] × [0, H];
  2. with ``depth`` (one H×W or H×W×1 camera-space depth per frame): the depth test. A pixel
     is kept only if every bilinear tap it reads from frame t−1 (every tap with non-zero weight)
     has ``|depth[t−1][tap] − depth[t][pixel]| ≤ depth_tolerance · |depth[t][pixel]|``
     (default 0.1, relative). The test compares camera-space depths of two frames, so it
     assumes the camera moves little along its axis between frames (a pan or small dolly);
     that is the usual TAA heuristic, not an exact reprojection;
  3. with ``masks`` (bool, True = counts; one H×W for all frames or one per frame): pair t uses
     ``masks[t]``.
  A sequence where no pixel survives is a ``ValueError`` (there is nothing to measure).
  Maps are (T−1)×H×W with 0 at masked pixels; :func:`warped_valid_masks` gives the masks.
* ``temporal_relmse`` (relMSE in spirit, scale-free: a scene 100× brighter scores the same):
  mean over pairs t, valid pixels and channels of ``(Δp − Δr)² / (m_t² + 0.01)`` with the
  **warped** frame differences Δp = p_t − W(p_{t−1}), Δr = r_t − W(r_{t−1}) (W: frame t's motion,
  disocclusions masked exactly as ``temporal_l1_warped``) and m_t the reference's **local
  magnitude** over the two frames compared: the larger of the 3×3 box mean of |r_t| and the warped
  3×3 box mean of |r_{t−1}|, W(box|r_{t−1}|), per channel (edges replicated). The local mean keeps
  one bright reference pixel, and the reference's own noise, out of the denominator (its noise
  variance there is 1/9 of a pixel's). Both frames enter it because both enter the numerator:
  with frame t's magnitude alone, a value the warp carries from a bright pixel of frame t−1 onto a
  pixel whose neighbourhood is black in frame t was divided by 0.01. Measured on the demo's
  glossy_fireflies (small emitters of radiance ~1e4 in front of a black background; the
  background's motion, −2.9 px per frame, is not the emitters', −0.6 px, so the warp reads the
  emitter into background pixels, a disocclusion the mask does not see): 10–19 pixels per frame
  pair scored 1e8–1e10, every denoiser's flicker was ~1.5e5 and the noisy input's stayed at
  1e3–7e5 per pair at 1, 4 and 16 spp; with both frames' magnitude the input's robust flicker is
  0.34–0.80 at 1 spp, 0.11–0.18 at 4, 0.036–0.051 at 16 (bench/flicker_pairs.py). ``motion`` is optional: without it W is the identity,
  which is right for a static camera only. Pairs whose frames are both bright and flat score
  like relMSE of the frame difference; the 0.01 is relMSE's.
* ``temporal_relmse_floor``: its reference-noise floor (see ``floors``). For a perfect
  prediction Δp − Δr = −(n_t − W(n_{t−1})), of variance V = v_t + W₂(v_{t−1}) where W₂ warps
  with the **squared** bilinear weights (independent noise per pixel and frame). Floor =
  mean(V / (m_t² + 0.01)), m_t as above. Frame t's noise enters pairs t and t+1, so the counted values are
  not independent: the se multiplies the summed variance by 3, a bound for a chain whose
  neighbours alone correlate (Var ΣX ≤ ΣVar + 2Σ|Cov| ≤ 3ΣVar).
* ``tpsnr``: PSNR (peak 1) of the tone-mapped frame differences,
  ``10·log10(1 / mean(((T(p_t) − T(p_{t−1})) − (T(r_t) − T(r_{t−1})))²))`` pooled over pairs,
  T the documented tone map. Identical sequences give +inf. Because the tone map is non-linear,
  p = r + c gives +inf only for a static reference; frame differences lie in (−1, 1), so
  tPSNR ≥ 20·log10(1/2).
* Motion and depth must be finite (``ValueError`` otherwise); a prediction with NaN/Inf in any
  frame gives the worst value (maps: worst everywhere).
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.metrics.floors.closed_form import EPS_RELMSE, Floor, as_variance, squared_error_floor
from denoisebench.metrics.metric import Metric, worst_values
from denoisebench.metrics.tonemap import tonemap
from denoisebench.metrics.validation import Checked, as_depth, as_mask, as_motion, check_sequences

# Lazy imports: scipy (0.3 s) is imported inside the functions that need it.

__all__ = [
    "DEPTH_TOLERANCE",
    "METRICS",
    "WORST",
    "warp_previous",
    "disocclusion_mask",
    "warped_valid_masks",
    "temporal_l1",
    "temporal_l1_map",
    "temporal_l1_warped",
    "temporal_l1_warped_map",
    "temporal_relmse",
    "temporal_relmse_map",
    "temporal_relmse_floor",
    "tpsnr",
]

DEPTH_TOLERANCE = 0.1
#: The relMSE epsilon, also in temporal_relmse's denominator.
EPS_TEMPORAL_RELMSE = EPS_RELMSE


# --------------------------------------------------------------------------- warping


def _taps(motion: np.ndarray):
    """Bilinear taps of the previous positions: (i0, i1, j0, j1, fy, fx, inside)."""
    h, w = motion.shape[:2]
    x = np.arange(w, dtype=np.float64)[None, :] + 0.5 + motion[..., 0]
    y = np.arange(h, dtype=np.float64)[:, None] + 0.5 + motion[..., 1]
    inside = (x >= 0.0) & (x <= w) & (y >= 0.0) & (y <= h)
    u = np.clip(x - 0.5, 0.0, w - 1)  # continuous column index of the sample
    v = np.clip(y - 0.5, 0.0, h - 1)
    j0 = np.floor(u).astype(np.intp)
    i0 = np.floor(v).astype(np.intp)
    fx = u - j0
    fy = v - i0
    j1 = np.minimum(j0 + 1, w - 1)
    i1 = np.minimum(i0 + 1, h - 1)
    return i0, i1, j0, j1, fy, fx, inside


def _bilinear(img: np.ndarray, taps) -> np.ndarray:
    i0, i1, j0, j1, fy, fx, _ = taps
    if img.ndim == 3:
        fx = fx[..., None]
        fy = fy[..., None]
    top = img[i0, j0] * (1.0 - fx) + img[i0, j1] * fx
    bottom = img[i1, j0] * (1.0 - fx) + img[i1, j1] * fx
    return top * (1.0 - fy) + bottom * fy


def warp_previous(prev: np.ndarray, motion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Warp frame t−1 (H×W×C or H×W) to frame t with frame t's motion (H×W×2), bilinearly.

    Returns the warped frame (float64) and the H×W mask of pixels whose previous position lies
    inside the image (the rest are disoccluded; their warped value is edge-clamped).
    """
    prev = np.asarray(prev, dtype=np.float64)
    motion = np.asarray(motion, dtype=np.float64)
    if motion.ndim != 3 or motion.shape[2] != 2 or motion.shape[:2] != prev.shape[:2]:
        raise ValueError(f"motion must be H×W×2 matching the frame {prev.shape[:2]}, got {motion.shape}")
    if not np.isfinite(motion).all():
        raise ValueError("motion has non-finite values (NaN/Inf)")
    taps = _taps(motion)
    return _bilinear(prev, taps), taps[6]


def _depth_ok(taps, depth_now: np.ndarray, depth_prev: np.ndarray, tol: float) -> np.ndarray:
    i0, i1, j0, j1, fy, fx, _ = taps
    limit = tol * np.abs(depth_now)
    ok = np.ones(depth_now.shape, dtype=bool)
    for ii, jj, weight in (
        (i0, j0, (1 - fy) * (1 - fx)),
        (i0, j1, (1 - fy) * fx),
        (i1, j0, fy * (1 - fx)),
        (i1, j1, fy * fx),
    ):
        ok &= (weight == 0) | (np.abs(depth_prev[ii, jj] - depth_now) <= limit)
    return ok


def disocclusion_mask(
    motion: np.ndarray,
    depth: np.ndarray | None = None,
    prev_depth: np.ndarray | None = None,
    depth_tolerance: float = DEPTH_TOLERANCE,
) -> np.ndarray:
    """H×W bool, True where frame t's pixel is visible in frame t−1 (see module Notes).

    ``depth``/``prev_depth``: H×W depth of frames t and t−1 for the depth test (both or neither).
    """
    motion = np.asarray(motion, dtype=np.float64)
    if motion.ndim != 3 or motion.shape[2] != 2:
        raise ValueError(f"motion must be H×W×2, got {motion.shape}")
    if not np.isfinite(motion).all():
        raise ValueError("motion has non-finite values (NaN/Inf)")
    taps = _taps(motion)
    valid = taps[6].copy()
    if (depth is None) != (prev_depth is None):
        raise ValueError("the depth test needs both depth and prev_depth")
    if depth is not None:
        d = np.asarray(depth, dtype=np.float64).reshape(motion.shape[:2])
        dp = np.asarray(prev_depth, dtype=np.float64).reshape(motion.shape[:2])
        valid &= _depth_ok(taps, d, dp, depth_tolerance)
    return valid


# --------------------------------------------------------------------------- helpers


def _context(c: Checked, motion, depth, masks, tol):
    n, h, w = c.pred.shape[:3]
    mask = None if masks is None else as_mask(masks, n, (h, w))
    mot = None if motion is None else as_motion(motion, n, (h, w))
    dep = None if depth is None else as_depth(depth, n, (h, w))
    if dep is not None and mot is None:
        raise ValueError("depth is only used with motion (the warped temporal error)")
    if not (math.isfinite(tol) and tol >= 0):
        raise ValueError(f"depth_tolerance must be finite and ≥ 0, got {tol}")
    return mask, mot, dep


def _pair_maps(c: Checked, mask, mot, dep, tol) -> tuple[np.ndarray, np.ndarray]:
    """Per-pair |Δp − Δr| maps (T−1)×H×W (channel mean) and validity masks."""
    e = c.pred.astype(np.float64) - c.ref  # Δp − Δr = e_t − e_{t−1} (warping is linear)
    n, h, w = e.shape[:3]
    maps = np.empty((n - 1, h, w))
    valid = np.ones((n - 1, h, w), dtype=bool)
    for t in range(1, n):
        if mot is None:
            prev = e[t - 1]
        else:
            taps = _taps(mot[t].astype(np.float64))
            prev = _bilinear(e[t - 1], taps)
            valid[t - 1] = taps[6]
            if dep is not None:
                valid[t - 1] &= _depth_ok(taps, dep[t].astype(np.float64), dep[t - 1].astype(np.float64), tol)
        maps[t - 1] = np.abs(e[t] - prev).mean(axis=-1)
        if mask is not None:
            valid[t - 1] &= mask[t]
    return maps, valid


def _pooled(maps: np.ndarray, valid: np.ndarray) -> float:
    count = int(np.count_nonzero(valid))
    if count == 0:
        raise ValueError("no pixel is left after masking and disocclusion: nothing to measure")
    return float(maps[valid].mean()) if count < valid.size else float(maps.mean())


def warped_valid_masks(motion, depth=None, masks=None, depth_tolerance: float = DEPTH_TOLERANCE) -> np.ndarray:
    """(T−1)×H×W masks of the pixels ``temporal_l1_warped`` counts, from T motion buffers."""
    mot = np.asarray(motion, dtype=np.float64)
    if mot.ndim != 4 or mot.shape[3] != 2 or mot.shape[0] < 2:
        raise ValueError(f"motion must be T×H×W×2 with T ≥ 2, got {mot.shape}")
    n, h, w = mot.shape[:3]
    mot = as_motion(mot, n, (h, w))
    dep = None if depth is None else as_depth(depth, n, (h, w))
    mask = None if masks is None else as_mask(masks, n, (h, w))
    out = np.empty((n - 1, h, w), dtype=bool)
    for t in range(1, n):
        out[t - 1] = disocclusion_mask(
            mot[t], None if dep is None else dep[t], None if dep is None else dep[t - 1], depth_tolerance
        )
        if mask is not None:
            out[t - 1] &= mask[t]
    return out


# --------------------------------------------------------------------------- metrics


def _masked_pair_maps(c: Checked, mask, mot, dep, depth_tolerance: float, worst: float) -> np.ndarray:
    """(T−1)×H×W per-pair |Δp − Δr| maps (:func:`_pair_maps`) with 0 where a pixel is not measured;
    ``worst`` everywhere when the prediction has a non-finite value (validation's policy)."""
    n, h, w = c.pred.shape[:3]
    if c.nonfinite_count:
        return np.full((n - 1, h, w), worst)
    maps, valid = _pair_maps(c, mask, mot, dep, depth_tolerance)
    return np.where(valid, maps, 0.0)


def temporal_l1(pred_seq, ref_seq, *, masks=None) -> float:
    """Mean |(p_t − p_{t−1}) − (r_t − r_{t−1})| over pairs, pixels, channels (linear). Lower is better."""
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    mask, _, _ = _context(c, None, None, masks, DEPTH_TOLERANCE)
    if c.nonfinite_count:
        return WORST["temporal_l1"]
    return _pooled(*_pair_maps(c, mask, None, None, DEPTH_TOLERANCE))


def temporal_l1_map(pred_seq, ref_seq, *, masks=None) -> np.ndarray:
    """(T−1)×H×W maps of |Δp − Δr| (channel mean); 0 where ``masks`` excludes a pixel."""
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    mask, _, _ = _context(c, None, None, masks, DEPTH_TOLERANCE)
    return _masked_pair_maps(c, mask, None, None, DEPTH_TOLERANCE, WORST["temporal_l1"])


def temporal_l1_warped(
    pred_seq, ref_seq, motion, *, depth=None, masks=None, depth_tolerance: float = DEPTH_TOLERANCE
) -> float:
    """``temporal_l1`` after warping frame t−1 by frame t's motion, disoccluded pixels masked."""
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    if motion is None:
        raise ValueError("temporal_l1_warped needs the motion buffers (one H×W×2 per frame)")
    mask, mot, dep = _context(c, motion, depth, masks, depth_tolerance)
    if c.nonfinite_count:
        return WORST["temporal_l1_warped"]
    return _pooled(*_pair_maps(c, mask, mot, dep, depth_tolerance))


def temporal_l1_warped_map(
    pred_seq, ref_seq, motion, *, depth=None, masks=None, depth_tolerance: float = DEPTH_TOLERANCE
) -> np.ndarray:
    """(T−1)×H×W warped |Δp − Δr| maps; 0 at disoccluded or masked pixels."""
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    if motion is None:
        raise ValueError("temporal_l1_warped needs the motion buffers (one H×W×2 per frame)")
    mask, mot, dep = _context(c, motion, depth, masks, depth_tolerance)
    return _masked_pair_maps(c, mask, mot, dep, depth_tolerance, WORST["temporal_l1_warped"])


def _bilinear_squared(img: np.ndarray, taps) -> np.ndarray:
    """Like :func:`_bilinear` with squared weights: the variance of a bilinear mix of independent values."""
    i0, i1, j0, j1, fy, fx, _ = taps
    if img.ndim == 3:
        fx = fx[..., None]
        fy = fy[..., None]
    wx0, wx1, wy0, wy1 = np.square(1.0 - fx), np.square(fx), np.square(1.0 - fy), np.square(fy)
    return (img[i0, j0] * wx0 + img[i0, j1] * wx1) * wy0 + (img[i1, j0] * wx0 + img[i1, j1] * wx1) * wy1


def _local_magnitude(ref_frame: np.ndarray) -> np.ndarray:
    from scipy.ndimage import uniform_filter

    return uniform_filter(np.abs(ref_frame), size=(3, 3, 1), mode="nearest")


def _relative_pairs(c: Checked, mask, mot, dep, tol, ref_var=None):
    """Per-pair (Δp − Δr) (T−1)×H×W×3, denominators m²+0.01, validity (T−1)×H×W, and noise variance V."""
    e = c.pred.astype(np.float64) - c.ref
    ref = c.ref.astype(np.float64)
    n, h, w = e.shape[:3]
    diff = np.empty((n - 1, h, w, e.shape[3]))
    denom = np.empty_like(diff)
    var = None if ref_var is None else np.empty_like(diff)
    valid = np.ones((n - 1, h, w), dtype=bool)
    for t in range(1, n):
        if mot is None:
            prev = e[t - 1]
            prev_var = None if ref_var is None else ref_var[t - 1]
        else:
            taps = _taps(mot[t].astype(np.float64))
            prev = _bilinear(e[t - 1], taps)
            prev_var = None if ref_var is None else _bilinear_squared(ref_var[t - 1], taps)
            valid[t - 1] = taps[6]
            if dep is not None:
                valid[t - 1] &= _depth_ok(taps, dep[t].astype(np.float64), dep[t - 1].astype(np.float64), tol)
        diff[t - 1] = e[t] - prev
        before = _local_magnitude(ref[t - 1])
        if mot is not None:
            before = _bilinear(before, taps)
        # both frames' local magnitude (module Notes): a value carried from a bright pixel of frame t−1
        # is measured against that brightness, not against frame t's black neighbourhood
        denom[t - 1] = np.square(np.maximum(_local_magnitude(ref[t]), before)) + EPS_TEMPORAL_RELMSE
        if var is not None:
            var[t - 1] = ref_var[t] + prev_var
        if mask is not None:
            valid[t - 1] &= mask[t]
    return diff, denom, valid, var


def _relative_setup(pred_seq, ref_seq, motion, depth, masks, depth_tolerance):
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    mask, mot, dep = _context(c, motion, depth, masks, depth_tolerance)
    return c, mask, mot, dep


def temporal_relmse(
    pred_seq, ref_seq, motion=None, *, depth=None, masks=None, depth_tolerance: float = DEPTH_TOLERANCE
) -> float:
    """Scale-free flicker: mean (Δp − Δr)² / (m² + 0.01) over warped frame differences (module Notes)."""
    c, mask, mot, dep = _relative_setup(pred_seq, ref_seq, motion, depth, masks, depth_tolerance)
    if c.nonfinite_count:
        return WORST["temporal_relmse"]
    diff, denom, valid, _ = _relative_pairs(c, mask, mot, dep, depth_tolerance)
    return _pooled((np.square(diff) / denom).mean(axis=-1), valid)


def temporal_relmse_map(
    pred_seq, ref_seq, motion=None, *, depth=None, masks=None, depth_tolerance: float = DEPTH_TOLERANCE
) -> np.ndarray:
    """(T−1)×H×W maps of (Δp − Δr)²/(m² + 0.01) (channel mean); 0 at disoccluded or masked pixels."""
    c, mask, mot, dep = _relative_setup(pred_seq, ref_seq, motion, depth, masks, depth_tolerance)
    n, h, w = c.pred.shape[:3]
    if c.nonfinite_count:
        return np.full((n - 1, h, w), WORST["temporal_relmse"])
    diff, denom, valid, _ = _relative_pairs(c, mask, mot, dep, depth_tolerance)
    return np.where(valid, (np.square(diff) / denom).mean(axis=-1), 0.0)


def temporal_relmse_floor(
    pred_seq, ref_seq, ref_var, motion=None, *, depth=None, masks=None, depth_tolerance: float = DEPTH_TOLERANCE
) -> Floor:
    """Reference-noise floor and se of :func:`temporal_relmse` from the T reference variance buffers."""
    c, mask, mot, dep = _relative_setup(pred_seq, ref_seq, motion, depth, masks, depth_tolerance)
    v = as_variance(ref_var, c.ref.shape)
    pred = np.where(np.isfinite(c.pred), c.pred, np.nan)
    diff, denom, valid, var = _relative_pairs(c._replace(pred=pred), mask, mot, dep, depth_tolerance, v)
    return squared_error_floor(diff, var, denom, valid=valid[..., None], correlation=3.0)


def tpsnr(pred_seq, ref_seq, *, masks=None) -> float:
    """PSNR (dB, peak 1) of tone-mapped frame differences, pooled over pairs. Higher is better."""
    c = check_sequences(pred_seq, ref_seq, min_frames=2)
    mask, _, _ = _context(c, None, None, masks, DEPTH_TOLERANCE)
    if c.nonfinite_count:
        return WORST["tpsnr"]
    tp = tonemap(c.pred)
    tr = tonemap(c.ref)
    d = np.diff(tp, axis=0) - np.diff(tr, axis=0)
    sq = np.mean(np.square(d), axis=-1)
    if mask is not None:
        valid = np.asarray(mask[1:])
        if not valid.any():
            raise ValueError("no pixel is left after masking: nothing to measure")
        err = float(sq[valid].mean())
    else:
        err = float(sq.mean())
    if err == 0.0:
        return math.inf
    return 10.0 * math.log10(1.0 / err)


# --------------------------------------------------------------------------- entries

METRICS: tuple[Metric, ...] = (
    Metric(
        name="temporal_l1",
        fn=temporal_l1,
        map_fn=temporal_l1_map,
        higher_is_better=False,
        domain="linear",
        kind="temporal",
        worst=math.inf,
        perfect=0.0,
        description="mean |(p_t - p_t-1) - (r_t - r_t-1)|",
        accepts=("masks",),
        aggregate="relative_to_input",
    ),
    Metric(
        name="temporal_l1_warped",
        fn=temporal_l1_warped,
        map_fn=temporal_l1_warped_map,
        higher_is_better=False,
        domain="linear",
        kind="temporal",
        worst=math.inf,
        perfect=0.0,
        description="temporal_l1 with frame t-1 warped by the motion buffer, disocclusions masked",
        accepts=("motion", "depth", "masks"),
        requires=("motion",),
        aggregate="relative_to_input",
    ),
    Metric(
        name="temporal_relmse",
        fn=temporal_relmse,
        map_fn=temporal_relmse_map,
        higher_is_better=False,
        domain="linear",
        kind="temporal",
        worst=math.inf,
        perfect=0.0,
        description="mean((dp - dr)^2 / (m^2 + 0.01)), warped frame differences, m = larger 3x3 mean |r| of the two frames",
        accepts=("motion", "depth", "masks"),
        floor_fn=temporal_relmse_floor,
    ),
    Metric(
        name="tpsnr",
        fn=tpsnr,
        higher_is_better=True,
        domain="tonemapped",
        kind="temporal",
        worst=20.0 * math.log10(0.5),  # tone-mapped frame differences lie in (-1, 1): MSE < 4
        perfect=math.inf,
        description="PSNR of tone-mapped frame differences, peak 1",
        unit="dB",
        accepts=("masks",),
    ),
)

#: Worst value of each metric, returned for a prediction with NaN/Inf (from :data:`METRICS`).
WORST: dict[str, float] = worst_values(METRICS)
