"""RPF's per-sample table and its neighbourhoods (the gathering and clustering of
:mod:`~denoisebench.baselines.rpf`'s steps 1 and 2), shared by its statistics and its filter.

:func:`sample_table` lays every sample out as one float32 row: colour, scene features (the clustering
features first), screen position (pixel + sub-pixel offset) and the random parameters the data holds
(the lens as its disk point); :class:`SampleLayout` names the column ranges. :func:`draw` gathers a
pixel's neighbourhood as flat row indices: its own samples first, then the draws of one offset
pattern of a :func:`pattern_pool` (Gaussian, σ = b/4, inside the box, mirrored at the border, never
the pixel itself). :func:`cluster_mask` is the paper's clustering rule.

Pitfalls: the table clips and zeroes non-finite values (huge world positions would overflow squares in
float32); draws are deterministic only through the pool and the ``pick`` a caller fixes (the filter
draws its picks for the whole image so that chunking never changes the bytes).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from denoisebench.denoisers.lens_sampling import square_to_disk_concentric

CLUSTER_FEATURES = ("normal", "albedo")
RANDOM_PARAMETERS = ("lens", "time", "medium", "light", "bounce")
#: the path's own random numbers (else: the variance heuristic); ``medium``: its first free flight in a medium
PATH_RANDOM_PARAMETERS = ("medium", "light", "bounce")
CLUSTER_TOLERANCE = 0.1


def _mirror(index: np.ndarray, size: int) -> np.ndarray:
    index = np.abs(index)
    index = np.where(index >= size, 2 * size - 2 - index, index)
    return np.clip(index, 0, size - 1)


@dataclass
class SampleLayout:
    """Column ranges of the per-sample table."""

    color: slice
    features: slice
    feature_groups: dict[str, slice]
    cluster: slice  # columns of the clustering features (empty: no clustering)
    position: slice
    random: slice
    random_groups: dict[str, slice]

    @property
    def path_randoms(self) -> bool:
        return any(name in self.random_groups for name in PATH_RANDOM_PARAMETERS)


def sample_table(samples: Mapping[str, np.ndarray], features: Sequence[str]) -> tuple[np.ndarray, SampleLayout]:
    """S×H×W×D float32: colour, features, screen position, random parameters (see :class:`SampleLayout`)."""
    color = np.maximum(np.asarray(samples["color"], np.float32), 0.0)
    s, h, w, _ = color.shape
    parts = [color]
    groups: dict[str, slice] = {}
    column = 3
    ordered = [f for f in CLUSTER_FEATURES if f in features] + [f for f in features if f not in CLUSTER_FEATURES]
    for name in ordered:
        if name in samples:
            array = np.asarray(samples[name], np.float32)
            parts.append(array)
            groups[name] = slice(column, column + array.shape[-1])
            column += array.shape[-1]
    feature_slice = slice(3, column)
    cluster_stop = max([groups[name].stop for name in CLUSTER_FEATURES if name in groups], default=3)
    cluster = slice(3, cluster_stop)  # the clustering features lead the feature columns
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
    layout = SampleLayout(
        slice(0, 3), feature_slice, groups, cluster, position, slice(position.stop, column), random_groups
    )
    table = np.concatenate(parts, axis=-1)
    # features can hold huge values (1e6 positions) or NaN: keep squares finite in float32
    np.nan_to_num(table, copy=False, nan=0.0, posinf=1e15, neginf=-1e15)
    np.clip(table, -1e15, 1e15, out=table)
    return np.ascontiguousarray(table), layout


def columns_of(block: slice) -> list[int]:
    return list(range(block.start, block.stop))


PATTERNS = 256  # offset patterns drawn per pass and stage; each pixel uses one at random


def pattern_pool(rng: np.random.Generator, spp: int, box: int, total: int, height: int, width: int):
    """(dy, dx, sample) offsets, each P×(total − S) ints: Gaussian (σ = b/4) pixel offsets inside the
    box, never (0, 0), and a uniform sample index; ``None`` when there is nothing to draw."""
    radius = box // 2
    extra = total - spp
    if extra <= 0 or radius == 0 or height * width == 1:
        return None
    dy, dx = np.clip(np.rint(rng.normal(0.0, box / 4.0, (2, PATTERNS, extra))), -radius, radius).astype(np.int64)
    zero = (dy == 0) & (dx == 0)
    step = np.where(rng.random(zero.shape) < 0.5, -1, 1)
    if width > 1:
        dx = np.where(zero, step, dx)
    else:
        dy = np.where(zero, step, dy)
    return dy, dx, rng.integers(0, spp, (PATTERNS, extra))


def _mirror_table(size: int, reach: int) -> np.ndarray:
    """Index i + reach → the mirrored coordinate of i, for i in [−reach, size − 1 + reach]."""
    return _mirror(np.arange(-reach, size + reach), size)


def draw(
    rng: np.random.Generator | None,
    pool,
    ys: np.ndarray,
    xs: np.ndarray,
    spp: int,
    height: int,
    width: int,
    pick: np.ndarray | None = None,
) -> np.ndarray:
    """n×M flat sample indices ((s·H + y)·W + x): P's own S samples first, then the draws of a
    pattern of ``pool`` picked at random per pixel (or given: ``pick``, n pattern numbers), mirrored
    at the border, never P itself."""
    own = (np.arange(spp)[None, :] * height + ys[:, None]) * width + xs[:, None]
    if pool is None:
        return own
    dy, dx, ds = pool
    if pick is None:
        pick = rng.integers(0, dy.shape[0], ys.size)
    # mirroring by table look-up (one gather per axis instead of abs/where/clip on every draw)
    reach_y, reach_x = int(np.abs(dy).max()), int(np.abs(dx).max())
    row = _mirror_table(height, reach_y) * width
    column = _mirror_table(width, reach_x)
    here = ys * width + xs
    drawn = row[(ys + reach_y)[:, None] + dy[pick]]
    drawn += column[(xs + reach_x)[:, None] + dx[pick]]
    # a mirror back onto P (at the border): step to an adjacent pixel instead
    same = drawn == here[:, None]
    if same.any():
        if width > 1:
            step = np.where(xs > 0, here - 1, here + 1)
        else:
            step = np.where(ys > 0, here - width, here + width)
        drawn = np.where(same, step[:, None], drawn)
    drawn += ds[pick] * (height * width)
    return np.concatenate([own, drawn], axis=1)


def cluster_mask(gathered: np.ndarray, spp: int, cluster: slice) -> np.ndarray:
    """n×M bool: the paper's clustering (|f − m_P| ≤ max(3σ_P, 0.1) for every clustering feature)."""
    n, m = gathered.shape[:2]
    if cluster.stop <= cluster.start:
        return np.ones((n, m), dtype=bool)
    f = gathered[:, :, cluster]
    own = f[:, :spp]
    mean = own.mean(1, keepdims=True)
    limit = np.maximum(3.0 * own.std(1, keepdims=True), CLUSTER_TOLERANCE)
    inside = (np.abs(f - mean) <= limit).all(-1)
    inside[:, :spp] = True
    return inside
