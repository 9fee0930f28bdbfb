"""RPF's statistics (:mod:`~denoisebench.baselines.rpf`'s steps 3 to 5): per pixel, the colour's and the
features' dependence on the random parameters and on the screen position by mutual information, and
the α and β weights the filter uses.

:func:`mutual_information` builds every joint histogram of a neighbourhood batch from one-hot codes in
one batched matmul, with the Miller–Madow bias correction; :func:`pass_statistics` gathers, clusters,
normalises and quantises the neighbourhoods of a set of pixels and turns the dependencies into α (per
colour channel), β (per feature channel), W^r_c and the kept share of the cluster.

Pitfalls: histogram MI from ~100 samples is biased upwards (two independent channels look dependent
without the correction); the blocks of the one-hot table are contiguous views only because the
sample table's columns are colour, features, screen position, random parameters, in that order.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from denoisebench.baselines.rpf_samples import SampleLayout, cluster_mask, columns_of, draw

_EPS = 1e-10


def one_hot_codes(quantised: torch.Tensor, mask: torch.Tensor, bins: int) -> torch.Tensor:
    """n×M×(D·bins) float32: each sample's bin of every channel as a one-hot block per channel, all
    zero for samples outside ``mask`` (the cluster). Built once per neighbourhood batch; the joint
    histograms of any two column blocks are then one batched matmul of slices of it (0/1 squared is
    itself, so the mask on both sides counts each sample once)."""
    n, m, d = quantised.shape
    offsets = torch.arange(d, dtype=torch.int64) * bins
    codes = torch.zeros((n, m, d * bins), dtype=torch.float32)
    weight = mask.to(torch.float32).unsqueeze(-1).expand(n, m, d)
    return codes.scatter_(2, quantised.long() + offsets, weight)


def _code_block(codes: torch.Tensor, columns: Sequence[int], bins: int) -> torch.Tensor:
    columns = list(columns)
    if columns == list(range(columns[0], columns[0] + len(columns))):  # a view, no copy
        return codes[:, :, columns[0] * bins : (columns[-1] + 1) * bins]
    picks = torch.tensor([c * bins + j for c in columns for j in range(bins)], dtype=torch.int64)
    return codes.index_select(2, picks)


def mutual_information_codes(
    codes_a: torch.Tensor, codes_b: torch.Tensor, total: torch.Tensor, bins: int
) -> torch.Tensor:
    """n×A×B MI (nats) from one-hot blocks (n×M×(A·bins), n×M×(B·bins), see :func:`one_hot_codes`)
    and the cluster sizes ``total`` (n, float32, ≥ 1); see :func:`mutual_information`."""
    n = codes_a.shape[0]
    na, nb = codes_a.shape[2] // bins, codes_b.shape[2] // bins
    if na == 0 or nb == 0:  # e.g. colour-only data: no feature channels
        return torch.zeros((n, na, nb), dtype=torch.float32)
    joint = torch.bmm(codes_a.transpose(1, 2), codes_b).view(n, na, bins, nb, bins)
    count_a = joint[:, :, :, 0, :].sum(-1)  # every sample has one bin of each channel
    count_b = joint[:, 0].sum(1)

    # Miller–Madow entropy log N − Σ c log c / N + (K − 1)/2N (K: non-empty cells) is
    # log N − (Σ g(c) + ½)/N with g(c) = c log c − ½ for c ≥ 1 and g(0) = 0: the counts are whole
    # numbers ≤ N, so g is one table look-up per cell instead of xlogy plus a separate count of the
    # non-empty cells (10-20% less CPU for the whole filter on rendered 128 px frames, A/B interleaved)
    size = int(total.max()) + 1 if total.numel() else 1
    whole = torch.arange(size, dtype=torch.float32)
    table = torch.xlogy(whole, whole) - 0.5
    table[0] = 0.0

    def entropy(counts: torch.Tensor, dims: tuple[int, ...]):
        shape = (n,) + (1,) * (counts.dim() - 1 - len(dims))
        g = torch.take(table, counts.to(torch.int64)).sum(dims)
        return total.log().view(shape) - (g + 0.5) / total.view(shape)

    h_a = entropy(count_a, (2,))  # n×A
    h_b = entropy(count_b, (2,))  # n×B
    h_ab = entropy(joint, (2, 4))  # n×A×B
    return (h_a.unsqueeze(2) + h_b.unsqueeze(1) - h_ab).clamp_(min=0.0)


def mutual_information(
    quantised: torch.Tensor, mask: torch.Tensor, bins: int, a: Sequence[int], b: Sequence[int]
) -> torch.Tensor:
    """n×A×B: MI (nats) between channel a[i] and channel b[j] in each of n neighbourhoods.

    ``quantised`` (n×M×D integers in [0, bins)) holds each neighbourhood's samples, ``mask`` (n×M
    bool) which of them count (the cluster). Every joint histogram of the A×B channel pairs comes out
    of one batched matmul of one-hot codes (n×(A·bins)×(B·bins) counts); entropies are
    H = log N − Σ c log c / N. Histogram MI from ~100 samples is biased upwards by about
    (K_a − 1)(K_b − 1)/2N nats, so the Miller–Madow correction (K − 1)/2N is added to each of the
    three entropies (K: non-empty bins); without it two independent channels would look dependent.
    """
    codes = one_hot_codes(quantised, mask, bins)
    total = mask.sum(1).clamp_min(1).to(torch.float32)  # n
    return mutual_information_codes(_code_block(codes, a, bins), _code_block(codes, b, bins), total, bins)


def normalise(gathered: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Channels minus their mean over the cluster, over its standard deviation (constant → 0)."""
    w = mask[:, :, None].astype(np.float32)
    count = np.maximum(w.sum(1, keepdims=True), 1.0)
    mean = (gathered * w).sum(1, keepdims=True) / count
    centred = gathered - mean
    std = np.sqrt((centred * centred * w).sum(1, keepdims=True) / count)
    inv = np.where(std > 1e-12 + 1e-6 * np.abs(mean), 1.0 / np.maximum(std, 1e-30), 0.0).astype(np.float32)
    return centred * inv


def pass_statistics(
    flat: np.ndarray,
    layout: SampleLayout,
    ys: np.ndarray,
    xs: np.ndarray,
    shape,
    pool,
    pass_index: int,
    bins: int,
    rng: np.random.Generator,
):
    """α (n×3), β (n×F), W^r_c (n), per-feature-channel W^r (n×F), kept share (n) at pixels (ys, xs)."""
    spp, height, width = shape
    index = draw(rng, pool, ys, xs, spp, height, width)
    gathered = flat[index]  # n×M×D
    mask = cluster_mask(gathered, spp, layout.cluster)
    normal = normalise(gathered, mask)
    quantised = np.clip(np.floor((normal + 3.0) * (bins / 6.0)), 0, bins - 1).astype(np.uint8)
    color_cols = columns_of(layout.color)
    # the table's columns are colour, features, screen position, random parameters: the blocks below
    # are contiguous views of one one-hot table (colour against colour is never needed)
    assert layout.color.stop == layout.features.start and layout.position.stop == layout.random.start
    with torch.no_grad():
        mask_t = torch.from_numpy(mask)
        codes = one_hot_codes(torch.from_numpy(quantised), mask_t, bins)
        total = mask_t.sum(1).clamp_min(1).to(torch.float32)
        x_block = codes[:, :, : layout.features.stop * bins]
        pr_block = codes[:, :, layout.position.start * bins : layout.random.stop * bins]
        mi_x = mutual_information_codes(x_block, pr_block, total, bins).double().numpy()  # n×X×(2 + R)
        mi_f = (
            mutual_information_codes(
                codes[:, :, layout.features.start * bins : layout.features.stop * bins],
                codes[:, :, : layout.color.stop * bins],
                total,
                bins,
            )
            .double()
            .numpy()
        )
    d_r = mi_x[:, :, 2:].sum(2)
    d_p = mi_x[:, :, :2].sum(2)
    d_cf = mi_f.sum(2)  # n×F: features against the colour channels
    w_r = d_r / (d_r + d_p + _EPS)
    d_rc, d_pc, d_fc = d_r[:, :3].sum(1), d_p[:, :3].sum(1), d_cf.sum(1)
    w_rc = d_rc / (d_rc + d_pc + _EPS)
    if not layout.path_randoms and spp > 1:
        # no path random numbers in the data: the within-pixel share of the colour's variance
        own = normal[:, :spp][:, :, color_cols]
        within = np.clip(own.var(axis=1), 0.0, 1.0)
        w_r[:, :3] = 1.0 - (1.0 - w_r[:, :3]) * (1.0 - within)
        w_rc = 1.0 - (1.0 - w_rc) * (1.0 - within.mean(1))
    growth = 1.0 + 0.1 * pass_index
    alpha = np.maximum(1.0 - 2.0 * growth * w_r[:, :3], 0.0)
    w_cf = d_cf / (d_rc + d_pc + d_fc + _EPS)[:, None]
    beta = w_cf * np.maximum(1.0 - growth * w_r[:, 3:], 0.0)
    kept = mask[:, spp:].mean(1) if mask.shape[1] > spp else np.ones(ys.size)
    return alpha, beta, w_rc, w_r[:, 3:], kept
