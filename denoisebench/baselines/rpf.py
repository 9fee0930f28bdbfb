"""Random Parameter Filtering (Sen & Darabi 2012, "On filtering the noise from the random parameters
in Monte Carlo rendering"), vectorised: numpy histograms for the statistics, torch for the filter.
The per-sample table and its neighbourhoods (steps 1-2) live in :mod:`~denoisebench.baselines.rpf_samples`,
the statistics (steps 3-5) in :mod:`~denoisebench.baselines.rpf_statistics`; this module is the filter
(step 6), the passes that drive them, the safeguards and the denoiser.

Per pass t = 0..3 with box size b (the paper's 55, 35, 17, 7 pixels; scaled down for images under
128 px, see :func:`scaled_boxes`), for every pixel P with its S samples:

1. **Gather** (the paper's Algorithm 2) the neighbourhood N: P's own S samples plus draws of
   (pixel, sample) at Gaussian offsets of σ = b/4 pixels around P, kept inside the b×b box
   (mirrored at the image border) and never P itself, b²·S/2 samples in all. Each sample is a
   vector of colour c (3), scene features f (``features``: first-hit world position, normal and
   albedo, second-hit position and normal, where the data has them), screen position p (pixel +
   sub-pixel offset) and the random parameters r the data holds: lens (u, v, as the disk point the
   renderer made of them), time, and the first vertex's light-sample and bounce-direction random
   numbers (``light``, ``bounce``).
2. **Cluster**: a drawn sample j joins N only if every clustering feature k (first-hit normal and
   albedo) satisfies |f_jk − m_k| ≤ max(3σ_k, 0.1), with m and σ the mean and standard deviation
   of P's own samples (the paper's rule). Clustering **gates both the statistics and the filter**:
   a sample from another surface has zero weight.
3. **Normalise** every channel by the mean and standard deviation of N.
4. **Dependencies** (Algorithm 3) by mutual information from joint histograms over N (``bins``
   equal bins over ±3 standard deviations, Miller–Madow bias correction): for every colour and
   feature channel x_k, D^r_k = Σ_l MI(x_k; r_l), D^p_k = Σ_l MI(x_k; p_l); for every feature,
   D^c_{f,k} = Σ_l MI(f_k; c_l). Then W^r_k = D^r_k / (D^r_k + D^p_k) for each channel;
   for the colour as a whole D^r_c = Σ_k D^r_{c,k}, D^p_c = Σ_k D^p_{c,k}, D^f_c = Σ_k D^c_{f,k},
   W^r_c = D^r_c / (D^r_c + D^p_c) and W^c_{f,k} = D^c_{f,k} / (D^r_c + D^p_c + D^f_c).
5. **Weights**: α_k = max(1 − 2(1 + 0.1t)·W^r_{c,k}, 0) for colour channels,
   β_k = W^c_{f,k}·max(1 − (1 + 0.1t)·W^r_{f,k}, 0) for feature channels: a feature that the colour
   depends on counts, one that depends on the random parameters (a defocused or moving edge, a
   second hit that follows the bounce) does not.
6. **Filter** (Algorithm 4), for each of P's samples i over the samples j of N::

       w_ij = exp(−|p_i − p_j|² / 2σ_p²) · exp(−Σ_k α_k (c̄_ik − c̄_jk)² / 2σ_c²) · exp(−Σ_k β_k (f̄_ik − f̄_jk)² / 2σ_f²)

   with σ_p = b/4 pixels, σ_c² = σ_f² = σ² / (1 − W^r_c)² and σ² = 8σ_8²/S, σ_8² = 0.02 (the
   paper's value at 8 spp). Sample i's new colour is Σ_j w_ij c_j / Σ_j w_ij; the next pass
   filters these colours; the pixel is the mean of its samples'. Every output is a convex
   combination of input samples (w_ii = 1 > 0): finite and non-negative.

Deviations (each with its reason; tests/baselines/test_classic.py shows what they cost):
    * **Sample counts are capped**: ``max_samples`` (128) for the filter, ``stat_samples`` (128)
      for the statistics, where the paper draws b²S/2 (6050 at b = 55, S = 4; the cap applies from
      b = 9 at 4 spp). Filtering is a Monte Carlo estimate of a weighted mean over the box: more
      draws lower its variance, not its expectation. Measured on synthetic 32 px frames
      (tests/baselines/test_rpf.py): 256 statistics samples were no better than 128; 256 filter
      samples were up to 20% better on a textured frame and no better on depth of field, at
      about 1.3× the time.
    * **Statistics on a coarser grid**: α, β and W^r_c are computed at every ``stride``-th pixel,
      stride = max(f, round(b / ``stat_stride_divisor``)) with divisor 4 and the floor
      f = max(2, min(``min_stat_stride``, b // 2)), ``min_stat_stride`` 2 (14 px at b = 55, 2 at
      b = 7), and every pixel takes its nearest grid point's. The statistics
      describe a neighbourhood of σ_p = b/4 pixels, which a grid of about σ_p resolves; clustering,
      which keeps edges, is still done for every pixel in the filter. Measured: no worse than
      statistics at every pixel (slightly better: fewer, less noisy estimates), at 1/stride² of
      their cost. (The ``fast`` preset's ``min_stat_stride=3`` is 10% faster at 128 px but weakens the
      lens response slightly: rpf_card.md gives the figures.) A 3-px grid in a 3-px box is too coarse (a bounce-driven feature moved a pixel by 1% in
      tests/baselines/test_rpf.py), hence the half-box cap on the floor.
      **Straddling pixels are refined** (``refine_passes``, ``refine_samples``): a pixel whose own
      samples straddle surfaces (3σ of its own clustering features above the tolerance 0.1 in some
      channel) clusters differently from its grid point, which may see one surface only and so no
      edge at all (α = β = 0 there: the pass blurs sky into the ground samples of a horizon pixel).
      In the first ``refine_passes`` (2) passes, whose grids are the coarsest (14 and 9 px at 128 px),
      such pixels get statistics of their own from ``refine_samples`` (48) draws. It lowers relMSE on
      rendered frames of every family (rpf_card.md, "Latest", with the variants tried). Cost: 16-44% of the pixels of rendered frames straddle, and statistics
      dominate, so the paper preset takes up to 2.4× as long on rendered 128 px frames; the ``fast``
      preset does not refine (0 passes) and keeps its speed.
    * **Clustering features** are the first-hit normal and albedo only. World position varies along
      every surface by an amount set by the scene's scale, so the paper's absolute tolerance 0.1
      would cut a plane into slivers in a large scene and miss nothing in a small one; second hits
      vary with the bounce by design. Both still enter the statistics and the feature term.
    * Without ``light``/``bounce`` data (older datasets, 1-D effects only) the colour's dependence
      on the path's own random numbers is estimated from the within-pixel share of its variance
      (E_P[Var_P c] / Var_N c): W^r_{c,k} = 1 − (1 − W_MI)(1 − W_var). At 1 spp that share is
      unknown and only MI counts.
    * The lens parameter enters the statistics as the disk point (a defocused hit moves linearly
      with it, non-monotonically with u or v alone, and MI over single coordinates would miss it).
    * Draws come from a pool of 256 random offset patterns per pass and stage (each pixel picks one
      at random), which costs a fraction of drawing every pixel's own; they are deterministic: the
      filter's picks are drawn for the whole image per (seed, pass), the statistics' per (seed, pass,
      chunk of grid rows) with chunks fixed by the image size, so neither the number of threads nor
      the filter's chunk size changes the bytes. One draw of the neighbourhoods against another moves
      relMSE by a few per cent (textured 128 px, 4 spp, seeds 0-3: 0.0555-0.0577).
    * Two safeguards the paper does not have, both for the relMSE of dark pixels beside bright noise:
      sample colours are capped at ``firefly_factor`` (16) × the largest pixel mean of the 8
      neighbouring pixels before the first pass (:func:`cap_spikes`), and with S ≥ 2 the output is
      kept within ``change_limit`` (3) standard errors of each pixel's own mean, plus 5% of it and
      0.01 (:func:`limit_change`). Without the second, on the rendered glossy_fireflies scene (64 px)
      RPF averaged a glossy floor's few highlight samples into pixels whose own samples were all
      dark: relMSE 95 at 4 spp against the input's 12 (with it: 0.46); cornell 4 spp 0.083 → 0.047.
      It cost depth_of_field 4 spp 0.034 → 0.043 (cross_bilateral: 0.149).

Cost (where the time goes): per pass every pixel gathers M ≤ 128 samples of D columns, so the filter
is a few passes over an n×M×D table per chunk of pixels (gather, centre, square, cluster test, three
batched matmuls: cluster sums, energies, output); the statistics' one-hot histograms dominate the last
pass. 128 px, 4 spp: 50-58 CPU s/MP on one thread before the straddling refinement (up to 2.4x that on
rendered frames with it; the fast preset does not refine); two threads split the chunks (about 1.5x).

Per-pixel α (mean over colour channels), β (mean over each feature's channels) and W^r of every pass
are kept in :attr:`RandomParameterFilter.last_weights` for inspection and tests.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import torch

from denoisebench.baselines.rpf_samples import (
    CLUSTER_TOLERANCE,
    PATTERNS,
    SampleLayout,
    draw,
    pattern_pool,
    sample_table,
)
from denoisebench.baselines.rpf_statistics import pass_statistics
from denoisebench.baselines.threads import available_threads
from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.protocol import DenoiserBase

# Lazy imports: scipy (0.3 s) is imported inside the functions that need it, so that the
# registry can list RPF without loading it.

DEFAULT_FEATURES = ("position", "normal", "albedo", "position2", "normal2")
PAPER_BOXES = (55, 35, 17, 7)  # at the paper's image size
PAPER_SIZE = 128  # boxes keep their paper size from 128 px up: the noise per pixel does not shrink with the image
SIGMA8_SQUARED = 0.02  # the paper's σ² at 8 spp; σ² = 8 σ_8² / S
_STAT_CELLS = 500_000  # gathered samples × channels of one statistics chunk: bounds memory (one-hot codes: × bins)
_FILTER_PAIRS = 400_000  # sample pairs (own × gathered) of one filter chunk


@dataclass
class RPFWeights:
    """Per-pass, per-pixel weights of one :func:`rpf_filter` call (each H×W float32)."""

    boxes: list[int] = field(default_factory=list)
    alpha: list[np.ndarray] = field(default_factory=list)  # mean α over colour channels
    beta: list[dict[str, np.ndarray]] = field(default_factory=list)  # feature -> mean β over its channels
    w_random: list[dict[str, np.ndarray]] = field(default_factory=list)  # "color" (W^r_c) and feature -> W^r
    cluster: list[np.ndarray] = field(default_factory=list)  # share of drawn samples the clustering kept


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
    """Threads for the statistics chunks of a pass (patched in tests)."""
    return available_threads()


def _filter(
    flat_t: torch.Tensor,
    layout: SampleLayout,
    ys: np.ndarray,
    xs: np.ndarray,
    shape,
    box: int,
    pool,
    scale: torch.Tensor,
    pick: np.ndarray,
) -> torch.Tensor:
    """S×n×3: one pass's new colours of the samples of pixels (ys, xs); ``scale`` (n×K, K = colour and
    feature columns) holds α/2σ_c² on colour columns and β/2σ_f² on feature columns.

    Normalising a channel (minus the cluster's mean, over its standard deviation σ) only scales its
    differences, (ō − ḡ)² = (o − g)²/σ², so the filter folds 1/σ² into ``scale`` instead of
    normalising every sample; values are centred on the mean of P's own samples, so that the expanded
    square Σ k o² + Σ k g² − 2 Σ k o g does not cancel (world positions can be large).
    """
    spp, height, width = shape
    index = torch.from_numpy(draw(None, pool, ys, xs, spp, height, width, pick=pick))
    n, m = index.shape
    gathered = torch.index_select(flat_t, 0, index.view(-1)).view(n, m, -1)  # colour, features, screen position
    d = gathered.shape[-1]
    kcols = layout.features.stop  # colour and features: the range terms
    # z (centred on the mean of P's own samples, so that the expanded squares below do not cancel:
    # world positions can be large) and z² side by side: every sum the filter needs of both comes out
    # of one batched matmul
    zz = torch.empty((n, m, 2 * d), dtype=gathered.dtype)
    z, squares = zz[:, :, :d], zz[:, :, d:]
    torch.sub(gathered, gathered[:, :spp].mean(1, keepdim=True), out=z)
    torch.mul(z, z, out=squares)  # (z * z: Tensor.square() is twice as slow on CPU)
    cl = layout.cluster
    if cl.stop > cl.start:  # the paper's clustering, gating statistics and weights alike
        # centred on its own mean: the own samples' standard deviation is their RMS
        limit = (3.0 * squares[:, :spp, cl].mean(1, keepdim=True).sqrt_()).clamp_(min=CLUSTER_TOLERANCE)
        mask = (squares[:, :, cl] <= limit.square_()).all(-1)  # |z| <= limit, on the squares at hand
        mask[:, :spp] = True
        mask = mask.to(z.dtype)
    else:
        mask = torch.ones((n, m), dtype=z.dtype)
    # the cluster's mean and variance of every range channel: masked sums of z and z² (one matmul)
    count = mask.sum(1, keepdim=True)
    sums = torch.bmm(mask.unsqueeze(1), zz).squeeze(1) / count  # n×2D
    mean = sums[:, :kcols]
    var = (sums[:, d : d + kcols] - mean * mean).clamp_(min=0.0)
    level = gathered[:, 0, :kcols].abs() + mean.abs()
    level *= level
    inv_var = torch.where(var > 1e-24 + 1e-12 * level, 1.0 / var.clamp_min(1e-30), torch.zeros_like(var))
    k = torch.cat([scale * inv_var, torch.full((n, d - kcols), 1.0 / (2.0 * (box / 4.0) ** 2))], dim=1)
    own = z[:, :spp]
    own_k = own * k.unsqueeze(1)  # n×S×D
    # Σ_k k (o − g)² = Σ k o² − 2 Σ k o g + Σ k g²: [−2 k o, k] · [g, g²] in one batched matmul
    left = torch.cat([own_k * -2.0, k.unsqueeze(1).expand(n, spp, d)], dim=2)
    energy = torch.bmm(left, zz.transpose(1, 2))
    energy += (own_k * own).sum(-1, keepdim=True)
    # capped at 80: exp(−80) ≈ 2e−35 is still a normal float (denormals are ~50x slower), and
    # beside w_ii = 1 a weight that small is nothing
    energy.clamp_(min=0.0, max=80.0).neg_().exp_()
    energy *= mask.unsqueeze(1)  # n×S×M weights, w_ii = 1
    filtered = torch.bmm(energy, gathered[:, :, layout.color]) / energy.sum(-1, keepdim=True)
    return filtered.transpose(0, 1)


@dataclass(frozen=True)
class RPFSettings:
    """Options of :func:`rpf_filter` (see the module docstring); validated on construction."""

    features: tuple[str, ...] = DEFAULT_FEATURES
    boxes: tuple[int, ...] | None = None  # None: scaled_boxes() of the image
    max_samples: int = 128  # cap of the paper's b²S/2 samples per pixel in the filter
    stat_samples: int = 128  # the same cap for the statistics
    stat_stride_divisor: float = 4.0  # statistics every max(min_stat_stride, round(b / this)) pixels (0: every pixel)
    min_stat_stride: int = 2  # statistics grid at least this coarse where within half the box (see the docstring)
    refine_passes: int = (
        2  # in this many first passes, pixels whose own samples straddle surfaces get their own statistics
    )
    refine_samples: int = 48  # ... from this many draws (capped by stat_samples)
    bins: int = 6
    sigma8_squared: float = SIGMA8_SQUARED
    firefly_factor: float | None = 16.0  # sample colours capped at this × the 8 neighbour pixels' largest mean
    change_limit: float | None = 3.0  # output within this many of the pixel's own standard errors (S >= 2)
    seed: int = 0

    def __post_init__(self) -> None:
        if (
            self.max_samples < 1
            or self.stat_samples < 2
            or self.refine_samples < 2
            or self.bins < 2
            or not self.sigma8_squared > 0
        ):
            raise ValueError("max_samples must be >= 1, stat_samples >= 2, bins >= 2 and sigma8_squared > 0")
        if self.stat_stride_divisor < 0 or self.min_stat_stride < 1 or self.refine_passes < 0:
            raise ValueError("stat_stride_divisor must be >= 0, min_stat_stride >= 1 and refine_passes >= 0")
        if self.firefly_factor is not None and not self.firefly_factor >= 1.0:
            raise ValueError("firefly_factor must be >= 1 or None")
        if self.change_limit is not None and not self.change_limit > 0.0:
            raise ValueError("change_limit must be > 0 or None")
        if self.boxes is not None and any(int(b) < 1 for b in self.boxes):
            raise ValueError("box sizes must be >= 1")
        object.__setattr__(self, "features", tuple(self.features))
        if self.boxes is not None:
            object.__setattr__(self, "boxes", tuple(int(b) for b in self.boxes))

    def stride(self, box: int) -> int:
        if self.stat_stride_divisor == 0:
            return 1
        # the floor applies where the grid stays within half the box (b >= 7 for the floor 3)
        floor = max(2, min(self.min_stat_stride, box // 2))
        return max(floor, int(round(box / self.stat_stride_divisor)))


def cap_spikes(color: np.ndarray, factor: float) -> np.ndarray:
    """S×H×W×3 sample colours, each channel capped at ``factor`` × the largest pixel mean of the 8
    neighbouring pixels (edges replicate): a spike no neighbour comes near is cut before it is
    spread. The paper filters spikes like any other noise, and a filter that averages a 1e4 sample
    into the dark pixels around it scores far worse (relMSE) than leaving it in its pixel."""
    from scipy.ndimage import maximum_filter  # noqa: PLC0415

    ring = np.ones((3, 3, 1), dtype=bool)
    ring[1, 1, 0] = False
    bound = maximum_filter(color.mean(axis=0), footprint=ring, mode="nearest") * np.float32(factor)
    return np.minimum(color, bound[None])


def limit_change(image: np.ndarray, own: np.ndarray, limit: float) -> np.ndarray:
    """``image`` moved back to within ``limit`` standard errors of each pixel's own mean (``own``:
    S×H×W×3 samples, S ≥ 2), with a floor of 5% of that mean plus 0.01 for the error.

    A safeguard the paper does not have. Where a surface's colour is mostly noise, α → 0 and RPF
    averages over everything the clustering keeps; on a glossy floor that carries a few very bright
    highlight samples into pixels whose own samples are all dark (rendered glossy_fireflies, 4 spp:
    relMSE 95 against the input's 12, dark pixels at 14 against a reference of 0.03). A pixel whose own
    samples agree is already known to that precision, so the filter may not move it further."""
    mean = own.mean(axis=0)
    error = np.sqrt(own.var(axis=0, ddof=1) / own.shape[0]) + 0.05 * np.abs(mean) + 0.01
    bound = limit * error
    return np.clip(image, mean - bound, mean + bound)


def _straddling(table: np.ndarray, cluster: slice) -> np.ndarray:
    """H×W bool: pixels whose own samples straddle surfaces, i.e. whose clustering tolerance
    (3σ of their own clustering features) is wider than the paper's floor of 0.1 in some channel."""
    spp = table.shape[0]
    if cluster.stop <= cluster.start or spp < 2:
        return np.zeros(table.shape[1:3], bool)
    return (3.0 * table[..., cluster].std(axis=0) > CLUSTER_TOLERANCE).any(-1)


def _grid(size: int, stride: int) -> np.ndarray:
    """Statistics rows (or columns): every ``stride``-th pixel, centred in its cell."""
    return np.arange(min(stride // 2, size - 1), size, stride)


def _nearest(size: int, grid: np.ndarray) -> np.ndarray:
    """For every pixel, the index of its nearest grid point."""
    position = np.arange(size)
    upper = np.clip(np.searchsorted(grid, position), 0, grid.size - 1)
    lower = np.clip(upper - 1, 0, grid.size - 1)
    return np.where(np.abs(grid[lower] - position) <= np.abs(grid[upper] - position), lower, upper)


def _map_chunks(function, count: int, workers: int) -> list:
    if workers > 1 and count > 1:
        with ThreadPoolExecutor(min(workers, count)) as pool:
            return list(pool.map(function, range(count)))
    return [function(k) for k in range(count)]


def rpf_filter(
    samples: Mapping[str, np.ndarray], settings: RPFSettings = RPFSettings()
) -> tuple[np.ndarray, RPFWeights]:
    """Filter per-sample data (name → S×H×W×C, needs ``color``); returns (H×W×3 float32, weights)."""
    table, layout = sample_table(samples, settings.features)
    spp, height, width, dims = table.shape
    if settings.firefly_factor is not None and height * width > 1:
        table[..., layout.color] = cap_spikes(table[..., layout.color], settings.firefly_factor)
    limit = settings.change_limit is not None and spp > 1
    own_color = table[..., layout.color].astype(np.float64) if limit else None
    shape = (spp, height, width)
    straddling = _straddling(table, layout.cluster)
    boxes = list(settings.boxes) if settings.boxes is not None else scaled_boxes(height, width)
    weights = RPFWeights()
    sigma2 = 8.0 * settings.sigma8_squared / spp
    threads = torch.get_num_threads()
    # Python threads run chunks, each torch operation on one thread: torch's own OpenMP threads spin at
    # every barrier, which on a loaded 2-core machine made 2 threads 3x slower than one
    torch.set_num_threads(1)
    try:
        for t, box in enumerate(boxes):
            paper = max(spp, box * box * spp // 2)
            flat = table.reshape(-1, dims)

            # statistics on a grid, in chunks of grid rows on threads (numpy releases the GIL)
            stride = settings.stride(box)
            gy, gx = _grid(height, stride), _grid(width, stride)
            stat_total = min(paper, max(settings.stat_samples, spp))
            rows_per_chunk = max(1, _STAT_CELLS // max(1, gx.size * stat_total * dims))
            chunks = [gy[i : i + rows_per_chunk] for i in range(0, gy.size, rows_per_chunk)]
            seeds = np.random.SeedSequence([settings.seed, t, 2]).spawn(len(chunks))

            stat_pool = pattern_pool(np.random.default_rng([settings.seed, t, 0]), spp, box, stat_total, height, width)

            def stats(k: int):
                ys, xs = np.meshgrid(chunks[k], gx, indexing="ij")
                return pass_statistics(
                    flat,
                    layout,
                    ys.ravel(),
                    xs.ravel(),
                    shape,
                    stat_pool,
                    t,
                    settings.bins,
                    np.random.default_rng(seeds[k]),
                )

            parts = _map_chunks(stats, len(chunks), _workers())
            alpha, beta, w_rc, w_rf, kept = (np.concatenate([p[i] for p in parts]) for i in range(5))
            pick = (_nearest(height, gy)[:, None] * gx.size + _nearest(width, gx)[None, :]).ravel()
            alpha, beta, w_rc, w_rf, kept = alpha[pick], beta[pick], w_rc[pick], w_rf[pick], kept[pick]
            if t < settings.refine_passes and stride > 1 and straddling.any():
                # a pixel whose own samples straddle surfaces clusters differently from its grid
                # point (which may see one surface only, and no edge): its statistics are its own
                on_grid = np.zeros((height, width), bool)
                on_grid[np.ix_(gy, gx)] = True
                todo = np.flatnonzero((straddling & ~on_grid).ravel())
                refine_total = min(stat_total, max(settings.refine_samples, spp))
                refine_pool = (
                    stat_pool
                    if refine_total == stat_total
                    else pattern_pool(
                        np.random.default_rng([settings.seed, t, 5]), spp, box, refine_total, height, width
                    )
                )
                per = max(1, _STAT_CELLS // max(1, refine_total * dims))
                pieces = [todo[i : i + per] for i in range(0, todo.size, per)]
                refine_seeds = np.random.SeedSequence([settings.seed, t, 4]).spawn(max(1, len(pieces)))

                def refine(k: int):
                    ys, xs = np.divmod(pieces[k], width)
                    return pass_statistics(
                        flat,
                        layout,
                        ys,
                        xs,
                        shape,
                        refine_pool,
                        t,
                        settings.bins,
                        np.random.default_rng(refine_seeds[k]),
                    )

                if pieces:
                    extra = _map_chunks(refine, len(pieces), _workers())
                    for target, i in zip((alpha, beta, w_rc, w_rf, kept), range(5)):
                        target[todo] = np.concatenate([p[i] for p in extra])

            # the filter, every pixel, in chunks of rows (torch threads inside)
            shrink = (1.0 - np.clip(w_rc, 0.0, 0.99)) ** 2 / (2.0 * sigma2)  # 1 / 2σ_c² = (1 − W^r_c)² / 2σ²
            scale = np.zeros((height * width, layout.features.stop), np.float32)
            scale[:, layout.color] = alpha * shrink[:, None]
            scale[:, layout.features] = beta * shrink[:, None]
            filter_total = min(paper, max(settings.max_samples, spp))
            rows = max(1, _FILTER_PAIRS // max(1, width * spp * filter_total))
            filter_pool = pattern_pool(
                np.random.default_rng([settings.seed, t, 1]), spp, box, filter_total, height, width
            )
            columns = np.r_[0 : layout.features.stop, layout.position.start : layout.position.stop]
            flat_t = torch.from_numpy(np.ascontiguousarray(flat[:, columns]))
            scale_t = torch.from_numpy(scale)
            new_color = np.empty((spp, height, width, 3), np.float32)
            # one pattern per pixel, drawn for the whole image: the bytes do not depend on the chunking
            picks = np.random.default_rng([settings.seed, t, 3]).integers(0, PATTERNS, height * width)

            def run_filter(k: int) -> None:
                y0 = k * rows
                y1 = min(height, y0 + rows)
                ys, xs = np.meshgrid(np.arange(y0, y1), np.arange(width), indexing="ij")
                with torch.no_grad():
                    out = _filter(
                        flat_t,
                        layout,
                        ys.ravel(),
                        xs.ravel(),
                        shape,
                        box,
                        filter_pool,
                        scale_t[y0 * width : y1 * width],
                        picks[y0 * width : y1 * width],
                    )
                new_color[:, y0:y1] = out.numpy().reshape(spp, y1 - y0, width, 3)

            _map_chunks(run_filter, -(-height // rows), _workers())
            table[..., layout.color] = new_color

            offset = layout.features.start
            weights.boxes.append(box)
            weights.alpha.append(alpha.mean(1).reshape(height, width).astype(np.float32))
            weights.beta.append(
                {
                    name: beta[:, s.start - offset : s.stop - offset].mean(-1).reshape(height, width).astype(np.float32)
                    for name, s in layout.feature_groups.items()
                }
            )
            groups = {"color": w_rc.reshape(height, width).astype(np.float32)}
            groups.update(
                {
                    name: w_rf[:, s.start - offset : s.stop - offset].mean(-1).reshape(height, width).astype(np.float32)
                    for name, s in layout.feature_groups.items()
                }
            )
            weights.w_random.append(groups)
            weights.cluster.append(kept.reshape(height, width).astype(np.float32))
    finally:
        torch.set_num_threads(threads)
    image = table[..., layout.color].mean(axis=0)
    if limit:
        image = limit_change(image, own_color, settings.change_limit)
    return np.maximum(image, 0.0).astype(np.float32), weights


#: Named option sets. ``fast`` (registered as ``rpf_fast``) draws 48 samples per neighbourhood for the
#: filter and the statistics instead of 128 and keeps the statistics grid at least 3 px: 2.3x less CPU
#: than ``paper`` (textured 128 px, 4 spp: 0.66 vs 1.55 CPU s) for relMSE 0.0668 vs 0.0577 there
#: (8 spp: 0.0864 vs 0.0629), and does not refine straddling pixels (``paper`` does in its first two
#: passes, at up to 2.4x the time on rendered frames). Rendered figures: baselines/rpf_card.md.
PRESETS: dict[str, dict] = {
    "paper": {},
    "fast": {"max_samples": 48, "stat_samples": 48, "min_stat_stride": 3, "refine_passes": 0},
}


class RandomParameterFilter(DenoiserBase):
    """RPF over the frame's per-sample data (``needs`` = {"samples"}); see the module docstring.
    ``preset`` (:data:`PRESETS`: ``paper``, the default, or ``fast``) sets the options; keywords
    override it."""

    name = "rpf"
    needs = frozenset({"samples"})
    temporal = False

    def __init__(self, preset: str = "paper", **options) -> None:
        if preset not in PRESETS:
            raise ValueError(f"unknown rpf preset {preset!r}; known: {', '.join(PRESETS)}")
        self.settings = RPFSettings(**{**PRESETS[preset], **options})  # raises ValueError/TypeError for bad options
        self.preset = preset
        self.name = "rpf" if preset == "paper" else f"rpf_{preset}"
        self.last_weights: RPFWeights | None = None

    def denoise(self, frame: Frame) -> np.ndarray:
        samples = frame.samples
        if samples is None or "color" not in samples:
            raise ValueError("rpf needs per-sample data with a 'color' entry")
        image, self.last_weights = rpf_filter(samples, self.settings)
        return image
