"""Adaptive references: render in rounds until the reference's own noise floor is small enough.

A reference is noisy too. Its **noise floor** is the relMSE a perfect denoiser would score against
it, ``mean(var / (ref² + 0.01))`` over pixels and channels, where ``var`` is the variance of the
reference's per-pixel mean (the relMSE epsilon of docs/architecture.md, "Metrics"). :func:`render_adaptive`
renders a frame's reference in rounds of equal sample count until the floor estimate is at most
``ref_error``, or until the next round would pass ``cap`` samples per pixel (``--ref-spp``); such a
frame is marked ``stopped_at_cap``.

Rounds and seeds:
    Round ``k`` renders ``round_spp = max(1, cap // MAX_ROUNDS)`` samples with the sampler seed
    :func:`round_seed` ``(render_seed, frame, k)``: fresh, independent random numbers per round, and
    the same ones on every run, so a resumed dataset gets the same bytes. The reference uses at most
    ``MAX_ROUNDS * round_spp <= cap`` samples (the cap rounded down to whole rounds), and at least
    ``MIN_ROUNDS`` rounds (batch means need several batches).

Half references:
    The even rounds (0, 2, 4, ...) and the odd rounds are two independent references of about half
    the spp. The file keeps the even rounds' mean as ``color_half`` (the odd rounds' mean follows
    from the full one: ``(N · full − N_even · half) / N_odd``) and the record their spp as
    ``half_spp``. Scores without a closed-form noise floor (FLIP, SSIM, PSNR, ...) measure the
    reference's effect from them (the score against each half and against the full reference gives
    its 1/spp trend: ``denoisebench.metrics.floors.half_reference``).

Robust floor estimate (why not just the sample variance):
    Fireflies are rare, very bright paths. With them the per-sample variance is unbiased but very
    skewed: most pixels have not met their firefly yet and under-report, a few report huge values,
    and the estimate jumps as rounds add samples; stopping at the first estimate below the target
    then stops early exactly when luck hid the fireflies. Two independent unbiased estimates of the
    variance of the mean are computed each round, and the floor is the **larger** of them:

    * **batch means**: the rounds' per-pixel means ``m_k`` (K of them, equal sizes) are independent
      draws of a mean over ``round_spp`` samples; ``Σ_k (m_k − m̄)² / (K (K − 1))`` is the variance of
      ``m̄`` with no assumption about the per-sample distribution (each round mean is much closer to
      Gaussian than a single sample is, so its spread is a steadier measure);
    * **pooled sample variance**: the renderer's per-pixel M2 of all samples, merged over rounds
      (Chan et al.), divided by ``N (N − 1)``. This is what the reference file stores as
      ``color_var`` (the report's floor is computed from it).

    Taking the maximum errs towards rendering more. The relMSE denominator uses the current mean.

    No estimator can see a firefly that has not been sampled, and both estimates under-report while
    rare bright paths are still being found. That shows as a floor that falls more slowly than
    1/spp, so the loop also tracks :func:`floor_growth` (``spp × floor`` at all rounds over the same at
    half of them: ≈ 1 once every kind of path is sampled often) and does **not** stop on an estimate
    whose growth exceeds :data:`GROWTH_WARNING` (judged from ``2 * MIN_ROUNDS`` rounds on); the record keeps it, and ``generate`` warns about
    frames that end with it (their floor is a lower bound). Measured (32 px, cap 1024, three seeds
    each): cornell 1.008-1.014 and depth_of_field 1.004-1.020, glossy_fireflies 1.40-1.80. Against
    the spread of 16 independent 256-spp references (32 px), the estimate matched the floor on
    cornell (ratio 0.99) and under-reported it on glossy_fireflies (ratio 0.21).

The manifest records per frame (``reference_adaptive``): the target, the spp used, rounds, the
floor estimate that stopped the loop, the pooled floor, and whether the cap stopped it.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass

import numpy as np

#: relMSE epsilon (docs/architecture.md, "Metrics"): relMSE = mean((p − r)² / (r² + 0.01)).
RELMSE_EPSILON = 0.01
#: A frame is rendered in at most this many rounds of equal size (``round_spp = cap // MAX_ROUNDS``).
MAX_ROUNDS = 64
#: Batch means need a few batches before the floor is trusted.
MIN_ROUNDS = 4
#: Buffers merged over rounds (each with its ``_var``), in output order.
MERGED = ("color", "diffuse", "specular")
#: Stream id of round seeds (noisy renders use 0, single-pass references 1).
ROUND_STREAM = 2


def round_seed(render_seed: int, frame: int, round_index: int) -> int:
    """32-bit seed of reference round ``round_index`` of ``frame`` (BLAKE2b of the three and the stream)."""
    data = struct.pack("<qqqq", int(render_seed), int(frame), int(round_index), ROUND_STREAM)
    return int.from_bytes(hashlib.blake2b(data, digest_size=4).digest(), "little")


def round_schedule(cap: int) -> tuple[int, int]:
    """``(round_spp, max_rounds)`` for a cap of ``cap`` samples per pixel."""
    if cap < 1:
        raise ValueError(f"the reference spp cap must be >= 1 (got {cap})")
    round_spp = max(1, cap // MAX_ROUNDS)
    return round_spp, max(1, min(MAX_ROUNDS, cap // round_spp))


def floor_of(mean: np.ndarray, var_of_mean: np.ndarray) -> float:
    """The relMSE a perfect denoiser would score against ``mean``: mean(var / (mean² + 0.01))."""
    mean = np.asarray(mean, np.float64)
    return float(np.mean(np.asarray(var_of_mean, np.float64) / (np.square(mean) + RELMSE_EPSILON)))


class RoundMerger:
    """Per-pixel statistics of equal-size rounds: the overall mean, pooled M2, and the batch means' spread."""

    def __init__(self, round_spp: int):
        self.round_spp = int(round_spp)
        self.rounds = 0
        self._sum = {}  # name → Σ_k m_k
        self._m2 = {}  # name → Σ_k M2_k (within-round)
        self._sq = {}  # name → Σ_k m_k²
        self._even = None  # Σ of color's round means over the even rounds (0, 2, 4, ...): the half reference

    def add(self, buffers: dict) -> None:
        """Add one round's buffers (``name`` = mean of the round, ``name_var`` = variance of that mean)."""
        n = self.round_spp
        for name in MERGED:
            if name not in buffers:
                continue
            m = np.asarray(buffers[name], np.float64)
            within = np.asarray(buffers[f"{name}_var"], np.float64) * n * (n - 1)  # the round's M2
            if name not in self._sum:
                self._sum[name], self._m2[name], self._sq[name] = np.zeros_like(m), np.zeros_like(m), np.zeros_like(m)
            self._sum[name] += m
            self._m2[name] += within
            self._sq[name] += np.square(m)
            if name == "color" and self.rounds % 2 == 0:
                self._even = m.copy() if self._even is None else self._even + m
        self.rounds += 1

    @property
    def half_spp(self) -> tuple[int, int] | None:
        """(spp of the even rounds, spp of the odd rounds): the two independent half references; None
        with fewer than 2 rounds."""
        if self.rounds < 2:
            return None
        even = (self.rounds + 1) // 2
        return even * self.round_spp, (self.rounds - even) * self.round_spp

    @property
    def spp(self) -> int:
        return self.rounds * self.round_spp

    def mean(self, name: str = "color") -> np.ndarray:
        return self._sum[name] / self.rounds

    def pooled_var(self, name: str = "color") -> np.ndarray:
        """Variance of the overall mean from all samples: (Σ M2_k + n Σ (m_k − m̄)²) / (N (N − 1))."""
        n, total = self.round_spp, self.spp
        if total < 2:
            return np.zeros_like(self._sum[name])
        return (self._m2[name] + n * self._between(name)) / (total * (total - 1))

    def batch_var(self, name: str = "color") -> np.ndarray:
        """Variance of the overall mean from the spread of the round means (needs 2 rounds)."""
        k = self.rounds
        if k < 2:
            return np.full_like(self._sum[name], np.inf)
        return self._between(name) / (k * (k - 1))

    def _between(self, name: str) -> np.ndarray:
        """Σ_k (m_k − m̄)² of the round means (clamped at 0 against rounding)."""
        return np.maximum(self._sq[name] - np.square(self._sum[name]) / self.rounds, 0.0)

    def floors(self) -> tuple[float, float]:
        """(robust floor = max of both estimates, pooled floor) of color."""
        mean = self.mean()
        pooled = floor_of(mean, self.pooled_var())
        if self.rounds < 2:  # one batch has no spread: the pooled estimate alone
            return pooled, pooled
        return max(pooled, floor_of(mean, self.batch_var())), pooled

    def buffers(self) -> dict:
        """float32 buffers for the reference file: every merged name with its ``_var`` (pooled)."""
        out = {}
        for name in self._sum:
            out[name] = self.mean(name).astype(np.float32)
            out[f"{name}_var"] = self.pooled_var(name).astype(np.float32)
        if self.half_spp is not None and self._even is not None:
            # the even rounds' mean: one of two independent half references (the other is the odd
            # rounds', recovered from the full mean: metrics.half_reference)
            out["color_half"] = (self._even / ((self.rounds + 1) // 2)).astype(np.float32)
        return out


#: ``floor_growth`` above this flags a floor estimate that is still rising with spp (unresolved fireflies).
GROWTH_WARNING = 1.25


def floor_growth(history: list) -> float | None:
    """How much ``spp × floor`` grew from half the rounds to all of them (1.0: the estimate falls as 1/spp,
    as it does once every kind of path has been sampled often; > 1: rare bright paths are still being
    found, so the estimate is a lower bound). None with fewer than 2 rounds."""
    rounds = len(history)
    if rounds < 2:
        return None
    half = rounds // 2
    before, after = history[half - 1] * half, history[-1] * rounds
    if not (before > 0 and np.isfinite(before) and np.isfinite(after)):
        return None
    return float(after / before)


@dataclass
class AdaptiveOutcome:
    """What :func:`render_adaptive` returns: merged buffers and the record for the manifest."""

    buffers: dict
    spp: int
    seconds: float
    compile_seconds: float
    record: dict


def render_adaptive(render_round, cap: int, ref_error: float) -> AdaptiveOutcome:
    """Render rounds with ``render_round(round_index, round_spp) -> (buffers, seconds, compile_seconds)``
    until the robust floor is <= ``ref_error`` (after at least :data:`MIN_ROUNDS`) or the cap."""
    if not ref_error > 0:
        raise ValueError(f"ref_error must be > 0 (got {ref_error})")
    round_spp, max_rounds = round_schedule(cap)
    merger = RoundMerger(round_spp)
    seconds = compile_seconds = 0.0
    floor = pooled = float("inf")
    history = []
    for k in range(max_rounds):
        buffers, sec, comp = render_round(k, round_spp)
        merger.add(buffers)
        seconds += sec
        compile_seconds += comp
        floor, pooled = merger.floors()
        history.append(floor)
        if merger.rounds >= min(MIN_ROUNDS, max_rounds) and merger.spp > 1 and floor <= ref_error:
            # A rising estimate is not trusted to stop on; growth is judged from 2 * MIN_ROUNDS rounds on
            # (over fewer, it is mostly the noise of a few samples per pixel).
            growth = floor_growth(history) if merger.rounds >= 2 * MIN_ROUNDS else None
            if growth is None or growth <= GROWTH_WARNING:
                break
    growth = floor_growth(history)
    if merger.spp < 2:  # one sample per pixel: no variance to estimate, so no floor (None in the record)
        floor = pooled = None
    reached = floor is not None and floor <= ref_error
    record = {
        "ref_error": float(ref_error),
        "spp": merger.spp,
        "cap": int(cap),
        "round_spp": round_spp,
        "rounds": merger.rounds,
        "floor": floor,
        "floor_pooled": pooled,
        "floor_growth": growth,
        "half_spp": list(merger.half_spp) if merger.half_spp is not None else None,
        "stopped_at_cap": not reached,
        "seconds": seconds,
    }
    return AdaptiveOutcome(merger.buffers(), merger.spp, seconds, compile_seconds, record)
