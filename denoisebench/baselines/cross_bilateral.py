"""Cross (joint) bilateral filter over screen position, color and feature buffers, vectorised in numpy.

Weight of neighbour q for pixel p (the lecture slides' cross-bilateral form, with the colour
distance normalised by the noise)::

    w(p, q) = exp(-|p - q|² / 2σ_s²)
            · exp(-|c_p - c_q|² / (2σ_c² · (2·min(V̄_p, V̄_q) + ε)))
            · Π_k exp(-|f_k,p - f_k,q|² / 2σ_k,eff²)         σ_k,eff² = (σ_k·s_k)² + 2·median(Var f_k)

* ``V̄`` is the per-pixel variance of the mean colour (``color_var``, averaged over channels; when
  the frame has none, or it is all zero as at 1 spp, a robust local spread: (1.4826·MAD)² over 5×5),
  smoothed by two 3×3 medians (so that neither a firefly's own variance nor a noisy variance
  estimate opens the filter). ``|c_p - c_q|²`` of two pixels of one flat region has mean
  2·V̄·channels, so σ_c counts noise standard deviations (a variance-stabilised colour distance).
  ε = (0.01·mean colour)² + 1e-12 keeps noise-free regions finite.
* Bright, noisy neighbours: a pair is measured against the smaller of its two noise levels. A
  pixel whose own samples agree that it is dark (tight variance) then takes nothing from a
  highlight next to it, however noisy the highlight is; normalising by the pair's sum, or by a
  mean-smoothed V̄, lets the highlight bleed into the dark floor around it (measured on a
  128 px, 4 spp glossy_fireflies frame: relMSE 35 against the input's 0.055; 0.011 with the min).
* ``s_k`` is a feature's scale: 1 for albedo, normal and roughness (their values are already in
  [0, 1] or unit length), and the median of the frame's depth (depth) or of the spread of the
  world positions (position), so the same σ_k works at any scene scale. Per-feature variance
  buffers (``<feature>_var``, e.g. from depth of field) widen σ_k by the frame's median variance.
* Each pair (p, q) is evaluated once and used for both pixels (the weight is symmetric); pixels
  outside the image take no part (no edge padding). The output is Σ w c / Σ w, a convex
  combination of the (sanitised, non-negative) input, so it is finite and non-negative.
* The pairs are evaluated in row strips on several threads (``_accumulate``), each with its own
  sums; the result is reproducible for a given number of CPUs and equal across CPU counts to
  float32 rounding.

Fireflies: a symmetric weight cannot both keep a firefly out of its neighbours and let the
neighbours into the firefly, so an isolated bright pixel would survive the filter unchanged. Before
filtering, a pixel whose weights to its 8 neighbours sum to less than ``firefly_support`` (0.2) and
that is brighter than its 3×3 median is replaced by that median (then the guide is rebuilt). This
removes energy (a bias, as every firefly clamp does). Measured on rendered 4 spp frames (64 and
128 px; input relMSE, then without → with it): dim_room 3.16, 3.12 → 0.125; depth_of_field 0.79,
0.75 → 0.26; glossy_fireflies 0.24, 0.17 → 0.030; texture_checker 0.161, 0.116 → 0.082; cornell
0.183, 0.020 → 0.018. ``firefly_support=None`` turns it off.

Defaults (``σ_c`` is in noise standard deviations):

==========  ======  =====  =========  =====  =========================================  ==========
preset      radius  σ_s    window     σ_c    features (σ_k)                             guide dims
==========  ======  =====  =========  =====  =========================================  ==========
fast        5       2.5    separable  6.0    albedo 0.1, normal 0.3                     PCA → 3
balanced    7       3.5    separable  6.0    albedo 0.1, normal 0.3, depth 0.03         all
high        8       4.0    full 2-D   6.0    + roughness 0.15                           all
==========  ======  =====  =========  =====  =========================================  ==========

"separable" runs a horizontal then a vertical 1-D pass over the same (2r+1)² window: 4r
pair evaluations per pixel instead of 2r(r+1), the classic separable bilateral approximation
(Pham & van Vliet 2005). "PCA → 3" projects the scaled feature guide onto its three principal
directions (distances within that subspace are kept, the rest is dropped).
Features the frame lacks are skipped, so the filter also runs on color alone.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np
from scipy import ndimage

from denoisebench.baselines.threads import available_threads
from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.protocol import DenoiserBase

DEFAULT_FEATURE_SIGMAS: dict[str, float] = {
    "albedo": 0.1,
    "normal": 0.3,
    "depth": 0.03,  # relative to the frame's median depth
    "position": 4.0,  # in one-pixel steps of the world position (the frame's median step)
    "roughness": 0.15,
}

PRESETS: dict[str, dict] = {
    "fast": dict(
        radius=5, sigma_spatial=2.5, separable=True, sigma_color=6.0, features=("albedo", "normal"), guide_dims=3
    ),
    "balanced": dict(
        radius=7,
        sigma_spatial=3.5,
        separable=True,
        sigma_color=6.0,
        features=("albedo", "normal", "depth"),
        guide_dims=None,
    ),
    "high": dict(
        radius=8,
        sigma_spatial=4.0,
        separable=False,
        sigma_color=6.0,
        features=("albedo", "normal", "depth", "roughness"),
        guide_dims=None,
    ),
}

FIREFLY_SUPPORT = 0.2  # see the module docstring, "Fireflies"
_STRIP_PIXELS = 32768  # pixels per row strip: keeps a strip's working set in cache
_MIN_PIXELS_PER_WORKER = 16384  # below this a thread costs more than it saves


def window_offsets(radius: int, sigma_spatial: float, separable: bool) -> list[list[tuple[int, int, float]]]:
    """Half-window offsets (dy, dx, spatial exponent) per pass: one pass (full) or two (separable)."""
    two_s2 = 2.0 * float(sigma_spatial) ** 2
    if separable:
        horizontal = [(0, d, d * d / two_s2) for d in range(1, radius + 1)]
        vertical = [(d, 0, d * d / two_s2) for d in range(1, radius + 1)]
        return [horizontal, vertical]
    half = [
        (dy, dx, (dy * dy + dx * dx) / two_s2)
        for dy in range(0, radius + 1)
        for dx in range(-radius, radius + 1)
        if dy > 0 or dx > 0
    ]
    return [half]


class Guide(NamedTuple):
    """What the range weight is computed from (float32, C-contiguous).

    ``features`` D×H×W, scaled so that their part of the exponent is Σ_d (g_p,d - g_q,d)²;
    ``color`` 3×H×W, the (firefly-suppressed) noisy colour; ``color_precision`` H×W,
    1 / (2 σ_c² (2 V̄ + ε)), of which a pair uses the larger (the smaller noise)."""

    features: np.ndarray
    color: np.ndarray
    color_precision: np.ndarray

    def log_weight(self, p: tuple[int, int], q: tuple[int, int]) -> float:
        """−(range exponent) of one pair of pixels (y, x): the reference formula, in float64."""
        f = self.features[:, p[0], p[1]].astype(np.float64) - self.features[:, q[0], q[1]]
        c = self.color[:, p[0], p[1]].astype(np.float64) - self.color[:, q[0], q[1]]
        precision = max(float(self.color_precision[p]), float(self.color_precision[q]))
        return -float(np.sum(f * f)) - float(np.sum(c * c)) * precision


def joint_bilateral_pass(color: np.ndarray, guide: Guide, offsets: Iterable[tuple[int, int, float]]) -> np.ndarray:
    """One filtering pass of ``color`` (C×H×W) with the range weights of ``guide`` over the half
    window ``offsets``. Returns C×H×W."""
    num, den = _accumulate(color, guide, offsets)
    num /= den
    return num


def _accumulate(color: np.ndarray, guide: Guide, offsets: Iterable[tuple[int, int, float]]):
    """(Σ_q w c_q over the window including the pixel itself (C×H×W), Σ_q w (H×W)); see above.

    The (row strip, offset) pairs are dealt round-robin to up to ``_workers()`` threads, each
    summing into its own accumulators (numpy's ufuncs release the GIL; a pair writes rows of
    two strips, so shared accumulators would race). The partial sums are added in a fixed order,
    so a given thread count always gives the same bytes."""
    channels, height, width = color.shape
    offsets = list(offsets)
    rows = max(1, _STRIP_PIXELS // max(width, 1))
    tasks = [(y0, offset) for y0 in range(0, height, rows) for offset in offsets]
    workers = max(1, min(_workers(), len(tasks), height * width // _MIN_PIXELS_PER_WORKER))
    partials = [np.zeros((channels, height, width), np.float32) for _ in range(workers)]
    dens = [np.zeros((height, width), np.float32) for _ in range(workers)]
    partials[0] += color
    dens[0] += 1.0
    if workers == 1:
        _accumulate_tasks(color, guide, tasks, rows, partials[0], dens[0])
    else:
        with ThreadPoolExecutor(workers) as pool:
            futures = [
                pool.submit(_accumulate_tasks, color, guide, tasks[k::workers], rows, partials[k], dens[k])
                for k in range(workers)
            ]
            for future in futures:
                future.result()
    num, den = partials[0], dens[0]
    for k in range(1, workers):
        num += partials[k]
        den += dens[k]
    return num, den


def _workers() -> int:
    """Threads for the filter (patched in tests)."""
    return available_threads()


def _accumulate_tasks(color, guide: Guide, tasks, rows: int, num: np.ndarray, den: np.ndarray) -> None:
    """Add the pairs of ``tasks`` ((strip top row, (dy, dx, spatial exponent))) into ``num``/``den``."""
    channels, height, width = color.shape
    features, guide_color, precision = guide
    depth = features.shape[0]
    diff_buf = np.empty((max(depth, 3), rows, width), np.float32)
    weight_buf = np.empty((rows, width), np.float32)
    pair_buf = np.empty((rows, width), np.float32)
    tmp_buf = np.empty((channels, rows, width), np.float32)
    for y0, (dy, dx, spatial) in tasks:
        y1 = min(y0 + rows, height - dy)
        x0, x1 = max(0, -dx), width - max(0, dx)
        if y1 <= y0 or x1 <= x0:
            continue
        n, m = y1 - y0, x1 - x0
        p = (slice(None), slice(y0, y1), slice(x0, x1))
        q = (slice(None), slice(y0 + dy, y1 + dy), slice(x0 + dx, x1 + dx))
        w = weight_buf[:n, :m]
        pair = pair_buf[:n, :m]
        # colour: |Δc|² at the precision of the less noisy pixel of the pair
        d = diff_buf[:3, :n, :m]
        np.subtract(guide_color[p], guide_color[q], out=d)
        np.square(d, out=d)
        np.add.reduce(d, axis=0, out=w)
        np.maximum(precision[p[1:]], precision[q[1:]], out=pair)
        np.multiply(w, pair, out=w)
        if depth:
            d = diff_buf[:depth, :n, :m]
            np.subtract(features[p], features[q], out=d)
            np.square(d, out=d)
            np.add.reduce(d, axis=0, out=pair)
            np.add(w, pair, out=w)
        np.subtract(-spatial, w, out=w)  # −(colour + features + spatial)
        np.exp(w, out=w)
        t = tmp_buf[:, :n, :m]
        np.multiply(color[q], w, out=t)
        num[p] += t
        np.multiply(color[p], w, out=t)
        num[q] += t
        den[p[1:]] += w
        den[q[1:]] += w


def median3x3(array: np.ndarray) -> np.ndarray:
    """3×3 median over the first two axes, edges replicated: ``scipy.ndimage.median_filter(size=3,
    mode="nearest")`` per channel, ~10× faster.

    Each column triple is sorted once (lo ≤ mid ≤ hi); the median of the 3×3 window is then the
    median of (the largest of the three lo, the median of the three mid, the smallest of the three
    hi): the classic exact median-of-9 by column sorting, about twenty elementwise min/max passes
    instead of a partition of a 9×H×W stack."""
    array = np.asarray(array)
    pad = [(1, 1), (1, 1)] + [(0, 0)] * (array.ndim - 2)
    padded = np.pad(array, pad, mode="edge")
    up, centre, down = padded[:-2], padded[1:-1], padded[2:]
    lo, hi = np.minimum(up, centre), np.maximum(up, centre)
    mid = np.maximum(lo, np.minimum(hi, down))
    lo, hi = np.minimum(lo, down), np.maximum(hi, down)

    def columns(a):
        return a[:, :-2], a[:, 1:-1], a[:, 2:]

    def median3(a, b, c):
        return np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))

    lo_max = np.maximum(np.maximum(*columns(lo)[:2]), columns(lo)[2])
    hi_min = np.minimum(np.minimum(*columns(hi)[:2]), columns(hi)[2])
    return median3(lo_max, median3(*columns(mid)), hi_min)


def _noise_variance(color: np.ndarray, variance: np.ndarray | None) -> np.ndarray:
    """Smoothed per-pixel variance of the mean colour (H×W), see the module docstring."""
    var = None
    if variance is not None:
        var = np.mean(np.asarray(variance, np.float32), axis=-1)
        if not np.any(var > 0):
            var = None
    if var is None:
        # no usable variance buffer: a robust local spread of the colour, (1.4826 · the 5×5 median
        # of |c − median3(c)|)². A plain local variance would be huge all around a firefly and
        # open the filter to it.
        deviation = np.abs(color - median3x3(color))
        sigma = 1.4826 * ndimage.median_filter(deviation, size=(5, 5, 1), mode="nearest")
        var = np.mean(sigma * sigma, axis=-1)
    # two 3×3 medians (a robust 5×5-wide smoothing): a mean would carry a highlight's variance
    # into the dark pixels around it (see the module docstring, "Bright, noisy neighbours")
    return median3x3(median3x3(np.maximum(var, 0.0)))


def _feature_scale(name: str, feature: np.ndarray) -> float:
    if name == "depth":
        finite = feature[np.isfinite(feature)]
        return float(np.median(np.abs(finite))) if finite.size else 1.0
    if name == "position":
        # the typical one-pixel step of the world position on a surface
        steps = []
        if feature.shape[1] > 1:
            steps.append(np.linalg.norm(np.diff(feature, axis=1), axis=-1).ravel())
        if feature.shape[0] > 1:
            steps.append(np.linalg.norm(np.diff(feature, axis=0), axis=-1).ravel())
        steps = np.concatenate(steps) if steps else np.zeros(0)
        steps = steps[np.isfinite(steps) & (steps > 0)]
        return float(np.median(steps)) if steps.size else 1.0
    return 1.0


def color_precision(color: np.ndarray, noise: np.ndarray, sigma_color: float) -> np.ndarray:
    """H×W: 1 / (2 σ_c² (2 V̄ + ε)), the colour part's weight per unit of |Δc|²."""
    eps = (0.01 * float(np.mean(color))) ** 2 + 1e-12
    precision = 1.0 / (2.0 * sigma_color**2 * (2.0 * noise.astype(np.float64) + eps))
    # |Δc|² · precision must stay finite in float32 even for absurd inputs
    return np.ascontiguousarray(np.minimum(precision, 1e30), dtype=np.float32)


def build_guide(
    color: np.ndarray,
    features: Mapping[str, np.ndarray],
    *,
    sigma_color: float,
    feature_sigmas: Mapping[str, float],
    color_variance: np.ndarray | None = None,
    feature_variances: Mapping[str, np.ndarray] | None = None,
    guide_dims: int | None = None,
    noise: np.ndarray | None = None,
) -> Guide:
    """The range weight's inputs: the colour, its precision, and the scaled features (PCA-projected if asked).

    ``noise`` is V̄ (H×W) when the caller has it already; otherwise it is estimated here."""
    color = np.asarray(color, np.float32)
    height, width = color.shape[:2]
    if noise is None:
        noise = _noise_variance(color, color_variance)
    feature_parts = []
    for name, sigma in feature_sigmas.items():
        if name not in features or sigma is None or sigma <= 0:
            continue
        feature = np.asarray(features[name], np.float32)
        sigma_eff2 = (sigma * max(_feature_scale(name, feature), 1e-12)) ** 2
        if feature_variances is not None and name in feature_variances:
            sigma_eff2 += 2.0 * float(np.median(feature_variances[name]))
        feature_parts.append(np.moveaxis(feature, -1, 0) / np.float32(np.sqrt(2.0 * sigma_eff2)))
    feats = np.concatenate(feature_parts, axis=0) if feature_parts else np.zeros((0, height, width), np.float32)
    if guide_dims is not None and 0 < guide_dims < feats.shape[0]:
        flat = feats.reshape(feats.shape[0], -1)
        # ~4096 pixels estimate a D×D covariance well; more only costs time
        sample = flat[:, :: max(1, flat.shape[1] // 4096)].astype(np.float64)
        sample = sample - sample.mean(axis=1, keepdims=True)
        cov = sample @ sample.T / max(sample.shape[1], 1)
        _, vectors = np.linalg.eigh(cov)
        basis = vectors[:, ::-1][:, :guide_dims].T.astype(np.float32)  # k×D, orthonormal rows
        feats = (basis @ flat).reshape(guide_dims, *feats.shape[1:])
    # |Δg|² must stay finite in float32 even for absurd inputs (squares of ≤ 2e15, ≤ 20 channels)
    np.clip(feats, -1e15, 1e15, out=feats)
    return Guide(
        np.ascontiguousarray(feats, dtype=np.float32),
        _color_planes(color),
        color_precision(color, noise, sigma_color),
    )


def _color_planes(color: np.ndarray) -> np.ndarray:
    """3×H×W float32 colour, clipped so that squared differences stay finite in float32."""
    return np.ascontiguousarray(np.clip(np.moveaxis(color, -1, 0), -1e15, 1e15), dtype=np.float32)


def ring_support(guide: Guide, sigma_spatial: float) -> np.ndarray:
    """H×W: Σ of the filter's weights from each pixel to its 8 neighbours (pixels outside take no part)."""
    height, width = guide.color_precision.shape
    (ring,) = window_offsets(1, sigma_spatial, separable=False)
    _, den = _accumulate(np.zeros((0, height, width), np.float32), guide, ring)
    return den - 1.0  # the pixel's own weight


def suppress_unsupported(
    color: np.ndarray, guide: Guide, sigma_spatial: float, threshold: float
) -> tuple[np.ndarray, int]:
    """``color`` (H×W×3) with its unsupported bright pixels replaced by their 3×3 median; and how many.

    A pixel is unsupported when the filter's weights to its 8 neighbours sum to less than
    ``threshold`` (nothing around it looks alike) and it is brighter than that median.
    """
    support = ring_support(guide, sigma_spatial)
    ys, xs = np.nonzero(support < threshold)
    if ys.size == 0:
        return color, 0
    # the median only where it may be needed (few pixels): their 3×3 windows, edges replicated
    height, width = color.shape[:2]
    offsets = np.arange(-1, 2)
    wy = np.clip(ys[:, None, None] + offsets[None, :, None], 0, height - 1)
    wx = np.clip(xs[:, None, None] + offsets[None, None, :], 0, width - 1)
    windows = color[wy, wx].reshape(ys.size, 9, color.shape[2])
    median = np.partition(windows, 4, axis=1)[:, 4]
    bad = color[ys, xs].mean(axis=-1) > median.mean(axis=-1)
    count = int(np.count_nonzero(bad))
    if count:
        color = color.copy()
        color[ys[bad], xs[bad]] = median[bad]
    return color, count


def cross_bilateral_filter(
    color: np.ndarray,
    features: Mapping[str, np.ndarray] | None = None,
    *,
    color_variance: np.ndarray | None = None,
    feature_variances: Mapping[str, np.ndarray] | None = None,
    radius: int = 7,
    sigma_spatial: float = 3.5,
    sigma_color: float = 6.0,
    feature_sigmas: Mapping[str, float] | None = None,
    separable: bool = True,
    guide_dims: int | None = None,
    firefly_support: float | None = FIREFLY_SUPPORT,
) -> np.ndarray:
    """Filter H×W×3 ``color`` guided by ``features`` (name → H×W×C); returns H×W×3 float32."""
    color = np.maximum(np.asarray(color, np.float32), 0.0)
    features = dict(features or {})
    sigmas = DEFAULT_FEATURE_SIGMAS if feature_sigmas is None else dict(feature_sigmas)

    # V̄ is estimated once: replacing fireflies leaves the variance buffer (and the robust fallback)
    # as it was, so only the guide's colour part is recomputed after it
    noise = _noise_variance(color, color_variance)
    guide = build_guide(
        color,
        features,
        sigma_color=sigma_color,
        feature_sigmas=sigmas,
        color_variance=color_variance,
        feature_variances=feature_variances,
        guide_dims=guide_dims,
        noise=noise,
    )
    if firefly_support is not None and firefly_support > 0:
        color, replaced = suppress_unsupported(color, guide, sigma_spatial, firefly_support)
        if replaced:
            guide = guide._replace(color=_color_planes(color))
    out = np.ascontiguousarray(np.moveaxis(color, -1, 0))
    for offsets in window_offsets(int(radius), sigma_spatial, separable):
        out = joint_bilateral_pass(out, guide, offsets)
    return np.ascontiguousarray(np.moveaxis(out, 0, -1), dtype=np.float32)


class CrossBilateral(DenoiserBase):
    """The cross-bilateral baseline. ``preset`` is fast, balanced or high; keywords override it."""

    needs = frozenset({"color"})  # features are used when the frame has them
    temporal = False

    def __init__(
        self,
        preset: str = "balanced",
        *,
        radius: int | None = None,
        sigma_spatial: float | None = None,
        sigma_color: float | None = None,
        separable: bool | None = None,
        features: Iterable[str] | None = None,
        feature_sigmas: Mapping[str, float] | None = None,
        guide_dims: int | None | str = "preset",
        firefly_support: float | None = FIREFLY_SUPPORT,
    ) -> None:
        if preset not in PRESETS:
            raise ValueError(f"unknown cross_bilateral preset {preset!r}; known: {', '.join(PRESETS)}")
        config = dict(PRESETS[preset])
        for key, value in (
            ("radius", radius),
            ("sigma_spatial", sigma_spatial),
            ("sigma_color", sigma_color),
            ("separable", separable),
        ):
            if value is not None:
                config[key] = value
        if guide_dims != "preset":
            config["guide_dims"] = guide_dims
        names = tuple(features) if features is not None else config["features"]
        unknown = sorted(set(names) - set(DEFAULT_FEATURE_SIGMAS))
        if unknown:
            raise ValueError(f"unknown feature(s) {', '.join(unknown)}; known: {', '.join(DEFAULT_FEATURE_SIGMAS)}")
        sigmas = {name: DEFAULT_FEATURE_SIGMAS[name] for name in names if name in DEFAULT_FEATURE_SIGMAS}
        sigmas.update(feature_sigmas or {})
        unknown = sorted(set(sigmas) - set(DEFAULT_FEATURE_SIGMAS))
        if unknown:
            raise ValueError(f"unknown feature(s) {', '.join(unknown)}; known: {', '.join(DEFAULT_FEATURE_SIGMAS)}")
        if int(config["radius"]) < 0 or float(config["sigma_spatial"]) <= 0 or float(config["sigma_color"]) <= 0:
            raise ValueError("radius must be >= 0 and sigma_spatial, sigma_color > 0")
        self.preset = preset
        self.radius = int(config["radius"])
        self.sigma_spatial = float(config["sigma_spatial"])
        self.sigma_color = float(config["sigma_color"])
        self.separable = bool(config["separable"])
        self.guide_dims = config["guide_dims"]
        self.feature_sigmas = sigmas
        self.uses = frozenset(sigmas)  # read when the frame has them: what its input's render is charged
        self.firefly_support = firefly_support
        self.name = "cross_bilateral" if preset == "balanced" else f"cross_bilateral_{preset}"

    def denoise(self, frame: Frame) -> np.ndarray:
        features = {name: frame.buffers[name] for name in self.feature_sigmas if name in frame.buffers}
        variances = {name: frame.buffers[f"{name}_var"] for name in features if f"{name}_var" in frame.buffers}
        return cross_bilateral_filter(
            frame.color,
            features,
            color_variance=frame.buffers.get("color_var"),
            feature_variances=variances,
            radius=self.radius,
            sigma_spatial=self.sigma_spatial,
            sigma_color=self.sigma_color,
            feature_sigmas=self.feature_sigmas,
            separable=self.separable,
            guide_dims=self.guide_dims,
            firefly_support=self.firefly_support,
        )
