"""The number that leads a score across scenes: one that no single scene can move by orders of magnitude.

The arithmetic mean of per-scene scores is decided by the scene with the largest score: on the demo
one scene (glossy_fireflies, small emitters of radiance ~1e4) held oidn's relMSE at 703 against the
input's 0.514 while OIDN was best on the four other scenes. The leading aggregate of the lead scores
(:data:`LEAD_SCORES`: spatial, gradient and temporal error) is therefore the **anchored trimmed
geometric mean** (:func:`lead_aggregate`):

1. Each scene's score is divided by its **anchor**, the noisy input's score on that scene at the run's
   lowest spp (the scene's difficulty: scale-free scores still differ by orders of magnitude
   between a flat wall and a firefly-lit room). One anchor per scene for every label and spp, so the
   curves over spp keep their shape and the noisy input's own curve falls as its error falls.
2. The logs of these ratios are averaged over scenes **without the ⌈12.5 %⌉ highest and lowest**
   (:func:`trimmed_count`: one of 3 to 8 scenes at each end, the rule that drops frames within a
   scene, :mod:`.run_index`); with 1 or 2 scenes nothing is dropped and nothing can be robust.
3. The result is a **share of the lowest-spp input's error** (the noisy input reads 1 at the lowest
   spp and falls from there): a number without the score's units, since any scale made of the
   scenes' own values (the anchors' geometric mean, say) moves again when a scene is dropped
   (measured on the demo's values: a trimmed scale moved the aggregate 1.9× where the share moved
   1.13×). The arithmetic mean beside it keeps the score's units.

Why this one (measured, docs/measurements.md): the plain geometric mean of the ratios already keeps
a scene's brightness out, but with five scenes one scene whose ratio is 1000× the others' moves it
by 1000^(1/5) ≈ 4× when dropped; trimmed, one scene moves it at most by the spread of the others
(a scene that is dropped changes which values are kept, never by more than the next value in line).
The bootstrap interval over scenes (:func:`.aggregate.bootstrap_mean`'s resampling, the same seed)
resamples scenes with their anchors and applies the same estimator.

Beside it, every cell keeps the **arithmetic mean** of the per-scene scores and names the
**deciding scenes**: those carrying more than half of that mean (:func:`deciding_scenes`), whose
image comparisons a report shows.

Notes
-----
* A scene without a positive, finite anchor (the noisy input not measured there at the lowest spp, or
  a score of 0) is left out of the lead aggregate; the cell counts the scenes used.
* Values ≤ 0 cannot enter a log: such a scene is left out the same way (a corrected score is raised
  to the reference's resolution before it gets here, :func:`.aggregate.corrected_values`).
* Returns None (no answer) when no scene is usable; never raises on finite or missing values.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.results.finite import is_finite

#: Scores whose cells lead with :func:`lead_aggregate` (spatial, gradient, temporal error; unbounded).
LEAD_SCORES = ("relmse_robust", "relmse", "grad_l1", "hfen", "temporal_relmse_robust", "temporal_relmse")
#: Share of scenes dropped at each end of the sorted log ratios (at least 3 scenes): as frames in a scene.
SCENE_TRIM = 0.125
#: The lead aggregate's name in results.json (``aggregate`` of a metric cell).
LEAD_RULE = "anchored_trimmed_geomean"
#: A scene carrying more than this share of an arithmetic mean decides it.
DECIDING_SHARE = 0.5
#: Bootstrap resamples and seed (fixed: the same run gives the same report).
RESAMPLES = 2000
SEED = 0

__all__ = [
    "LEAD_SCORES",
    "LEAD_RULE",
    "SCENE_TRIM",
    "DECIDING_SHARE",
    "is_lead_score",
    "trimmed_count",
    "trimmed_log_mean",
    "lead_aggregate",
    "lead_value",
    "arithmetic_mean",
    "deciding_scenes",
    "drop_one_factor",
]


def is_lead_score(metric: str) -> bool:
    """Whether ``metric``'s cells lead with the anchored trimmed geometric mean."""
    return metric in LEAD_SCORES


def trimmed_count(n: int) -> int:
    """Values dropped at each end of ``n`` sorted values: ⌈SCENE_TRIM · n⌉ from 3 values on, else 0."""
    if n < 3:
        return 0
    return min(math.ceil(SCENE_TRIM * n), (n - 1) // 2)


def trimmed_log_mean(values) -> float | None:
    """Mean of ``values`` (already on the log scale) without the :func:`trimmed_count` lowest and highest."""
    data = sorted(float(v) for v in values if is_finite(v))
    if not data:
        return None
    k = trimmed_count(len(data))
    kept = data[k : len(data) - k]
    return float(sum(kept) / len(kept))


def _usable(mine: dict, anchors: dict) -> list[str]:
    return sorted(s for s, v in mine.items() if is_finite(v) and v > 0 and is_finite(anchors.get(s)) and anchors[s] > 0)


def _estimate(log_ratios: np.ndarray) -> np.ndarray:
    """Row-wise estimator over the last axis: the trimmed mean of the log ratios."""
    n = log_ratios.shape[-1]
    k = trimmed_count(n)
    return np.sort(log_ratios, axis=-1)[..., k : n - k].mean(axis=-1)


def lead_value(mine: dict, anchors: dict) -> float | None:
    """:func:`lead_aggregate`'s value alone (no interval): None when no scene is usable."""
    scenes = _usable(mine, anchors)
    if not scenes:
        return None
    return _exp(float(_estimate(np.array([math.log(mine[s]) - math.log(anchors[s]) for s in scenes]))))


def lead_aggregate(mine: dict, anchors: dict) -> tuple[float | None, float | None, float | None, int]:
    """(value, low, high, scenes used) of per-scene scores ``mine`` with per-scene ``anchors`` (module Notes).

    ``low``/``high``: percentile 95 % bootstrap over scenes (None with fewer than 2 scenes)."""
    scenes = _usable(mine, anchors)
    if not scenes:
        return None, None, None, 0
    log_ratios = np.array([math.log(mine[s]) - math.log(anchors[s]) for s in scenes])
    value = _exp(float(_estimate(log_ratios)))
    if len(scenes) < 2:
        return value, None, None, 1
    rng = np.random.default_rng(SEED)
    index = rng.integers(0, len(scenes), size=(RESAMPLES, len(scenes)))
    samples = _estimate(log_ratios[index])
    low, high = np.percentile(samples, [2.5, 97.5])
    return value, _exp(float(low)), _exp(float(high)), len(scenes)


def _exp(x: float) -> float:
    """exp clamped to the float range (a finite answer for any finite log)."""
    return math.exp(min(max(x, -745.0), 709.0))


def arithmetic_mean(mine: dict) -> float | None:
    """Arithmetic mean of the finite per-scene values (None without one)."""
    values = [float(v) for v in mine.values() if is_finite(v)]
    if not values:
        return None
    return math.fsum(v / len(values) for v in values)  # each term divided first: no overflow


def deciding_scenes(mine: dict, share: float = DECIDING_SHARE) -> list[tuple[str, float]]:
    """[(scene, share of the arithmetic mean)] of the scenes carrying more than ``share`` of it.

    Only for non-negative values (a share of a sum is meaningless when values cancel); at most one
    scene can carry more than half."""
    values = {s: float(v) for s, v in mine.items() if is_finite(v)}
    if len(values) < 2 or any(v < 0 for v in values.values()):
        return []
    mean = arithmetic_mean(values)
    if not mean or not mean > 0:
        return []
    n = len(values)
    return sorted(((s, v / n / mean) for s, v in values.items() if v / n / mean > share), key=lambda x: -x[1])


def drop_one_factor(mine: dict, anchors: dict) -> float | None:
    """The largest factor by which dropping one scene moves :func:`lead_aggregate` (≥ 1), None with < 2 scenes."""
    scenes = _usable(mine, anchors)
    if len(scenes) < 2:
        return None
    full = lead_value({s: mine[s] for s in scenes}, anchors)
    worst = 1.0
    for out in scenes:
        value = lead_value({s: mine[s] for s in scenes if s != out}, anchors)
        if value and full:
            worst = max(worst, value / full, full / value)
    return worst
