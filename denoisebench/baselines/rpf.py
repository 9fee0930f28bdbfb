"""Random Parameter Filtering (Sen & Darabi 2012, "On filtering the noise from the random parameters
in Monte Carlo rendering"), vectorised in numpy over per-sample data.

Per pass t (box sizes shrinking: the paper's 55 → 35 → 17 → 7 pixels, scaled down for images under
128 px), for every pixel P:

1. **Gather** P's own S samples plus ``M − S`` samples drawn from the b×b box around P
   (mirrored at the image border). Each sample is a vector of colour c (3), scene features f
   (``features``: world position, normal, albedo by default), screen position p (pixel index +
   sub-pixel offset) and the random parameters r the render plan has (lens u,v with depth of
   field, time with motion blur).
2. **Normalise** every channel by the neighbourhood's mean and standard deviation.
3. **Cluster** (the paper's pre-process): only neighbours whose every feature lies within
   3·max(σ_P, 0.3) of the mean of P's own samples (normalised units) enter the statistics, so
   they describe the surface P sees.
4. **Dependencies.** Mutual information from joint histograms (``bins`` equal bins over ±3
   standard deviations, Miller–Madow bias correction): D^r_k = Σ_l MI(x_k; r_l), D^p_k =
   Σ_l MI(x_k; p_l) for each colour and feature channel x_k, D^c_{f,k} = Σ_l MI(f_k; c_l), and
   the colour's total D_c = Σ_k (D^r_{c,k} + D^p_{c,k} + D^f_{c,k}).
5. **Weights.** W^r_k = D^r_k / (D^r_k + D^p_k + ε) (how much x_k depends on the random
   parameters rather than on screen position);
   α_k = max(1 − (1 + 0.1t)·W^r_{c,k}, 0) for colour, β_k = W^c_{f,k}·max(1 − (1 + 0.1t)·W^r_{f,k}, 0)
   for features with W^c_{f,k} = D^c_{f,k} / D_c. A feature that varies with the lens (a defocused
   edge) or with time (motion) gets a small β: it says nothing reliable about the surface at P.
6. **Filter.** For each of P's samples i, over the gathered samples j (the lecture's formula)::

       w_ij = exp(−|p_i − p_j|² / 2σ_p²) · exp(−Σ_k α_k (c̄_ik − c̄_jk)² / 2σ_c²) · exp(−Σ_k β_k (f̄_ik − f̄_jk)² / 2σ_f²)

   with σ_p = b/4 pixels, σ_c² = σ_c0² / (1 − W^r_c)² and σ_f² = σ_f0² / (1 − W^r_c)² (W^r_c the
   mean over colour channels). The paper uses one σ² = 0.02 for both; here the colour gets its own,
   wider σ_c0² = 0.5 (``sigma2_color``; σ_f0² = 0.01, ``sigma2_feature``), because our colour's
   α stays larger than the paper's (see the first note) and a tight colour term keeps the noise.
   Chosen on rendered 32 px, 4 spp frames, where relMSE goes (noisy → RPF): cornell 0.140 → 0.053,
   depth_of_field 0.614 → 0.056, dim_room 3.48 → 0.106, texture_checker 0.171 → 0.097,
   glossy_fireflies 0.132 → 0.104, thin_geometry 0.074 → 0.034 (with σ_c0² = 2 cornell got worse
   than its input, 0.21: noisy ceiling pixels pulled in the light's samples).
   Sample i's new colour is Σ_j w_ij c_j / Σ_j w_ij; the next pass filters these colours; the pixel
   is the mean of its samples' colours. Every output is a convex combination of input samples:
   finite and non-negative.

Notes:
    * Our renderer stores the random parameters pixel, lens and time, but not the random numbers
      that choose the path's bounces, on which most of the colour's noise depends (the paper
      has them). Their share is estimated instead: the within-pixel part of the neighbourhood's
      colour variance (E_i[Var_P c] / Var_neighbourhood c, in [0, 1]) is variance that screen
      position cannot explain. W^r_{c,k} = 1 − (1 − W_MI)(1 − W_var) combines both. At 1 spp
      the within-pixel variance is unknown (0) and only MI counts.
    * The lens parameter is stored as the square sample (u, v); statistics use the disk point the
      renderer made of it (:mod:`~denoisebench.denoisers.lens_sampling`). A hit point moves
      linearly with the disk point but non-monotonically with (u, v) one at a time, and MI summed
      over single coordinates barely sees that dependence.
    * Samples are drawn as in the paper: Gaussian offsets (σ = b/4) around P, inside the box.
    * Histogram MI from ~100 samples is biased upwards by about (K_a − 1)(K_b − 1)/2N nats;
      without the Miller–Madow correction two independent channels would look dependent and
      every W would drift towards 1/2.
    * ``max_samples`` (M) bounds the work: the paper draws b²S/2 samples, which at b = 55 is far
      more than a numpy implementation can afford per pixel. Draws use a fixed seed, one
      generator per (pass, chunk of rows): the filter is deterministic, and the chunks of a pass
      run on several threads (numpy releases the GIL; 1.7× on 2 cores) with the same bytes as on one.
    * Per-pixel α and β of every pass are kept in :attr:`RandomParameterFilter.last_weights`
      (β averaged over each feature's channels) for inspection and tests.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.lens_sampling import square_to_disk_concentric
from denoisebench.denoisers.protocol import DenoiserBase

from .threads import available_threads

DEFAULT_FEATURES = ("position", "normal", "albedo")
PAPER_BOXES = (55, 35, 17, 7)  # at the paper's image size
PAPER_SIZE = 128  # boxes keep their paper size from 128 px up: the noise per pixel does not shrink with the image
RANDOM_PARAMETERS = ("lens", "time")
_EPS = 1e-10
_CHUNK_PAIRS = 3_000_000  # sample pairs (own × gathered) per pixel chunk: bounds memory
_PAIR_GROUP_CELLS = 4_000_000  # samples × channel pairs counted by one bincount


@dataclass
class RPFWeights:
    """Per-pass, per-pixel weights of one :func:`rpf_filter` call (each H×W float32)."""

    boxes: list[int] = field(default_factory=list)
    alpha: list[np.ndarray] = field(default_factory=list)  # mean α over colour channels
    beta: list[dict[str, np.ndarray]] = field(default_factory=list)  # feature -> mean β over its channels
    w_random: list[dict[str, np.ndarray]] = field(default_factory=list)  # channel group -> W^r


def scaled_boxes(height: int, width: int, boxes: Sequence[int] = PAPER_BOXES) -> list[int]:
    """The paper's box sizes scaled to the image (odd, at least 3, at most the image's larger side
    rounded up to odd), duplicates after scaling dropped."""
    scale = min(1.0, max(height, width) / PAPER_SIZE)
    limit = max(3, max(height, width) | 1)
    out: list[int] = []
    for box in boxes:
        size = int(round(box * scale)) | 1
        size = min(max(size, 3), limit)
        if not out or size < out[-1]:
            out.append(size)
    return out


def _workers() -> int:
    """Threads for the pixel chunks of a pass (patched in tests)."""
    return available_threads()


def _mirror(index: np.ndarray, size: int) -> np.ndarray:
    index = np.abs(index)
    index = np.where(index >= size, 2 * size - 2 - index, index)
    return np.clip(index, 0, size - 1)


class _Histograms:
    """Mutual information between channels of n neighbourhoods of m quantised samples each.

    Entropies use H = log N − Σ_b c_b log c_b / N with a lookup table of c log c (counts are
    integers ≤ m); samples outside the cluster mask are counted in one extra bin that is dropped.
    Histograms of many channel pairs are counted by one ``bincount`` (Python overhead per pair
    would otherwise dominate).
    """

    def __init__(self, quantised: np.ndarray, mask: np.ndarray, bins: int):
        n, m, _ = quantised.shape
        self.n, self.bins = n, bins
        self.q = np.ascontiguousarray(np.moveaxis(quantised, 2, 0), dtype=np.int32)  # D×n×m
        self.outside = ~mask
        self.total = np.maximum(mask.sum(axis=1).astype(np.float64), 1.0)
        self.c_log_c = np.zeros(m + 1)
        self.c_log_c[1:] = np.arange(1, m + 1) * np.log(np.arange(1, m + 1))
        self.marginals = self._entropies(self.q, bins)  # (H, K) per channel, each D×n

    def _entropies(self, index: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray]:
        """Entropy (nats) and non-empty bins of the P×n histograms that ``index`` (P×n×m cells) fills."""
        groups = index.shape[0]
        # int32 halves the memory traffic (a group indexes ≤ _PAIR_GROUP_CELLS / m · bins² cells)
        flat = index + (np.arange(groups * self.n, dtype=np.int32).reshape(groups, self.n, 1) * np.int32(cells))
        flat[:, self.outside] = groups * self.n * cells  # the dump bin
        counts = np.bincount(flat.ravel(), minlength=groups * self.n * cells + 1)[:-1].reshape(groups, self.n, cells)
        entropy = np.log(self.total) - self.c_log_c[counts].sum(axis=2) / self.total
        return entropy, np.count_nonzero(counts, axis=2)

    def mutual_information(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """P×n: MI(channel a[i]; channel b[i]) in every neighbourhood."""
        h_ab, k_ab = self._entropies(self.q[a] * self.bins + self.q[b], self.bins * self.bins)
        h, k = self.marginals
        # Miller–Madow: H ≈ H_plugin + (K − 1)/2N for each of the three entropies
        bias = ((k[a] - 1) + (k[b] - 1) - (k_ab - 1)) / (2.0 * self.total)
        return np.maximum(h[a] + h[b] - h_ab + bias, 0.0)

    def dependency(self, channels: Sequence[int], on: Sequence[int]) -> np.ndarray:
        """n×len(channels): Σ over ``on`` of MI(channel; o)."""
        out = np.zeros((self.n, len(channels)))
        if not channels or not on:
            return out
        a = np.repeat(np.asarray(channels, dtype=np.intp), len(on))
        b = np.tile(np.asarray(on, dtype=np.intp), len(channels))
        step = max(1, _PAIR_GROUP_CELLS // max(1, self.q[0].size))
        mi = np.concatenate([self.mutual_information(a[i : i + step], b[i : i + step]) for i in range(0, a.size, step)])
        return mi.reshape(len(channels), len(on), self.n).sum(axis=1).T


@dataclass
class _Layout:
    """Column ranges of the per-sample table."""

    color: slice
    features: slice
    feature_groups: dict[str, slice]
    position: slice
    random: slice
    random_groups: dict[str, slice]


def _sample_table(samples: Mapping[str, np.ndarray], features: Sequence[str]) -> tuple[np.ndarray, _Layout]:
    """S×H×W×D float32: colour, features, screen position, random parameters (see :class:`_Layout`)."""
    color = np.maximum(np.asarray(samples["color"], np.float32), 0.0)
    s, h, w, _ = color.shape
    parts = [color]
    groups: dict[str, slice] = {}
    column = 3
    for name in features:
        if name in samples:
            array = np.asarray(samples[name], np.float32)
            parts.append(array)
            groups[name] = slice(column, column + array.shape[-1])
            column += array.shape[-1]
    feature_slice = slice(3, column)
    ys, xs = np.meshgrid(np.arange(h, dtype=np.float32), np.arange(w, dtype=np.float32), indexing="ij")
    offset = np.asarray(samples["pixel"], np.float32) if "pixel" in samples else np.full((s, h, w, 2), 0.5, np.float32)
    parts.append(np.stack([xs, ys], axis=-1)[None] + offset)
    position = slice(column, column + 2)
    column += 2
    random_groups: dict[str, slice] = {}
    for name in RANDOM_PARAMETERS:
        if name in samples:
            array = np.asarray(samples[name], np.float32)
            if name == "lens":  # the point on the lens, on which a defocused hit depends linearly
                array = square_to_disk_concentric(array).astype(np.float32)
            parts.append(array)
            random_groups[name] = slice(column, column + array.shape[-1])
            column += array.shape[-1]
    layout = _Layout(slice(0, 3), feature_slice, groups, position, slice(position.stop, column), random_groups)
    table = np.concatenate(parts, axis=-1)
    # features can hold huge values (1e6 positions): keep squares finite in float32
    np.clip(table, -1e15, 1e15, out=table)
    return np.ascontiguousarray(table), layout


def _columns(block: slice) -> list[int]:
    return list(range(block.start, block.stop))


def _filter_chunk(
    table: np.ndarray,
    layout: _Layout,
    rows: slice,
    box: int,
    pass_index: int,
    rng: np.random.Generator,
    *,
    max_samples: int,
    bins: int,
    sigma2_color: float,
    sigma2_feature: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One pass over the pixels of ``rows``: (new sample colours S×n×3, α n, β n×F, W^r n×F+3)."""
    spp, height, width, dims = table.shape
    ys, xs = np.meshgrid(np.arange(rows.start, rows.stop), np.arange(width), indexing="ij")
    ys, xs = ys.ravel(), xs.ravel()
    n = ys.size
    radius = box // 2
    extra = max(0, min(max_samples, box * box * spp) - spp)
    own_s = np.broadcast_to(np.arange(spp), (n, spp))
    # the paper's draw: Gaussian offsets of σ = b/4 pixels, kept inside the box
    offsets = np.clip(np.rint(rng.normal(0.0, box / 4.0, (2, n, extra))), -radius, radius).astype(np.int64)
    gy = np.concatenate([np.broadcast_to(ys[:, None], (n, spp)), _mirror(ys[:, None] + offsets[0], height)], 1)
    gx = np.concatenate([np.broadcast_to(xs[:, None], (n, spp)), _mirror(xs[:, None] + offsets[1], width)], 1)
    gs = np.concatenate([own_s, rng.integers(0, spp, (n, extra))], 1)
    gathered = table[gs, gy, gx]  # n×M×D float32
    m = gathered.shape[1]

    # 2. normalise by the neighbourhood; a constant channel becomes 0 everywhere
    mean = gathered.mean(axis=1, keepdims=True)
    std = gathered.std(axis=1, keepdims=True)
    inv = np.where(std > 1e-12 + 1e-6 * np.abs(mean), 1.0 / np.maximum(std, 1e-30), 0.0).astype(np.float32)
    normal = (gathered - mean) * inv
    own = normal[:, :spp]

    # 3. cluster: neighbours on the surface P sees (features within 3 max(σ_P, 0.3) of P's mean)
    feat = layout.features
    own_mean = own[:, :, feat].mean(axis=1, keepdims=True)
    own_std = own[:, :, feat].std(axis=1, keepdims=True)
    inside = np.abs(normal[:, :, feat] - own_mean) <= 3.0 * np.maximum(own_std, 0.3)
    mask = inside.all(axis=2) if inside.shape[2] else np.ones((n, m), bool)
    mask[:, :spp] = True

    # 4. dependencies from histograms over ±3 standard deviations
    quantised = np.clip(np.floor((normal + 3.0) * (bins / 6.0)), 0, bins - 1).astype(np.int32)
    histograms = _Histograms(quantised, mask, bins)
    color_cols, feature_cols = _columns(layout.color), _columns(layout.features)
    p_cols, r_cols = _columns(layout.position), _columns(layout.random)
    x_cols = color_cols + feature_cols
    d_r = histograms.dependency(x_cols, r_cols)
    d_p = histograms.dependency(x_cols, p_cols)
    w_r = d_r / (d_r + d_p + _EPS)
    d_cf = histograms.dependency(feature_cols, color_cols)  # n×F
    d_c = (d_r[:, :3] + d_p[:, :3]).sum(axis=1) + d_cf.sum(axis=1)

    # the bounce random numbers we do not have: the within-pixel share of the colour's variance
    if spp > 1:
        within = np.clip(own[:, :, color_cols].var(axis=1), 0.0, 1.0)
        w_r[:, :3] = 1.0 - (1.0 - w_r[:, :3]) * (1.0 - within)
    growth = 1.0 + 0.1 * pass_index
    alpha = np.maximum(1.0 - growth * w_r[:, :3], 0.0)
    beta = d_cf / (d_c[:, None] + _EPS) * np.maximum(1.0 - growth * w_r[:, 3:], 0.0)
    w_rc = np.clip(w_r[:, :3].mean(axis=1), 0.0, 0.99)
    shrink = (1.0 - w_rc) ** 2  # σ² / (1 − W^r_c)²: a colour that is mostly noise widens both terms

    # 6. the cross-bilateral filter over samples: Σ_d k_d (o_d − g_d)², expanded into one matmul
    scale = np.zeros((n, dims), np.float32)
    scale[:, layout.color] = alpha * (shrink / (2.0 * sigma2_color))[:, None]
    scale[:, layout.features] = beta * (shrink / (2.0 * sigma2_feature))[:, None]
    pos_cols = layout.position
    raw_own = gathered[:, :spp, pos_cols]
    raw_all = gathered[:, :, pos_cols]
    sigma_p2 = (box / 4.0) ** 2
    spatial = ((raw_own[:, :, None, :] - raw_all[:, None, :, :]) ** 2).sum(-1) / (2.0 * sigma_p2)
    weighted_own = own * scale[:, None, :]
    energy = (
        (weighted_own * own).sum(-1)[:, :, None]
        + ((normal * normal) * scale[:, None, :]).sum(-1)[:, None, :]
        - 2.0 * np.einsum("nsd,nmd->nsm", weighted_own, normal, optimize=True)
    )
    np.maximum(energy, 0.0, out=energy)
    weights = np.exp(-(energy + spatial))
    colors = gathered[:, :, layout.color]
    filtered = np.einsum("nsm,nmc->snc", weights, colors, optimize=True) / weights.sum(-1).T[:, :, None]

    w_summary = np.concatenate([w_r[:, :3].mean(axis=1, keepdims=True), w_r[:, 3:]], axis=1)
    return filtered, alpha.mean(axis=1), beta, w_summary


@dataclass(frozen=True)
class RPFSettings:
    """Options of :func:`rpf_filter` (see the module docstring); validated on construction."""

    features: tuple[str, ...] = DEFAULT_FEATURES
    boxes: tuple[int, ...] | None = None  # None: scaled_boxes() of the image
    max_samples: int = 96
    bins: int = 6
    sigma2_color: float = 0.5
    sigma2_feature: float = 0.01
    seed: int = 0

    def __post_init__(self) -> None:
        if self.max_samples < 1 or self.bins < 2 or not (self.sigma2_color > 0 and self.sigma2_feature > 0):
            raise ValueError("max_samples must be >= 1, bins >= 2 and sigma2_color, sigma2_feature > 0")
        if self.boxes is not None and any(int(b) < 1 for b in self.boxes):
            raise ValueError("box sizes must be >= 1")
        object.__setattr__(self, "features", tuple(self.features))
        if self.boxes is not None:
            object.__setattr__(self, "boxes", tuple(int(b) for b in self.boxes))


def rpf_filter(samples: Mapping[str, np.ndarray], settings: RPFSettings = RPFSettings()) -> tuple[np.ndarray, RPFWeights]:
    """Filter per-sample data (name → S×H×W×C, needs ``color``); returns (H×W×3 float32, weights)."""
    features, boxes, max_samples, bins = settings.features, settings.boxes, settings.max_samples, settings.bins
    sigma2_color, sigma2_feature = settings.sigma2_color, settings.sigma2_feature
    table, layout = _sample_table(samples, features)
    spp, height, width, dims = table.shape
    boxes = list(boxes) if boxes is not None else scaled_boxes(height, width)
    weights = RPFWeights()
    for t, box in enumerate(boxes):
        m = max(spp, min(max_samples, box * box * spp))
        rows_per_chunk = max(1, _CHUNK_PAIRS // max(1, width * spp * m))
        new_color = np.empty((spp, height, width, 3), np.float32)
        alpha = np.empty((height, width), np.float32)
        n_feat = layout.features.stop - layout.features.start
        beta = np.empty((height, width, n_feat), np.float32)
        w_r = np.empty((height, width, 1 + n_feat), np.float32)
        chunks = [slice(y0, min(height, y0 + rows_per_chunk)) for y0 in range(0, height, rows_per_chunk)]
        # one generator per chunk, from (seed, pass, chunk): the same draws on any number of threads
        seeds = np.random.SeedSequence([settings.seed, t]).spawn(len(chunks))

        def run(k: int):
            return _filter_chunk(
                table, layout, chunks[k], box, t, np.random.default_rng(seeds[k]),
                max_samples=max_samples, bins=bins, sigma2_color=sigma2_color, sigma2_feature=sigma2_feature,
            )

        workers = min(_workers(), len(chunks))
        if workers > 1:
            with ThreadPoolExecutor(workers) as pool:
                results = list(pool.map(run, range(len(chunks))))
        else:
            results = [run(k) for k in range(len(chunks))]
        for rows, (filtered, a, b, wr) in zip(chunks, results):
            count = rows.stop - rows.start
            new_color[:, rows] = filtered.reshape(spp, count, width, 3)
            alpha[rows] = a.reshape(count, width)
            beta[rows] = b.reshape(count, width, n_feat)
            w_r[rows] = wr.reshape(count, width, 1 + n_feat)
        table[..., layout.color] = new_color
        offset = layout.features.start
        weights.boxes.append(box)
        weights.alpha.append(alpha)
        weights.beta.append(
            {name: beta[..., s.start - offset : s.stop - offset].mean(-1) for name, s in layout.feature_groups.items()}
        )
        groups = {"color": w_r[..., 0]}
        groups.update({name: w_r[..., 1 + s.start - offset : 1 + s.stop - offset].mean(-1) for name, s in layout.feature_groups.items()})
        weights.w_random.append(groups)
    image = table[..., layout.color].mean(axis=0)
    return np.maximum(image, 0.0).astype(np.float32), weights


class RandomParameterFilter(DenoiserBase):
    """RPF over the frame's per-sample data (``needs`` = {"samples"}); see the module docstring."""

    name = "rpf"
    needs = frozenset({"samples"})
    temporal = False

    def __init__(self, **options) -> None:
        self.settings = RPFSettings(**options)  # raises ValueError/TypeError for bad options
        self.last_weights: RPFWeights | None = None

    def denoise(self, frame: Frame) -> np.ndarray:
        samples = frame.samples
        if samples is None or "color" not in samples:
            raise ValueError("rpf needs per-sample data with a 'color' entry")
        image, self.last_weights = rpf_filter(samples, self.settings)
        return image
