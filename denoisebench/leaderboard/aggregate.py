"""How per-scene scores become one number per denoiser: the metric's aggregation rule, with intervals.

Every place the leaderboard combines scenes (the summary table, ``denoisebench leaderboard``, the
flicker table) goes through :func:`aggregate`, so a plugin metric that states its rule
(:attr:`denoisebench.metrics.Metric.aggregate`) is combined correctly too.

Rules (DESIGN.md "Metrics"; the registry's docstring says why):

* ``mean``: arithmetic mean of the per-scene values (scale-free scores).
* ``geomean``: exp(mean(log value)). A brightness factor of one scene multiplies every denoiser's
  value alike, so it cannot reorder them. A value ≤ 0 (a perfect score) makes it 0.
* ``relative_to_input``: exp(mean(log(value / noisy input's value))) over the scenes where both
  exist and are > 0: the geometric-mean share of the input's score (the noisy row is 1).

Notes
-----
* **Intervals.** A percentile bootstrap over scenes (frames of one scene are not independent
  samples) of the mean on the rule's own scale (values, or logs), mapped back. When the scores
  carry a standard error from the reference's noise (``ses``; :mod:`denoisebench.metrics.floors`)
  every resample also adds a normal draw of that size to each scene's value (on the log scale:
  sqrt(log(1 + (se/value)²)), the spread of a log-normal with that mean and se; the delta method's
  se/value explodes where the se is comparable to the value, as for linear MSE on a reference
  with fireflies), so the interval includes the reference's uncertainty. Fixed seed:
  the same run gives the same interval. Fewer than 2 scenes: no interval.
* **Not distinguishable.** :func:`reference_resolution` is the half-width (95 %) of what the
  reference's noise alone allows between two denoisers' aggregated scores. Their reference-noise
  errors are correlated (one reference), and only each score's own se is stored, so the se of a
  difference is bounded by the sum of the two (|ρ| ≤ 1): conservative, it never claims a
  difference the reference cannot resolve.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

#: Bootstrap resamples and seed (fixed: the same run gives the same report).
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
#: Two-sided 95 % normal quantile.
Z95 = 1.959963984540054

__all__ = ["aggregate", "scene_terms", "bootstrap_mean", "reference_resolution", "rule_of"]


def rule_of(metric_name: str) -> str:
    """The aggregation rule of a registered metric; ``mean`` for names the registry does not know."""
    from denoisebench.metrics import get_metric

    try:
        return get_metric(metric_name).aggregate
    except ValueError:
        return "mean"


def _ok(v) -> bool:
    return v is not None and math.isfinite(v)


def log_se(se: float | None, value: float) -> float:
    """Standard deviation on the log scale of a positive value with standard error ``se`` (log-normal)."""
    if not se or value <= 0:
        return 0.0
    return math.sqrt(math.log1p((se / value) ** 2))


def scene_terms(rule: str, mine: dict, noisy: dict | None = None, ses: dict | None = None):
    """(terms, term ses, back-transform) on the rule's scale, over the scenes usable for ``rule``.

    ``mine``/``noisy``/``ses``: {scene: value}. Returns None for the transform when the geometric
    mean is 0 (a value ≤ 0).
    """
    ses = ses or {}
    scenes = sorted(s for s, v in mine.items() if _ok(v))
    if rule == "mean":
        return [mine[s] for s in scenes], [ses.get(s) or 0.0 for s in scenes], (lambda x: x)
    if rule == "geomean":
        if any(mine[s] <= 0 for s in scenes):
            return [], [], None
        return ([math.log(mine[s]) for s in scenes], [log_se(ses.get(s), mine[s]) for s in scenes], math.exp)
    if rule == "relative_to_input":
        noisy = noisy or {}
        keep = [s for s in scenes if _ok(noisy.get(s)) and noisy[s] > 0 and mine[s] > 0]
        return ([math.log(mine[s] / noisy[s]) for s in keep], [log_se(ses.get(s), mine[s]) for s in keep], math.exp)
    raise ValueError(f"unknown aggregation rule {rule!r}")


def bootstrap_mean(terms, ses=None) -> tuple[float | None, float | None]:
    """Percentile 95 % interval of the mean of ``terms``, each jittered by its se (see Notes)."""
    data = np.asarray(terms, dtype=np.float64)
    if data.size < 2:
        return None, None
    se = np.zeros_like(data) if ses is None else np.nan_to_num(np.asarray(ses, dtype=np.float64), nan=0.0)
    if not np.any(se > 0):
        if np.all(data == data[0]):
            return float(data[0]), float(data[0])
        from scipy.stats import bootstrap

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # few scenes: scipy warns that the distribution is degenerate
            result = bootstrap(
                (data,),
                np.mean,
                n_resamples=BOOTSTRAP_RESAMPLES,
                method="percentile",
                rng=np.random.default_rng(BOOTSTRAP_SEED),
            )
        return float(result.confidence_interval.low), float(result.confidence_interval.high)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    index = rng.integers(0, data.size, size=(BOOTSTRAP_RESAMPLES, data.size))
    samples = data[index] + rng.standard_normal(index.shape) * se[index]
    means = samples.mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def aggregate(rule: str, mine: dict, noisy: dict | None = None, ses: dict | None = None):
    """(value, low, high, scenes used) of per-scene values ``mine`` under ``rule`` (module docstring)."""
    terms, term_ses, back = scene_terms(rule, mine, noisy, ses)
    if back is None:  # geometric mean with a zero
        return 0.0, None, None, len([v for v in mine.values() if _ok(v)])
    if not terms:
        return None, None, None, 0
    low, high = bootstrap_mean(terms, term_ses)
    value = back(float(np.mean(terms)))
    return value, (None if low is None else back(low)), (None if high is None else back(high)), len(terms)


def reference_resolution(rule: str, mine_a: dict, ses_a: dict, mine_b: dict, ses_b: dict) -> float | None:
    """95 % half-width of the difference of two aggregates that the reference's noise allows.

    On the rule's scale (``mean``: score units; the geometric rules: log units, i.e. a ratio)
    over the scenes both have; None without stored ses.
    """
    scenes = sorted(s for s in mine_a if s in mine_b and _ok(mine_a[s]) and _ok(mine_b[s]))
    if not scenes or not any(_ok(ses_a.get(s)) or _ok(ses_b.get(s)) for s in scenes):
        return None
    total = 0.0
    for s in scenes:
        a, b = ses_a.get(s) or 0.0, ses_b.get(s) or 0.0
        if rule != "mean":
            if mine_a[s] <= 0 or mine_b[s] <= 0:
                return None
            a, b = log_se(a, mine_a[s]), log_se(b, mine_b[s])
        total += (a + b) ** 2
    return Z95 * math.sqrt(total) / len(scenes)
