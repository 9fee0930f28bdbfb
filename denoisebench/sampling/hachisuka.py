"""The ``hachisuka2008`` sampler: image-space adaptive sampling on a k-d tree refined by contrast.

Hachisuka, T., Jarosz, W., Weistroffer, R. P., Dale, K., Humphreys, G., Zwicker, M. and Jensen,
H. W. (2008), "Multidimensional adaptive sampling and reconstruction for ray tracing", ACM
Transactions on Graphics 27(3) (SIGGRAPH): samples are kept in a k-d tree whose leaves are
refined where the *contrast* of their samples is high, and new samples go to the leaves of largest
error. The denoising lecture's recap shows its image-space variant, which this is: the tree covers
the image plane only (the paper's tree spans pixel, lens and time dimensions together).

Per round: every leaf's contrast is measured from its pixels' luminance means and variances, the
root-mean-square relative deviation of its samples from the leaf mean,
``c² = mean_p[(L_p − L̄)² + σ_p²] / max(L̄, ε)²`` (``σ_p²`` the per-sample variance, ``n · var``); up to
``splits_per_round`` passes split every leaf whose error ``c · area`` is at least the mean leaf
error, at the midpoint of its longer side (k-d: the axis alternates with the shape), down to
one-pixel leaves; then the round's samples go to the leaves with final counts aimed at
``n ∝ c`` per pixel, uniformly within a leaf.

Notes
-----
* The paper places samples one at a time in the leaf of largest error; a round here is placed in
  one step, with the allocation that minimises ``Σ_leaf area · c² / n`` at a fixed total (``n ∝ c``),
  the same fixed point the greedy rule approaches. Samples in a pixel are the renderer's (stratified
  within the pixel); the paper's anisotropic reconstruction over the tree is not done: the image is
  each pixel's mean, so that the sampler stays unbiased and a denoiser can follow it.
* ``c`` includes the pixel-to-pixel contrast (edges, texture) as well as the noise, as the paper's
  sample contrast does: edges draw samples even where they are noise-free. A noise-free constant
  image has ``c = 0`` everywhere and gets uniform samples.
* The variance ``σ_p²`` is the colour variance folded into luminance as an upper bound (see
  :mod:`~denoisebench.sampling.allocation`); ``ε = 1e-4`` floors the mean of dark leaves.
"""

from __future__ import annotations

import numpy as np

from denoisebench.sampling.allocation import luminance, luminance_var
from denoisebench.sampling.schedule import initial_samples, round_size, top_up, uniform

EPSILON = 1e-4


def leaf_contrasts(lum: np.ndarray, sample_var: np.ndarray, leaves: np.ndarray) -> np.ndarray:
    """RMS contrast of the samples of every leaf (rows ``y0, y1, x0, x1``; module docstring), vectorised."""
    labels = leaf_labels(leaves, lum.shape)
    count = np.bincount(labels.ravel(), minlength=len(leaves)).astype(np.float64)
    mean = np.bincount(labels.ravel(), lum.ravel(), len(leaves)) / count
    square = np.bincount(labels.ravel(), (lum**2 + sample_var).ravel(), len(leaves)) / count
    return np.sqrt(np.maximum(square - mean**2, 0.0)) / np.maximum(mean, EPSILON)


def leaf_labels(leaves: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """H×W map of the index of the leaf each pixel lies in."""
    labels = np.empty(shape, dtype=np.int64)
    for index, (y0, y1, x0, x1) in enumerate(leaves.tolist()):
        labels[y0:y1, x0:x1] = index
    return labels


def split(leaves: np.ndarray) -> np.ndarray:
    """Each leaf's two halves at the midpoint of its longer side (one-pixel leaves stay whole)."""
    y0, y1, x0, x1 = leaves.T
    tall = (y1 - y0 >= x1 - x0) & (y1 - y0 > 1)
    wide = ~tall & (x1 - x0 > 1)
    ym, xm = (y0 + y1) // 2, (x0 + x1) // 2
    first = np.stack([y0, np.where(tall, ym, y1), x0, np.where(wide, xm, x1)], axis=1)
    second = np.stack([np.where(tall, ym, y0), y1, np.where(wide, xm, x0), x1], axis=1)
    return np.concatenate([first, second[tall | wide]])


class Hachisuka2008:
    """Image-space contrast-refined k-d tree (module docstring)."""

    name = "hachisuka2008"

    def __init__(self, initial_spp: int = 4, rounds: int = 6, splits_per_round: int = 3):
        if not initial_spp >= 1 or not rounds >= 1 or not splits_per_round >= 1:
            raise ValueError("hachisuka2008 needs initial_spp >= 1, rounds >= 1, splits_per_round >= 1")
        self.initial_spp = int(initial_spp)
        self.rounds = int(rounds)
        self.splits_per_round = int(splits_per_round)
        self.leaves = np.zeros((0, 4), dtype=np.int64)

    def refine(self, lum: np.ndarray, sample_var: np.ndarray) -> np.ndarray:
        """Split the leaves of high error (``splits_per_round`` passes); the leaves' contrasts after."""
        contrasts = leaf_contrasts(lum, sample_var, self.leaves)
        for _ in range(self.splits_per_round):
            area = (self.leaves[:, 1] - self.leaves[:, 0]) * (self.leaves[:, 3] - self.leaves[:, 2])
            errors = contrasts * area
            chosen = (errors >= errors.mean()) & (area > 1)
            if not errors.mean() > 0 or not chosen.any():
                break
            self.leaves = np.concatenate([self.leaves[~chosen], split(self.leaves[chosen])])
            contrasts = leaf_contrasts(lum, sample_var, self.leaves)
        return contrasts

    def weights(self, contrasts: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
        """The per-pixel map of leaf contrasts."""
        return contrasts[leaf_labels(self.leaves, shape)]

    def sample(self, budget, rounds) -> None:
        self.leaves = np.array([[0, rounds.height, 0, rounds.width]], dtype=np.int64)
        first = initial_samples(rounds, self.initial_spp)
        if first <= 0:
            return
        result = rounds.render(uniform(rounds, first))
        done = 0
        while not rounds.cut and (size := round_size(rounds, done, self.rounds)) > 0:
            lum = luminance(result.buffers)
            sample_var = np.where(rounds.counts > 0, luminance_var(result.buffers) * np.maximum(rounds.counts, 1), 0.0)
            contrasts = self.refine(lum, sample_var)
            weights = self.weights(contrasts, lum.shape)
            result = rounds.render(top_up(weights, rounds.counts, size))
            done += 1
