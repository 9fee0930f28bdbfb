"""A progressive frame of known truth and known per-pixel noise, with the renderer's round interface.

:class:`SyntheticProgressiveFrame` speaks the interface of the feature renderer's progressive frame
(``generator/render/progressive.py``: ``width``, ``height``, ``render_round(counts) -> RoundBuffers``)
on an image whose expected value and noise are given, so that tests know the right allocation and
the truth an unbiased sampler must converge to. :func:`noisy_half`, :func:`constant` and
:func:`check_frame` build the frames the tests and ``check-plugin --sampler`` use.

Noise model: each sample of pixel ``p`` is ``truth[p] · g`` with ``g ~ Gamma(k, 1/k)``,
``k = 1 / noise[p]²``: mean ``truth[p]``, relative standard deviation ``noise[p]`` per sample, the
same ``g`` for the three channels (grey noise), ``g = 1`` where ``noise`` is 0. The gamma is skewed
like Monte Carlo radiance (many low samples, a few high ones), so the sample mean and the sample
variance are correlated: a stopping rule that reads the variance can bias the mean, which the
convergence check is there to catch (with Gaussian noise it could not).

Notes
-----
* Deterministic per round: round ``i`` draws from ``default_rng([seed, reference, i])``, so the
  same sequence of requests gives bit-identical buffers; a different request order gives different
  samples, as it would in the renderer.
* As in the renderer's progressive frame, a pixel without samples has mean 0 and variance inf,
  one with a single sample variance 0.
* ``diffuse`` is ``diffuse_fraction`` of ``color`` and ``specular`` the rest (their sum is ``color``,
  as in docs/architecture.md's buffer table); ``albedo``, ``normal`` and ``depth`` are noise-free features with
  zero variance.
* ``seconds`` is the measured wall time of the round's numpy work, a stand-in for render time:
  figures made with this frame are labelled synthetic.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np


@dataclass
class RoundBuffers:
    """What a round returns (the same fields as the renderer's ``RoundBuffers``).

    ``buffers``: accumulated per-pixel means (H×W×C float32) and ``<name>_var`` (variance of the
    mean; inf where a pixel has no sample, 0 where it has one); ``counts``: H×W int32 samples per
    pixel so far; ``seconds``: render seconds of this round; ``samples``: this round's new samples
    when asked for, ``{"color": N×H×W×3}`` with N the round's largest count, row ``j`` a pixel's
    ``j``-th new sample and zeros past its count (the renderer's layout).
    """

    buffers: dict[str, np.ndarray]
    counts: np.ndarray
    seconds: float
    samples: dict[str, np.ndarray] | None = None


class SyntheticProgressiveFrame:
    """Known ``truth`` (H×W×3) with per-sample relative noise ``noise`` (H×W); see the module docstring."""

    def __init__(
        self,
        truth: np.ndarray,
        noise: np.ndarray,
        *,
        seed: int = 0,
        reference: bool = False,
        keep_samples: bool = False,
        diffuse_fraction: float = 0.6,
    ):
        truth = np.asarray(truth, dtype=np.float64)
        noise = np.asarray(noise, dtype=np.float64)
        if truth.ndim != 3 or truth.shape[2] != 3 or noise.shape != truth.shape[:2]:
            raise ValueError(f"truth must be H×W×3 and noise H×W (got {truth.shape} and {noise.shape})")
        if (noise < 0).any() or (truth < 0).any():
            raise ValueError("truth and noise must be non-negative")
        self.truth = truth
        self.noise = noise
        self.height, self.width = noise.shape
        self.seed = int(seed)
        self.reference = bool(reference)
        self.keep_samples = bool(keep_samples)
        self.diffuse_fraction = float(diffuse_fraction)
        self.rounds = 0
        pixels = self.width * self.height
        self._n = np.zeros(pixels, dtype=np.int64)
        self._sum = np.zeros(pixels)
        self._sum2 = np.zeros(pixels)
        self._shape = np.where(noise > 0, 1.0 / np.maximum(noise, 1e-12) ** 2, 1.0).ravel()

    def expected_var(self, counts: np.ndarray) -> np.ndarray:
        """H×W×3 variance of the mean of ``color`` at ``counts`` samples per pixel (inf where 0)."""
        per_sample = (self.truth * self.noise[..., None]) ** 2
        with np.errstate(divide="ignore"):
            return per_sample / np.asarray(counts, dtype=np.float64)[..., None]

    def render_round(self, counts: np.ndarray) -> RoundBuffers:
        """Add ``counts[y, x]`` samples to each pixel; the accumulated buffers so far."""
        started = time.perf_counter()
        counts = np.asarray(counts)
        if counts.shape != (self.height, self.width) or (counts < 0).any():
            raise ValueError(f"counts must be a non-negative {self.height}×{self.width} map (got {counts.shape})")
        flat = counts.astype(np.int64).ravel()
        rng = np.random.default_rng([self.seed, int(self.reference), self.rounds])
        self.rounds += 1
        pixel = np.repeat(np.arange(flat.size), flat)
        shape = self._shape[pixel]
        draws = rng.gamma(shape, 1.0 / shape)
        draws = np.where(self.noise.ravel()[pixel] > 0, draws, 1.0)
        self._n += flat
        self._sum += np.bincount(pixel, draws, minlength=flat.size)
        self._sum2 += np.bincount(pixel, draws * draws, minlength=flat.size)
        buffers = self._buffers()
        samples = None
        if self.keep_samples:
            rank = np.arange(pixel.size) - np.repeat(np.cumsum(flat) - flat, flat)  # j-th new sample of its pixel
            color = np.zeros((int(flat.max(initial=0)), flat.size, 3), dtype=np.float32)
            color[rank, pixel] = self.truth.reshape(-1, 3)[pixel] * draws[:, None]
            samples = {"color": color.reshape(-1, self.height, self.width, 3)}
        return RoundBuffers(
            buffers=buffers,
            counts=self._n.reshape(self.height, self.width).astype(np.int32),
            seconds=time.perf_counter() - started,
            samples=samples,
        )

    def _buffers(self) -> dict[str, np.ndarray]:
        n = self._n.astype(np.float64)
        shape = (self.height, self.width)
        with np.errstate(divide="ignore", invalid="ignore"):
            mean_g = np.where(n > 0, self._sum / np.maximum(n, 1), 0.0)
            spread = np.where(n > 1, (self._sum2 - n * mean_g**2) / np.maximum(n - 1, 1), 0.0)
            var_g = np.where(n > 0, np.maximum(spread, 0.0) / np.maximum(n, 1), np.inf)
        color = self.truth * mean_g.reshape(shape)[..., None]
        unseen = np.isinf(var_g).reshape(shape)[..., None]
        color_var = np.where(unseen, np.inf, self.truth**2 * np.where(unseen, 0.0, var_g.reshape(shape)[..., None]))
        share = self.diffuse_fraction
        zeros = np.zeros(shape + (3,), dtype=np.float32)
        buffers = {
            "color": color,
            "color_var": color_var,
            "diffuse": color * share,
            "diffuse_var": color_var * share**2,
            "specular": color * (1 - share),
            "specular_var": color_var * (1 - share) ** 2,
            "albedo": np.clip(self.truth, 0.0, 1.0),  # noise-free features: the same with or without samples
            "albedo_var": zeros,
            "normal": np.broadcast_to(np.array([0.0, 0.0, 1.0]), shape + (3,)),
            "normal_var": zeros,
            "depth": np.ones(shape + (1,)),
            "depth_var": np.zeros(shape + (1,)),
        }
        return {name: np.ascontiguousarray(array, dtype=np.float32) for name, array in buffers.items()}


def noisy_half(width: int = 32, height: int = 16, *, quiet: float = 0.05, loud: float = 1.0, seed: int = 0):
    """A grey (0.5) image whose right half is ``loud`` noisy and whose left half is ``quiet``."""
    noise = np.full((height, width), quiet)
    noise[:, width // 2 :] = loud
    return SyntheticProgressiveFrame(np.full((height, width, 3), 0.5), noise, seed=seed)


def constant(width: int = 16, height: int = 16, *, noise: float = 0.0, seed: int = 0):
    """A constant grey (0.5) image with the same relative noise everywhere (0: noise-free)."""
    return SyntheticProgressiveFrame(np.full((height, width, 3), 0.5), np.full((height, width), noise), seed=seed)


def check_frame(width: int = 32, height: int = 32, *, seed: int = 0):
    """The convergence check's frame: a coloured ramp, a bright square, a dark corner and noise from 0.1 to 2.

    Noise rises left to right (0.1 to 2 per sample, relative); a 3×-bright square sits in the middle
    and the top-left corner is a dim 0.01, so a sampler meets edges, dark pixels and heavy tails.
    """
    y, x = np.mgrid[0:height, 0:width] / np.array([max(height - 1, 1), max(width - 1, 1)])[:, None, None]
    truth = np.stack([0.2 + 0.6 * x, 0.3 + 0.4 * y, 0.5 + 0.0 * x], axis=-1)
    square = (np.abs(x - 0.5) < 0.2) & (np.abs(y - 0.5) < 0.2)
    truth[square] *= 3.0
    truth[(x < 0.25) & (y < 0.25)] = 0.01
    noise = 0.1 + 1.9 * x
    return SyntheticProgressiveFrame(truth, noise, seed=seed)
