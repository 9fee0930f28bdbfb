"""How per-scene scores become one number per denoiser: the metric's aggregation rule, with intervals.

Every place that combines scenes (the report's summary table, ``denoisebench leaderboard``, the
flicker table) goes through :func:`aggregate`, so a plugin metric that states its rule
(:attr:`denoisebench.metrics.Metric.aggregate`) is combined correctly too.

Rules (docs/architecture.md, "Metrics"; the registry's docstring says why):

* ``mean``: arithmetic mean of the per-scene values (scale-free scores).
* ``geomean``: exp(mean(log value)). A brightness factor of one scene multiplies every denoiser's
  value alike, so it cannot reorder them. A value ≤ 0 (a perfect score) makes it 0.
* ``relative_to_input``: exp(mean(log(value / noisy input's value))) over the scenes where both
  exist and are > 0: the geometric-mean share of the input's score (the noisy row is 1).

Notes
-----
* **Intervals.** A percentile bootstrap over scenes (frames of one scene are not independent
  samples) of the mean on the rule's own scale (values, or logs), mapped back. When the scores
  carry a standard error from the reference's noise (``ses``; :mod:`denoisebench.metrics.floors.closed_form`)
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
* **Corrected scores lead** (:func:`corrected_values`). Every score with a reference-noise floor
  (the MSE family, their robust and temporal forms) is aggregated as ``score − floor`` per scene:
  an unbiased estimate of the error against the noise-free image, whose interval carries the
  reference's uncertainty (its se, above). A per-scene corrected value below its own se (what the
  reference can still resolve) is raised to that se: the log-scale rules and the log axes need a
  positive value, and a value the reference cannot tell from 0 is reported as "at most what the
  reference resolves". The raise only ever makes a score worse, by less than one se, and the cells
  count the scenes where it happened (``at_resolution``). Raw values stay beside the corrected ones.
* **Measured floors** (:func:`leading_floor`). A score with a closed-form floor also has its floor
  measured from the reference's two independent halves (the score against each half, extrapolated
  to the full reference: :mod:`denoisebench.metrics.floors.half_reference`). The closed form rests on the
  reference's per-pixel variance and a smooth expansion; a heavy-tailed pixel (a rare bright path
  that one half found and the variance estimate did not see) escapes it, the halves do not. Where
  the two disagree by more than the measured floor's 95 % uncertainty, the measured one corrects the
  score (and its se widens the intervals); the cell names those scenes (``measured_floor_leads``).
  The set-apart rule below then judges the corrected scores with the floor that led.
* **References whose scores cannot be used** (:func:`unresolved_references`). A scene is set apart
  only when even its corrected numbers cannot rank, for one of three reasons, judged on the headline
  scores that have floors (the robust relMSE and the robust flicker score; their raw forms for runs
  without them), over every label (noisy input included) and every measured spp:

  - ``floor_growing``: the floor estimate was still growing when rendering stopped (``floor_growth``
    in the manifest above :data:`GROWTH_LIMIT`, 1.25: rare bright paths were still being found, so
    the floor is a lower bound and the correction too small);
  - ``reference_too_noisy``: more than :data:`NOISY_VALUES_LIMIT` of the reference's values have a
    noise comparable to their signal (variance above ``floors.SECOND_ORDER_LIMIT · (r² + 0.01)``),
    where the floor's expansion is outside its stated validity (:mod:`denoisebench.metrics.floors.closed_form`);
  - ``cannot_rank``: no two entries on the scene (denoisers and the noisy input, at every spp) differ
    by more than the reference resolves (95 %, the two se added): nothing there can be ranked.

  Such a scene is listed apart with its reason and the reference spp that would bring its floor to a
  tenth of the best score (the floor falls as 1/spp once every kind of path is sampled, so
  ``ref_spp · floor / (0.1 · best)``; for a growing floor at least twice the spp it has, a lower
  bound), is left out of the headline aggregates unless asked for
  (``run-benchmark --include-unresolved``), and keeps its raw and corrected rows in results.json.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from denoisebench.metrics import get_metric
from denoisebench.results.finite import is_finite

# Lazy imports: scipy (0.3 s) only where a bootstrap interval is drawn.

#: Bootstrap resamples and seed (fixed: the same run gives the same report).
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
#: Two-sided 95 % normal quantile.
Z95 = 1.959963984540054

#: The spp a set-apart scene's reference would need is the one bringing its floor to this fraction of the best score.
RESOLVE_FRACTION = 0.1
#: A reference with more than this share of values whose noise is comparable to their signal has no usable floor.
NOISY_VALUES_LIMIT = 0.05
#: ``floor_growth`` above this: the floor estimate was still rising (generator.render.reference.GROWTH_WARNING).
GROWTH_LIMIT = 1.25
#: The scores the rule is judged on, each pair in order of preference (the robust form, else the raw one).
RESOLUTION_METRICS = (("relmse_robust", "relmse"), ("temporal_relmse_robust", "temporal_relmse"))

__all__ = [
    "aggregate",
    "scene_terms",
    "bootstrap_mean",
    "reference_resolution",
    "SceneFloors",
    "leading_floor",
    "rule_of",
    "RESOLVE_FRACTION",
    "NOISY_VALUES_LIMIT",
    "corrected_values",
    "GROWTH_LIMIT",
    "Unresolved",
    "reference_states",
    "unresolved_references",
    "excluded_scenes",
]


def rule_of(metric_name: str) -> str:
    """The aggregation rule of a registered metric; ``mean`` for names the registry does not know."""
    try:
        return get_metric(metric_name).aggregate
    except ValueError:
        return "mean"


def log_se(se: float | None, value: float) -> float:
    """Standard deviation on the log scale of a positive value with standard error ``se`` (log-normal)."""
    if not se or value <= 0:
        return 0.0
    ratio = se / value
    if ratio > 1e150:  # (se/value)² beyond the floats: log1p(r²) = 2·log(r) to every digit there
        return math.sqrt(2.0 * math.log(ratio))
    return math.sqrt(math.log1p(ratio**2))


def _exp(x: float) -> float:
    """``math.exp`` held within the floats: the back-transform of a mean of logs is always finite."""
    return math.exp(min(max(x, -745.0), 709.0))


def scene_terms(rule: str, mine: dict, noisy: dict | None = None, ses: dict | None = None):
    """(terms, term ses, back-transform) on the rule's scale, over the scenes usable for ``rule``.

    ``mine``/``noisy``/``ses``: {scene: value}. Returns None for the transform when the geometric
    mean is 0 (a value ≤ 0).
    """
    ses = ses or {}
    scenes = sorted(s for s, v in mine.items() if is_finite(v))
    if rule == "mean":
        return [mine[s] for s in scenes], [ses.get(s) or 0.0 for s in scenes], (lambda x: x)
    if rule == "geomean":
        if any(mine[s] <= 0 for s in scenes):
            return [], [], None
        return ([math.log(mine[s]) for s in scenes], [log_se(ses.get(s), mine[s]) for s in scenes], _exp)
    if rule == "relative_to_input":
        noisy = noisy or {}
        keep = [s for s in scenes if is_finite(noisy.get(s)) and noisy[s] > 0 and mine[s] > 0]
        terms = [math.log(mine[s]) - math.log(noisy[s]) for s in keep]  # a ratio may underflow, its log not
        return (terms, [log_se(ses.get(s), mine[s]) for s in keep], _exp)
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
    with np.errstate(over="ignore", invalid="ignore"):
        means = samples.mean(axis=1)
        low, high = float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))
    if not (math.isfinite(low) and math.isfinite(high)):
        return None, None  # jitter beyond the floats: no interval rather than an infinite one
    return low, high


def bootstrap_over_scenes(
    scores: dict[str, list[float]],
    frame_scene: list[str],
    model: str,
    peers: list[str],
    *,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
):
    """95 % percentile intervals of each denoiser's mean score over frames and of ``model``/peer
    ratios of those means (the model cards' intervals).

    Frames of one scene are correlated (same geometry and light), so the resampled unit is the
    scene: each draw picks len(scenes) scenes with replacement and takes the mean over all their
    frames, for every denoiser with the same draw (the ratios are paired). Deterministic (``seed``).
    """
    scenes = sorted(set(frame_scene))
    index = {scene: i for i, scene in enumerate(scenes)}
    owner = np.array([index[s] for s in frame_scene])
    rng = np.random.default_rng(seed)
    counts = np.stack(
        [np.bincount(rng.integers(0, len(scenes), len(scenes)), minlength=len(scenes)) for _ in range(resamples)]
    )  # resamples × scenes: how often each scene is drawn
    weights = counts[:, owner].astype(np.float64)  # resamples × frames
    means = {name: weights @ np.asarray(values, np.float64) / weights.sum(axis=1) for name, values in scores.items()}
    intervals = {name: [float(v) for v in np.percentile(m, [2.5, 97.5])] for name, m in means.items()}
    ratios = {}
    for peer in peers:
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = means[model] / means[peer]
        finite = ratio[np.isfinite(ratio)]
        ratios[peer] = [float(v) for v in np.percentile(finite, [2.5, 97.5])] if finite.size else None
    return intervals, ratios


def aggregate(rule: str, mine: dict, noisy: dict | None = None, ses: dict | None = None):
    """(value, low, high, scenes used) of per-scene values ``mine`` under ``rule`` (module docstring)."""
    terms, term_ses, back = scene_terms(rule, mine, noisy, ses=ses)
    if back is None:  # geometric mean with a zero
        return 0.0, None, None, len([v for v in mine.values() if is_finite(v)])
    if not terms:
        return None, None, None, 0
    low, high = bootstrap_mean(terms, term_ses)
    value = back(float(np.mean(terms)))
    return value, (None if low is None else back(low)), (None if high is None else back(high)), len(terms)


def corrected_values(
    mine: dict, floors: dict, ses: dict | None = None, higher_is_better: bool = False
) -> tuple[dict, list[str]]:
    """({scene: score − floor}, scenes raised to their se) over the scenes of ``mine`` with a floor.

    A corrected error below the scene's se (the reference's standard error of that score) is raised
    to it (module Notes); with no se (a reference without variance) a value ≤ 0 keeps its raw score.
    A higher-is-better score (SSIM, PSNR: their floor is measured from half references) is only
    corrected, never raised.
    """
    ses = ses or {}
    out, raised = {}, []
    for scene, value in mine.items():
        floor = floors.get(scene)
        if not is_finite(value) or not is_finite(floor):
            out[scene] = value
            continue
        corrected = value - floor
        se = ses.get(scene)
        if higher_is_better:
            out[scene] = corrected
            continue
        if is_finite(se) and se > 0:
            if corrected < se:
                corrected = se
                raised.append(scene)
        elif corrected <= 0:
            corrected = value
        out[scene] = corrected
    return out, sorted(raised)


@dataclass(frozen=True, kw_only=True)
class SceneFloors:
    """A score's reference-noise floors on one scene: the closed form's (``closed``, with the score's se
    ``closed_se``), the one measured from the reference's two halves (``measured``, ``measured_se``), and
    the one that leads (``floor``/``se``; ``source``: ``closed_form``, ``measured`` or ``none``)."""

    closed: float | None
    closed_se: float | None
    measured: float | None
    measured_se: float | None
    floor: float | None
    se: float | None
    source: str


def leading_floor(closed, closed_se, measured, measured_se) -> SceneFloors:
    """The floor a scene's score is corrected with (module Notes, "Measured floors").

    The measured one leads where it and the closed form disagree by more than the measured one's 95 %
    uncertainty (Z95 × its se), or where there is no closed form; else the closed form (smoother: it
    rests on every pixel's variance, not on one draw of two halves). Where the measured floor leads,
    the se is the larger of the score's and the measured floor's."""
    parts = {"closed": closed, "closed_se": closed_se, "measured": measured, "measured_se": measured_se}
    if not is_finite(measured):
        return SceneFloors(**parts, floor=closed, se=closed_se, source="none" if closed is None else "closed_form")
    if closed is None:
        return SceneFloors(**parts, floor=measured, se=measured_se, source="measured")
    if abs(measured - closed) > Z95 * (measured_se or 0.0):
        se = max(x for x in (closed_se, measured_se, 0.0) if is_finite(x))
        return SceneFloors(**parts, floor=measured, se=se if se > 0 else None, source="measured")
    return SceneFloors(**parts, floor=closed, se=closed_se, source="closed_form")


def reference_resolution(rule: str, mine_a: dict, ses_a: dict, mine_b: dict, ses_b: dict) -> float | None:
    """95 % half-width of the difference of two aggregates that the reference's noise allows.

    On the rule's scale (``mean``: score units; the geometric rules: log units, i.e. a ratio)
    over the scenes both have; None without stored ses.
    """
    scenes = sorted(s for s in mine_a if s in mine_b and is_finite(mine_a[s]) and is_finite(mine_b[s]))
    if not scenes or not any(is_finite(ses_a.get(s)) or is_finite(ses_b.get(s)) for s in scenes):
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


# --------------------------------------------------------------------------------------------------
# references that cannot resolve a score


@dataclass(frozen=True, kw_only=True)
class Unresolved:
    """One scene whose reference cannot resolve a score (module Notes): why, and what it would need.

    ``reason``: ``"floor_growing"``, ``"reference_too_noisy"`` or ``"cannot_rank"``. ``metric``/``spp``/``label``/``best``/
    ``floor``: the best score on the scene, where it was reached and its floor (``floor_growing``:
    those of the judged metric, possibly None). ``needed_spp``: the reference spp that would bring
    the floor to a tenth of the best score; ``needed_is_lower_bound`` when the floor is still growing.
    ``noisy_share``: the reference's share of values beyond the floor's validity (``reference_too_noisy``).
    """

    scene: str
    reason: str
    metric: str | None
    reference_spp: int | None
    floor_growth: float | None
    best: float | None
    label: str | None
    spp: int | None
    floor: float | None
    needed_spp: int | None
    needed_is_lower_bound: bool
    noisy_share: float | None = None

    def sentence(self) -> str:
        """One line for a report: the scene, the reason in words, the spp it would need."""
        need = ""
        if self.needed_spp is not None:
            need = f"; it would need {'at least ' if self.needed_is_lower_bound else ''}{self.needed_spp} spp"
        have = f"{self.reference_spp}-spp reference" if self.reference_spp else "reference"
        if self.reason == "floor_growing":
            growth = f"{self.floor_growth:.2f}" if self.floor_growth is not None else "?"
            why = (
                f"its {have}'s noise floor estimate was still growing (spp × floor ×{growth} from half the "
                "samples to all: rare bright paths not yet resolved, so the floor and the correction are too low)"
            )
        elif self.reason == "reference_too_noisy":
            share = f"{100 * self.noisy_share:.1f} %" if self.noisy_share is not None else "many"
            why = (
                f"its {have} is too noisy for a floor: {share} of its values have a noise comparable to their "
                f"signal (over {100 * NOISY_VALUES_LIMIT:g} %), where the floor's approximation does not hold"
            )
        else:
            why = (
                f"no two entries there differ by more than its {have} resolves in {self.metric} (corrected "
                f"scores; best {self.label} at {self.spp} spp: {self.best:.3g}, floor {self.floor:.3g})"
            )
        return f"{self.scene}: {why}{need}"

    def as_dict(self) -> dict:
        return {**asdict(self), "sentence": self.sentence()}


def reference_states(scene_records: dict[str, dict]) -> dict[str, dict]:
    """{scene: {"spp": reference spp, "floor_growth": largest over its frames or None}} from manifest
    scene records (``dataset.scene(name).record``, or ``manifest["scenes"]``)."""
    out = {}
    for scene, record in scene_records.items():
        growth, spps = [], []
        for frame in (record.get("renders", {}) or {}).get("reference", {}).values():
            adaptive = frame.get("reference_adaptive") or {}
            if adaptive.get("floor_growth") is not None:
                growth.append(float(adaptive["floor_growth"]))
            spp = adaptive.get("spp") or frame.get("spp")
            if spp:
                spps.append(int(spp))
        ref_spp = max(spps) if spps else record.get("ref_spp")  # the spp used (adaptive: below the cap)
        out[scene] = {"spp": int(ref_spp) if ref_spp else None, "floor_growth": max(growth) if growth else None}
    return out


def _can_rank(data, scene: str, metric: str) -> bool | None:
    """Whether two entries on ``scene`` differ in ``metric`` by more than the reference resolves.

    Entries are every (label, spp) (the noisy input at rising spp is the curve a report compares
    against); corrected scores (:func:`corrected_values`). A difference is resolved when it exceeds
    1.96 × (se_a + se_b) (one reference: correlated, so the sum bounds the se of the difference).
    Identical outputs (identity and the input) are no pair to judge. None when nothing can be judged
    (no se stored, or every entry the same)."""
    entries = []
    for spp in data.spp:
        for label in data.labels:
            values, floors, ses = data.per_scene(label, spp, metric, scenes=[scene])
            if scene not in values or not is_finite(values[scene]):
                continue
            corrected, _ = corrected_values(values, floors, ses)
            entries.append((values[scene], corrected[scene], ses.get(scene)))
    judged = False
    for i, (raw_a, a, sa) in enumerate(entries):
        for raw_b, b, sb in entries[i + 1 :]:
            if not (is_finite(sa) or is_finite(sb)) or math.isclose(raw_a, raw_b, rel_tol=1e-12, abs_tol=0.0):
                continue
            judged = True
            if abs(a - b) > Z95 * ((sa or 0.0) + (sb or 0.0)):
                return True
    return False if judged else None


def _needed(ref_spp: int | None, floor: float | None, best: float | None, fraction: float) -> int | None:
    if not ref_spp or floor is None or best is None or not (best > 0 and floor > 0):
        return None
    return int(math.ceil(ref_spp * floor / (fraction * best)))


def unresolved_references(
    data,
    references: dict[str, dict],
    *,
    fraction: float = RESOLVE_FRACTION,
    growth_limit: float = GROWTH_LIMIT,
    noisy_limit: float = NOISY_VALUES_LIMIT,
    metrics=RESOLUTION_METRICS,
) -> list[Unresolved]:
    """The scenes of a run whose corrected scores cannot rank anything (module Notes).

    ``data``: a :class:`denoisebench.analysis.summary.RunData` (``scenes``, ``labels``, ``spp``,
    ``per_scene(label, spp, metric)`` and the metric names); ``references``: :func:`reference_states`,
    optionally with ``noisy_share`` per scene (the reference's share of values beyond the floor's
    validity). One entry per scene and reason, floor growth first; lower-is-better scores with floors.
    ``fraction`` only sizes the advice (the spp that brings the floor to that share of the best score).
    """
    measured = set(data.frame_metric_names) | set(data.sequence_metric_names)
    judged = [next((m for m in pair if m in measured), None) for pair in metrics]
    judged = [m for m in judged if m is not None and not higher_is_better(m)]
    out: list[Unresolved] = []
    for scene in data.scenes:
        state = references.get(scene) or {}
        ref_spp, growth, share = state.get("spp"), state.get("floor_growth"), state.get("noisy_share")
        bests = []
        for metric in judged:
            best = None  # (value, label, spp, floor)
            for label in data.labels:
                for spp in data.spp:
                    values, floors, _ = data.per_scene(label, spp, metric, scenes=[scene])
                    value = values.get(scene)
                    if value is not None and (best is None or value < best[0]):
                        best = (value, label, spp, floors.get(scene))
            if best is not None:
                bests.append((metric, *best))
        first = bests[0] if bests else (None, None, None, None, None)

        def entry(reason: str, best: tuple, *, needed, lower_bound: bool, noisy_share=None) -> Unresolved:
            metric, value, label, spp, floor = best
            return Unresolved(
                scene=scene,
                reason=reason,
                metric=metric,
                reference_spp=ref_spp,
                floor_growth=growth,
                best=value,
                label=label,
                spp=spp,
                floor=floor,
                needed_spp=needed,
                needed_is_lower_bound=lower_bound,
                noisy_share=noisy_share,
            )

        if growth is not None and growth > growth_limit:
            needed = _needed(ref_spp, first[4], first[1], fraction=fraction)
            needed = max(needed or 0, 2 * ref_spp) if ref_spp else needed
            out.append(entry("floor_growing", first, needed=needed, lower_bound=True))
            continue
        if share is not None and share > noisy_limit:
            needed = _needed(ref_spp, first[4], first[1], fraction=fraction)
            out.append(entry("reference_too_noisy", first, needed=needed, lower_bound=False, noisy_share=share))
            continue
        for best in bests:
            metric, value, _, _, floor = best
            if floor is not None and _can_rank(data, scene, metric) is False:
                needed = _needed(ref_spp, floor, value, fraction=fraction)
                out.append(entry("cannot_rank", best, needed=needed, lower_bound=False))
                break
    return out


def excluded_scenes(unresolved: list[Unresolved]) -> list[str]:
    """The scenes the headline aggregates leave out (sorted, each once)."""
    return sorted({u.scene for u in unresolved})


def higher_is_better(metric: str) -> bool:
    """The registry's direction of ``metric``; False (an error) for names it does not know."""

    try:
        return get_metric(metric).higher_is_better
    except ValueError:
        return False
