"""Numbers a report is made of, computed from one run in the results store (no drawing, no HTML).

* :func:`summary_table`: per denoiser and input spp, every metric aggregated over scenes by its
  rule (:mod:`.aggregate`: scale-free scores by mean, linear ones relative to the noisy input or by
  geometric mean) with a bootstrap 95 % interval over **scenes** (frames of one scene are not
  independent samples) that includes the reference's uncertainty; MSE-family metrics also carry
  their reference-noise floor and the floor-corrected value; and seconds per frame.
* :func:`indistinguishable_pairs`: pairs of denoisers whose scores differ by less than the
  reference's noise can resolve ("not distinguishable at this reference quality").
* :func:`accuracy_time`: per denoiser and spp, mean error (robust relMSE, relMSE, FLIP) against total
  seconds per frame (render at that spp + denoise, at the time model's resolution); the noisy
  inputs as the "just render more samples" curve; the Pareto front; and the reading in words
  (:func:`readings`).
* :func:`effect_breakdown`: per denoiser and scene effect, the share of the input's error left.
* :func:`flicker_series`: per denoiser, the per-frame flicker (a scale-free temporal metric of frame
  t against t−1) averaged over scenes, at one spp.

Notes
-----
* **Equivalent spp.** The noisy input's error falls as a power of spp; a line fitted to
  log(error) against log(spp) over the measured input spp (:func:`fit_noisy`; with one spp
  measured the slope is assumed to be −1, the Monte Carlo rate for relMSE, and −0.5 for FLIP)
  draws the "render more" curve. A reading's verdict uses only the measured rungs: the spp that
  rendering alone needs for a denoiser's error e is read off the log-log segment between the two
  rungs around e (:func:`.equal_tables.spp_for`); an e below the top rung's error gets a sentence
  that says no verdict is given (the equal-quality table carries the extrapolated figure, marked).
  Beyond the reference's own spp the comparison says more about the reference's noise than about
  the denoiser: the reading says so.
* **Time axis.** With a :class:`.time_model.TimeModel` (the report's case) every second is the
  model's at the resolution it states (``--time-at``, default 1920×1080): render seconds from the
  ladder's line of seconds against spp, denoise seconds from fixed + per-pixel costs. Without one,
  seconds are as measured, and the render line is :func:`fit_render_time` over the noisy inputs
  and the reference (offset + seconds per spp × spp), since part of a frame's render time does not
  grow with spp.
* **The reference** has zero error against itself, which a log axis cannot show: it appears as a
  vertical line at its render time, not as a point.
* Failed units are left out of means and listed separately; a denoiser/spp with no successful
  unit has no point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from denoisebench.analysis import aggregate as agg
from denoisebench.analysis.aggregate import BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED  # noqa: F401 (re-exported)
from denoisebench.analysis.equal_tables import ABOUT, ratio_text, spp_for
from denoisebench.analysis.run_index import RunIndex
from denoisebench.metrics import floors
from denoisebench.results.finite import finite_mean, is_finite
from denoisebench.results.names import (  # noqa: F401 (ERROR_METRICS: re-exported for the report)
    ERROR_METRICS,
    FLICKER_METRICS,
    FLICKER_PREFIX,
    NOISY,
)

#: Scenes a per-effect column needs (on one scene a column is that scene's score, not the effect's).
MIN_EFFECT_SCENES = 2
#: Assumed slope of log(error) vs log(spp) when only one input spp was measured.
DEFAULT_SLOPE = {"relmse_robust": -1.0, "relmse": -1.0, "mse": -1.0, "flip": -0.5}


def bootstrap_interval(values, ses=None) -> tuple[float | None, float | None]:
    """Percentile bootstrap 95 % interval of the mean; ``ses`` widen it by the reference's noise."""
    values = list(values)
    keep = [i for i, v in enumerate(values) if is_finite(v)]
    return agg.bootstrap_mean([float(values[i]) for i in keep], None if ses is None else [ses[i] for i in keep])


@dataclass
class Cell:
    """A metric aggregated over scenes under its ``rule`` (:mod:`.aggregate`), with a 95 % interval.

    For metrics with a reference-noise floor (the MSE family, with a reference variance) ``value``,
    ``low`` and ``high`` are the **floor-corrected** aggregate (``score − floor`` per scene, raised to
    the reference's se where below it: :func:`.aggregate.corrected_values`), and the interval carries
    the reference's uncertainty; ``raw``/``raw_low``/``raw_high`` are the score as measured against
    the reference, ``floor`` the floor aggregated by the same rule, ``at_resolution`` the scenes whose
    corrected value was at the reference's resolution. Without a floor ``raw`` is ``value``.
    """

    value: float | None
    low: float | None
    high: float | None
    scenes: int
    rule: str = "mean"
    floor: float | None = None
    raw: float | None = None
    raw_low: float | None = None
    raw_high: float | None = None
    at_resolution: int = 0

    @property
    def corrected(self) -> float | None:
        """The floor-corrected aggregate (``value``), None for a metric without a floor."""
        return self.value if self.floor is not None else None


@dataclass
class SummaryRow:
    denoiser: str
    spp: int
    metrics: dict[str, Cell]
    denoise_seconds: float | None  # mean per frame
    total_seconds: float | None  # mean per frame
    render_seconds: float | None  # mean per frame
    frames: int
    failed_units: int
    errors: list[str] = field(default_factory=list)


class _DictView:
    """A list attribute's rows as plain dicts (:meth:`.records.ByKey.as_dict`), made once, when first read."""

    def __init__(self, rows: str):
        self.rows = rows

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, obj, owner=None):
        if obj is None:
            return self
        value = [row.as_dict() for row in getattr(obj, self.rows)]
        obj.__dict__[self.name] = value  # a plain attribute from now on
        return value


class RunData(RunIndex):
    """One run's rows from the store, indexed once for the analyses (:class:`.run_index.RunIndex`).

    Typed rows: ``run_row``, ``entries``, ``unit_rows``, ``frame_rows``, ``sequence_rows``. The
    report reads ``run``, ``denoisers``, ``units``, ``frames`` and ``sequences``: the same rows as
    plain dicts (results.json writes them), made when first read.
    """

    def __init__(self, store, run_id: str):
        self.run_row = store.run(run_id)
        self.run_id = run_id
        self.entries = store.denoisers(run_id)
        super().__init__(store.units(run_id), store.frames(run_id), store.sequence_metrics(run_id))
        self.labels = [d.label for d in self.entries if not d.load_error]
        self._entry = {d.label: d for d in self.entries}

    def entry(self, label: str):
        """The :class:`~.records.EntryRow` of ``label`` (its sampler and denoiser: the run's sampler
        dimension), or None for a label the run does not have."""
        return self._entry.get(label)

    @cached_property
    def run(self) -> dict:
        return self.run_row.as_dict()

    denoisers = _DictView("entries")
    units = _DictView("unit_rows")
    frames = _DictView("frame_rows")
    sequences = _DictView("sequence_rows")


#: References read per scene to measure their noise (evenly spaced frames; the largest share is kept).
NOISE_CHECK_FRAMES = 4


def reference_noisy_shares(dataset, scenes: list[str]) -> dict[str, float]:
    """{scene: largest share of reference values too noisy for a floor} over a few frames of each scene
    (:func:`denoisebench.metrics.floors.noisy_value_share`); scenes without a reference variance are left out."""
    out = {}
    for scene in scenes:
        info = dataset.scene(scene)
        count = info.frame_count
        picks = sorted({round(i * (count - 1) / max(NOISE_CHECK_FRAMES - 1, 1)) for i in range(NOISE_CHECK_FRAMES)})
        shares = []
        for index in picks if count else []:
            try:
                layers, _ = dataset.reference(scene, index)
            except Exception:  # noqa: BLE001 - a missing or unreadable reference: its units failed already
                continue
            if "color_var" in layers:
                shares.append(floors.noisy_value_share(layers["color"], layers["color_var"]))
        if shares:
            out[scene] = max(shares)
    return out


def set_apart(data: RunData, dataset) -> list[agg.Unresolved]:
    """The scenes of a run whose scores cannot rank (:func:`.aggregate.unresolved_references`), judged
    from the dataset's reference records and a few of its references (:func:`reference_noisy_shares`):
    the one rule the report and ``denoisebench leaderboard`` share."""
    states = agg.reference_states({s: dataset.scene(s).record for s in data.scenes})
    for scene, share in reference_noisy_shares(dataset, data.scenes).items():
        states.setdefault(scene, {})["noisy_share"] = share
    return agg.unresolved_references(data, states)


def summary_table(data: RunData, exclude=()) -> list[SummaryRow]:
    """Per (spp, denoiser): every metric aggregated over its ok scenes, except ``exclude`` (the scenes
    whose reference cannot resolve the headline scores, :func:`.aggregate.unresolved_references`)."""
    exclude = set(exclude)
    rows = []
    for spp in data.spp:
        for label in data.labels:
            units = data.units_of(label, spp)
            if not units:
                continue
            ok_scenes = [u.scene for u in units if u.status == "ok" and u.scene not in exclude]
            cells = {}
            for metric in data.frame_metric_names + data.sequence_metric_names:
                cells[metric] = metric_cell(data, label, spp, metric, ok_scenes)
            frames = [f for s in ok_scenes for f in data.ok_frames(label, spp, s)]
            rows.append(
                SummaryRow(
                    label,
                    spp,
                    cells,
                    finite_mean(f.denoise_seconds for f in frames),
                    finite_mean(f.total_seconds for f in frames),
                    finite_mean(f.render_seconds for f in frames),
                    len(frames),
                    sum(u.status != "ok" for u in units),
                    sorted({u.error for u in units if u.error}),
                )
            )
    return rows


def metric_cell(data: RunData, label: str, spp: int, metric: str, scenes: list[str] | None) -> Cell:
    """One metric of one denoiser at one spp, aggregated over ``scenes`` by the metric's rule.

    With floors on every scene the cell leads with the corrected aggregate (:class:`Cell`); for
    ``relative_to_input`` both the denoiser's and the input's scores are corrected before the ratio."""
    rule = agg.rule_of(metric)
    mine, floors, ses = data.per_scene(label, spp, metric, scenes)
    noisy = noisy_floors = noisy_ses = None
    if rule == "relative_to_input":
        noisy, noisy_floors, noisy_ses = data.per_scene(NOISY, spp, metric, scenes)
    value, low, high, count = agg.aggregate(rule, mine, noisy, ses)
    if not (floors and len(floors) == len(mine) and value is not None):
        return Cell(value, low, high, count, rule, raw=value, raw_low=low, raw_high=high)
    # relative_to_input: the floor relative to the input's own score (noisy is None otherwise)
    floor = agg.aggregate(rule, floors, noisy)[0]
    higher = agg.higher_is_better(metric)
    corrected, raised = agg.corrected_values(mine, floors, ses, higher)
    noisy_corrected = None
    if noisy is not None:
        noisy_corrected = agg.corrected_values(noisy, noisy_floors or {}, noisy_ses, higher)[0]
    c_value, c_low, c_high, c_count = agg.aggregate(rule, corrected, noisy_corrected, ses)
    return Cell(c_value, c_low, c_high, c_count, rule, floor, value, low, high, len(raised))


@dataclass
class Indistinguishable:
    """Two denoisers whose aggregated scores differ by less than the reference can resolve."""

    spp: int
    metric: str
    a: str
    b: str
    difference: float  # a − b on the rule's scale (score units for mean; log ratio otherwise)
    resolution: float  # 95 % half-width the reference's noise allows


def indistinguishable_pairs(data: RunData, summary: list[SummaryRow]) -> list[Indistinguishable]:
    """Pairs (noisy input included) whose difference lies within the reference's uncertainty.

    For every metric with stored reference se (the MSE family) and every spp; per-scene values over
    the scenes both measured (:func:`.aggregate.reference_resolution`, conservative).
    """
    found = []
    metrics = [
        m
        for m in data.frame_metric_names + data.sequence_metric_names
        if any(c.metrics.get(m) is not None and c.metrics[m].floor is not None for c in summary)
    ]
    for spp in data.spp:
        rows = [r for r in summary if r.spp == spp and r.failed_units == 0]
        for metric in metrics:
            rule = agg.rule_of(metric)
            per = {r.denoiser: data.per_scene(r.denoiser, spp, metric) for r in rows}
            labels = [r.denoiser for r in rows if per[r.denoiser][0]]
            for i, a in enumerate(labels):
                for b in labels[i + 1 :]:
                    (va, _, sa), (vb, _, sb) = per[a], per[b]
                    resolution = agg.reference_resolution(rule, va, sa, vb, sb)
                    if resolution is None:
                        continue
                    common = [s for s in va if s in vb]
                    if rule == "mean":
                        diff = float(np.mean([va[s] - vb[s] for s in common]))
                    elif all(va[s] > 0 and vb[s] > 0 for s in common):
                        diff = float(np.mean([math.log(va[s] / vb[s]) for s in common]))
                    else:
                        continue
                    if abs(diff) <= resolution:
                        found.append(Indistinguishable(spp, metric, a, b, diff, resolution))
    return found


# --------------------------------------------------------------------------------------------------
# accuracy against time


@dataclass
class Point:
    denoiser: str
    spp: int
    seconds: float  # total seconds per frame
    error: float
    pareto: bool = False


@dataclass
class NoisyFit:
    """log(error) = intercept + slope · log(spp); render seconds = time_offset + seconds_per_spp · spp."""

    intercept: float
    slope: float
    seconds_per_spp: float
    measured_spp: list[int]
    assumed_slope: bool
    time_offset: float = 0.0

    def seconds_at(self, spp: float) -> float:
        return self.time_offset + self.seconds_per_spp * spp

    def spp_for(self, error: float) -> float:
        return math.exp((math.log(error) - self.intercept) / self.slope)

    def error_at(self, spp: float) -> float:
        return math.exp(self.intercept + self.slope * math.log(spp))


@dataclass
class AccuracyTime:
    metric: str
    points: list[Point]  # denoisers (noisy included, as label NOISY)
    fit: NoisyFit | None
    reference_seconds: float | None
    reference_spp: int | None
    hidden: list[str]  # points that cannot be drawn on log axes, and why
    time_label: str = "seconds per frame (render at input spp + denoise)"
    noisy_curve: dict[int, float] = field(default_factory=dict)  # measured rungs {spp: error}
    model: object = None  # the time model the seconds come from (its spreads bound the time verdicts)


def pareto_front(points: list[Point]) -> None:
    """Mark the points no other point beats in both time and error (ties broken by neither)."""
    for p in points:
        p.pareto = not any(
            (q.seconds <= p.seconds and q.error <= p.error) and (q.seconds < p.seconds or q.error < p.error)
            for q in points
        )


def fit_render_time(render_times: list[tuple[float, float]]) -> tuple[float, float] | None:
    """(offset, seconds per spp) of render seconds against spp: a line through the measured (spp, seconds).

    A frame's render time has a part that does not grow with spp (scene set-up, features, writing);
    a pure proportion would charge it once per sample and make "render more samples" look far dearer
    than it is. With one spp measured the time is taken as proportional. Offset is kept ≥ 0.
    """
    pairs = [(float(s), float(t)) for s, t in render_times if t is not None and t > 0 and s > 0]
    if not pairs:
        return None
    spp = np.array([p[0] for p in pairs])
    seconds = np.array([p[1] for p in pairs])
    if np.ptp(spp) > 0:
        slope, offset = np.polyfit(spp, seconds, 1)
        if slope > 0 and offset >= 0:
            return float(offset), float(slope)
        if slope > 0:  # negative offset: refit through the origin
            return 0.0, float(np.sum(spp * seconds) / np.sum(spp * spp))
    return 0.0, float(np.mean(seconds / spp))


def fit_noisy(points: list[Point], render_times: list[tuple[float, float]], metric: str) -> NoisyFit | None:
    """The noisy input's error against spp, and render time against spp (:func:`fit_render_time`)."""
    noisy = [p for p in points if p.denoiser == NOISY and p.error > 0]
    timing = fit_render_time(render_times)
    if not noisy or timing is None:
        return None
    log_spp = np.log([p.spp for p in noisy])
    log_err = np.log([p.error for p in noisy])
    if len(noisy) >= 2 and np.ptp(log_spp) > 0:
        slope, intercept = np.polyfit(log_spp, log_err, 1)
        assumed = False
        if slope >= 0:  # more samples did not help (a converged or broken input): no extrapolation
            return None
    else:
        slope, assumed = DEFAULT_SLOPE.get(metric, -1.0), True
        intercept = float(np.mean(log_err - slope * log_spp))
    return NoisyFit(float(intercept), float(slope), timing[1], sorted(p.spp for p in noisy), assumed, timing[0])


def accuracy_time(data: RunData, summary: list[SummaryRow], metric: str, reference: dict, model=None) -> AccuracyTime:
    """Points of ``metric`` against seconds per frame; with a :class:`.time_model.TimeModel`, the
    seconds are the model's at its resolution (render line and denoise costs), else as measured."""
    points, hidden = [], []
    for row in summary:
        cell = row.metrics.get(metric)
        seconds = row.total_seconds if model is None else model.total_seconds(row.denoiser, row.spp)
        if cell is None or cell.value is None:
            continue
        if seconds is None:
            if model is not None:
                hidden.append(f"{row.denoiser} at {row.spp} spp: no time at {model.time_at[0]}×{model.time_at[1]}")
            continue
        if cell.value <= 0 or seconds <= 0:
            hidden.append(
                f"{row.denoiser} at {row.spp} spp ({metric} {cell.value:.3g}, {seconds:.3g} s): not positive, off a log axis"
            )
            continue
        points.append(Point(row.denoiser, row.spp, seconds, cell.value))
    pareto_front(points)
    render_times = [(f.spp, f.render_seconds) for f in data.frames_of(NOISY) if f.render_seconds]
    if reference.get("seconds") and reference.get("spp") and model is None:
        render_times.append((reference["spp"], reference["seconds"]))  # the reference is a render time too
    fit = fit_noisy(points, render_times, metric)
    reference_seconds = reference.get("seconds")
    label = "seconds per frame (render at input spp + denoise)"
    if model is not None and model.render is not None:
        if fit is not None:
            fit.time_offset, fit.seconds_per_spp = model.render.offset(model.pixels), model.render.per_spp(model.pixels)
        if model.projected and reference.get("spp"):
            reference_seconds = model.render_seconds(reference["spp"])
        width, height = model.time_at
        label = f"seconds per frame at {width}×{height}" + (" (projected)" if model.projected else "")
    at = AccuracyTime(metric, points, fit, reference_seconds, reference.get("spp"), hidden, label, model=model)
    at.noisy_curve = {p.spp: p.error for p in points if p.denoiser == NOISY}
    return at


def spp_text(spp: float) -> str:
    """``"16-spp"`` for a whole (measured) spp, ``"≈ 2.4-spp (interpolated)"`` for a fractional one: a
    rendering time read between rungs is never shown as if a rung had been rendered."""
    if abs(spp - round(spp)) <= 1e-6 * max(spp, 1.0):
        return f"{round(spp):,}-spp"
    digits = f"{spp:.2g}" if spp < 10 else f"{spp:,.0f}"
    return f"≈ {digits}-spp (interpolated)"


def readings(at: AccuracyTime) -> list[str]:
    """One sentence per denoiser at the spp where it saves the most time against rendering alone.

    A verdict rests only on the measured rungs of the noisy input: the spp rendering alone needs for
    a denoiser's error is read off the straight log-log segment between the two rungs around it
    (:func:`.equal_tables.spp_for`). An error below the top rung's (or any error when one rung was
    measured) would need an extrapolation: the sentence then says so and gives no verdict."""
    if at.fit is None:
        return [f"No noisy-input curve for {at.metric}: the inputs' error does not fall with spp (or no render times)."]
    fit = at.fit
    noisy_error = at.noisy_curve or {p.spp: p.error for p in at.points if p.denoiser == NOISY}
    rungs = sorted(noisy_error)
    measured = f"{rungs[0]}–{rungs[-1]} spp" if len(rungs) > 1 else f"{rungs[0]} spp"
    sentences = []
    best: dict[str, tuple[float, str]] = {}
    for p in at.points:
        if p.denoiser == NOISY:
            continue
        if p.spp in noisy_error and p.error >= noisy_error[p.spp]:
            text = f"{p.denoiser} at {p.spp} spp does not improve on its own input ({at.metric} {p.error:.3g} vs {noisy_error[p.spp]:.3g})."
            best.setdefault(p.denoiser, (-math.inf, text))
            continue
        found = spp_for(noisy_error, p.error) if len(rungs) > 1 else None
        if found is None or found.how == "extrapolated":
            text = (
                f"{p.denoiser} at {p.spp} spp ({at.metric} {p.error:.3g}) is below the error of rendering alone at "
                f"every measured rung ({measured}): no verdict, since the rendering time to match it would be "
                "extrapolated (the equal-quality table gives that figure, marked)."
            )
            best.setdefault(p.denoiser, (-math.inf + 1, text))
            continue
        spp_eq = found.value
        seconds_eq = fit.seconds_at(spp_eq)
        ratio = p.seconds / seconds_eq
        notes = []
        if at.reference_spp and spp_eq > at.reference_spp:
            notes.append(f"beyond the {at.reference_spp}-spp reference, whose own noise then dominates the score")
        note = f" ({'; '.join(notes)})" if notes else ""
        bounds = at.model.ratio_bounds(p.denoiser, p.spp, spp_eq) if at.model is not None else None
        low, high = bounds if bounds is not None else (ratio, ratio)
        spread = ""
        if ratio_text(low) != ratio_text(high):
            spread = f", {ratio_text(low)}–{ratio_text(high)} across the timings' spread"
        # one rule with the equal-quality verdicts (equal_tables.verdicts): a saving or a loss only
        # beyond 5 % either side of rendering's time, at both ends of the timings' spread
        if high < 1 - ABOUT:
            text = (
                f"{p.denoiser} at {p.spp} spp matches {spp_text(spp_eq)} rendering in {at.metric} "
                f"at {ratio_text(ratio)} of its time ({p.seconds:.3g} s vs {seconds_eq:.3g} s per frame{spread}){note}."
            )
        elif low > 1 + ABOUT:
            text = (
                f"{p.denoiser} at {p.spp} spp reaches the {at.metric} of {spp_text(spp_eq)} rendering but takes "
                f"{ratio:.2g}× as long ({p.seconds:.3g} s vs {seconds_eq:.3g} s per frame{spread}): rendering more "
                f"samples is cheaper{note}."
            )
        else:
            text = (
                f"{p.denoiser} at {p.spp} spp matches {spp_text(spp_eq)} rendering in {at.metric} in about its time "
                f"({p.seconds:.3g} s vs {seconds_eq:.3g} s per frame{spread}): no time verdict{note}."
            )
        score = -math.log(ratio)
        if p.denoiser not in best or score > best[p.denoiser][0]:
            best[p.denoiser] = (score, text)
    for _, text in sorted(best.values(), key=lambda item: -item[0]):
        sentences.append(text)
    front = [f"{p.denoiser}@{p.spp}" for p in sorted(at.points, key=lambda p: p.seconds) if p.pareto]
    if front:
        sentences.append(f"Pareto front ({at.metric} against time, fastest first): {', '.join(front)}.")
    return sentences


# --------------------------------------------------------------------------------------------------
# effects and flicker


def effect_breakdown(data: RunData, scene_effects: dict[str, list[str]], metric: str = "relmse") -> dict:
    """{denoiser: {effect: geometric-mean share of the input's error left}}, plus ``overall``.

    The share is denoiser error / noisy-input error per scene and spp (so scene difficulty cancels),
    averaged geometrically over the scenes that exercise the effect.

    Notes
    -----
    A column needs :data:`MIN_EFFECT_SCENES` scenes: columns with fewer are left out (``too_few``) and
    ``notes`` says so, and which sentences the report cannot write (a "suffers most from" needs two
    columns). Effects that the run's scenes always exercise together (every scene with ``specular`` also has
    ``transmission`` and the other way round) would be columns of the same numbers, computed over the
    same scenes: they are one column, named by their effects joined with ``" + "``
    (``"specular + transmission"``). The run cannot tell such effects apart; more scenes can.
    """
    scene_effects = _merge_inseparable(scene_effects, data.scenes)
    counts: dict[str, int] = {}
    for scene in data.scenes:
        for effect in scene_effects.get(scene, []):
            counts[effect] = counts.get(effect, 0) + 1
    effects = sorted(e for e, n in counts.items() if n >= MIN_EFFECT_SCENES)
    too_few = {e: n for e, n in sorted(counts.items()) if n < MIN_EFFECT_SCENES}
    notes = []
    if too_few:
        notes.append(
            f"Not shown: {', '.join(f'{e} ({n} scene)' for e, n in too_few.items())}. A per-effect column needs "
            f"{MIN_EFFECT_SCENES} scenes of its own: on one scene it is that scene's score, not the effect's."
        )
    if len(effects) < 2:
        notes.append(
            "No \"suffers most from\" sentence: that needs two columns to compare"
            + (f" (this run has {len(effects)})." if effects else " (this run has none).")
        )
    table: dict[str, dict[str, float | None]] = {}
    for label in data.labels:
        if label == NOISY:
            continue
        shares: dict[str, list[float]] = {}
        for scene in data.scenes:
            for spp in data.spp:
                mine, noisy = data.scene_value(label, spp, scene, metric), data.scene_value(NOISY, spp, scene, metric)
                if mine is None or not noisy or mine <= 0 or not data.unit_ok(label, spp, scene):
                    continue
                for key in ["overall", *scene_effects.get(scene, [])]:
                    shares.setdefault(key, []).append(mine / noisy)
        table[label] = {
            key: (float(np.exp(np.mean(np.log(shares[key])))) if shares.get(key) else None)
            for key in ["overall", *effects]
        }
    return {"metric": metric, "effects": effects, "table": table, "too_few": too_few, "notes": notes}


def _merge_inseparable(scene_effects: dict[str, list[str]], scenes) -> dict[str, list[str]]:
    """``scene_effects`` with effects exercised by exactly the same of ``scenes`` merged into one name."""
    present = [s for s in scenes if s in scene_effects]
    holders: dict[str, frozenset] = {}
    for effect in sorted({e for s in present for e in scene_effects[s]}):
        holders[effect] = frozenset(s for s in present if effect in scene_effects[s])
    groups: dict[frozenset, list[str]] = {}
    for effect, where in holders.items():
        groups.setdefault(where, []).append(effect)
    name_of = {effect: " + ".join(group) for group in groups.values() for effect in group}
    return {scene: list(dict.fromkeys(name_of.get(e, e) for e in effects)) for scene, effects in scene_effects.items()}


def flicker_metrics(data: RunData) -> list[str]:
    """The per-frame flicker metrics a run stored: FLICKER_METRICS, or ``temporal_l1`` of old runs."""
    stored = data.flicker_names
    names = [m for m in FLICKER_METRICS if FLICKER_PREFIX + m in stored]
    if not names and "flicker" in stored:
        names = ["temporal_l1"]  # older runs: "flicker" was temporal_l1 (linear: not averaged in a figure)
    return names


def flicker_series(data: RunData, spp: int, metric: str = FLICKER_METRICS[0]) -> dict[str, list[float | None]]:
    """{denoiser: [mean ``metric`` flicker of frame 1, 2, ...] over scenes} at ``spp`` (frame 0 has none).

    The mean over scenes is arithmetic: only for scale-free metrics (the flicker ones are).
    """
    key = "flicker" if metric == "temporal_l1" else FLICKER_PREFIX + metric
    series = {}
    for label in data.labels:
        by_frame: dict[int, list[float]] = {}
        for f in data.ok_frames(label, spp):
            value = f.metrics.get(key)
            if is_finite(value):
                by_frame.setdefault(f.frame, []).append(value)
        if by_frame:
            last = max(by_frame)
            series[label] = [float(np.mean(by_frame[i])) if i in by_frame else None for i in range(1, last + 1)]
    return series
