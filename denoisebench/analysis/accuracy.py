"""Accuracy against time, computed from one run's summary (no drawing, no HTML).

Per denoiser and spp, mean error (robust relMSE, relMSE, FLIP) against total
seconds per frame (render at that spp + denoise, at the time model's resolution); the noisy
inputs as the "just render more samples" curve; the Pareto front; and the reading in words
(:func:`readings`).

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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from denoisebench.analysis.equal_tables import ABOUT, ratio_text, safe_exp, spp_for, withheld_side
from denoisebench.analysis.summary import RunData, SummaryRow
from denoisebench.results.names import NOISY

#: Assumed slope of log(error) vs log(spp) when only one input spp was measured.
DEFAULT_SLOPE = {"relmse_robust": -1.0, "relmse": -1.0, "mse": -1.0, "flip": -0.5}


@dataclass(kw_only=True)
class Point:
    denoiser: str
    spp: int
    seconds: float  # total seconds per frame
    error: float
    pareto: bool = False


@dataclass(kw_only=True)
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
        return safe_exp((math.log(error) - self.intercept) / self.slope)

    def error_at(self, spp: float) -> float:
        return safe_exp(self.intercept + self.slope * math.log(spp))


@dataclass(kw_only=True)
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
    return NoisyFit(
        intercept=float(intercept),
        slope=float(slope),
        seconds_per_spp=timing[1],
        measured_spp=sorted(p.spp for p in noisy),
        assumed_slope=assumed,
        time_offset=timing[0],
    )


def accuracy_time(
    data: RunData,
    summary: list[SummaryRow],
    metric: str,
    *,
    reference_seconds: float | None = None,
    reference_spp: int | None = None,
    model=None,
) -> AccuracyTime:
    """Points of ``metric`` against seconds per frame; with a :class:`.time_model.TimeModel`, the
    seconds are the model's at its resolution (render line and denoise costs), else as measured.

    ``reference_seconds``/``reference_spp``: the references' mean render seconds and spp (None: unknown)."""
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
        points.append(Point(denoiser=row.denoiser, spp=row.spp, seconds=seconds, error=cell.value))
    pareto_front(points)
    render_times = [(f.spp, f.render_seconds) for f in data.frames_of(NOISY) if f.render_seconds]
    if reference_seconds and reference_spp and model is None:
        render_times.append((reference_spp, reference_seconds))  # the reference is a render time too
    fit = fit_noisy(points, render_times, metric)
    label = "seconds per frame (render at input spp + denoise)"
    if model is not None and model.render is not None:
        if fit is not None:
            fit.time_offset, fit.seconds_per_spp = model.render.offset(model.pixels), model.render.per_spp(model.pixels)
        if model.projected and reference_spp:
            reference_seconds = model.render_seconds(reference_spp)
        width, height = model.time_at
        label = f"seconds per frame at {width}×{height}" + (" (projected)" if model.projected else "")
    at = AccuracyTime(
        metric=metric,
        points=points,
        fit=fit,
        reference_seconds=reference_seconds,
        reference_spp=reference_spp,
        hidden=hidden,
        time_label=label,
        model=model,
    )
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
    if not rungs:
        return [f"No noisy-input curve for {at.metric}: the input was not measured (no rung to compare with)."]
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
        if not (seconds_eq > 0 and p.seconds > 0):
            text = (
                f"{p.denoiser} at {p.spp} spp ({at.metric} {p.error:.3g}): no time verdict (a time of 0 s to compare)."
            )
            best.setdefault(p.denoiser, (-math.inf + 1, text))
            continue
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
            how = {"slower": "in no less than its time", "faster": "in less than its time, perhaps only slightly"}
            text = (
                f"{p.denoiser} at {p.spp} spp matches {spp_text(spp_eq)} rendering in {at.metric} "
                f"{how.get(withheld_side(low, high), 'in about its time')} "
                f"({p.seconds:.3g} s vs {seconds_eq:.3g} s per frame{spread}): no time verdict{note}."
            )
        score = math.log(seconds_eq) - math.log(p.seconds)  # -log(ratio): a ratio may underflow to 0, its log not
        if p.denoiser not in best or score > best[p.denoiser][0]:
            best[p.denoiser] = (score, text)
    for _, text in sorted(best.values(), key=lambda item: -item[0]):
        sentences.append(text)
    front = [f"{p.denoiser}@{p.spp}" for p in sorted(at.points, key=lambda p: p.seconds) if p.pareto]
    if front:
        sentences.append(f"Pareto front ({at.metric} against time, fastest first): {', '.join(front)}.")
    return sentences
