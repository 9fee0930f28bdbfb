"""Equal-time and equal-quality tables: the two comparisons rendering papers print.

* **Equal time** (:func:`equal_time`): for each budget, the seconds per frame of rendering ``s`` spp
  at the time axis' resolution (one row per measured rung ``s``), the (denoiser, spp) of lowest
  error whose render + denoise seconds fit that budget, its error with its 95 % interval, against
  the error of rendering ``s`` spp alone.
* **Equal quality** (:func:`equal_quality`): for each error target (the noisy input's error at each
  measured rung, then at 4× and 16× the top rung), the seconds per frame each denoiser needs to
  reach it, against the seconds rendering alone needs.

Notes
-----
* **Interpolation only between measured rungs.** A denoiser's (or the input's) error between two
  measured spp is read off the straight line joining them on log-log axes (Monte Carlo error is a
  power of spp); its denoise seconds are linear in spp between them. Outside the measured rungs a
  figure is **extrapolated** along the nearest segment, marked ``extrapolated`` in every table, and
  never makes a verdict (:func:`verdicts`). A target a denoiser already meets at its lowest measured
  spp gets "≤" (it might need fewer samples, which were not measured), a bound and no extrapolation.
* **Where the seconds come from.** Every second is the :class:`~.time_model.TimeModel` at the
  report's resolution (``projected`` when that is not the dataset's); the tables do not mix
  resolutions.
* **Timing spread.** A candidate fits a budget for a verdict only when its time fits at the top of
  its spread (:meth:`.time_model.TimeModel.ratio_bounds`); a row where a better candidate fits only
  at the bottom is ``contested`` and makes no verdict either way. An equal-quality saving or loss is
  stated only when its ratio's bounds lie on one side of 1 (with 5 % either side called "about").
* **Which error.** The lead metric is the robust relMSE (``relmse_robust``) when the metrics
  registry has it and the run measured it, else relMSE; FLIP beside it (:func:`lead_metrics`). Each
  is aggregated over scenes by its rule (:func:`.analysis.summary_table`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from denoisebench.metrics.registry import metric_names
from denoisebench.results.finite import num
from denoisebench.results.names import NOISY

#: A time ratio within this of 1 is "about rendering's time" (the same rule as accuracy.readings).
ABOUT = 0.05


def withheld_side(low: float, high: float) -> str:
    """What a withheld time verdict's bounds (ratios to rendering's time, within ``ABOUT`` of 1 at one
    end at least) still say: ``"slower"`` when they lie wholly at or above 1 (no saving; a loss that
    may be smaller than ``ABOUT``), ``"faster"`` when wholly at or below 1 (a saving that may be
    smaller than ``ABOUT``: the end nearest 1 is within it), else ``"either"``.

    Pitfall: a range like 100–117 % is no saving; calling it "about its time" read as a tie."""
    if low >= 1.0:
        return "slower"
    if high <= 1.0:
        return "faster"
    return "either"


#: Multiples of the top rung the equal-quality table adds as (extrapolated) targets.
EXTRA_TARGETS = (4, 16)
#: An extrapolation further than this multiple of the top rung is not given (a nearly flat last segment
#: would put a target at absurd spp): the table says "not reached".
EXTRAPOLATION_LIMIT = 64


def lead_metrics(measured: list[str]) -> list[str]:
    """The tables' metrics: robust relMSE (else relMSE), then FLIP, among those the run measured."""
    registered = set(metric_names())
    first = "relmse_robust" if "relmse_robust" in registered and "relmse_robust" in measured else "relmse"
    return [m for m in (first, "flip") if m in measured]


@dataclass(kw_only=True)
class Estimate:
    """A value read off measured rungs: ``how`` is ``measured``, ``interpolated``, ``at_most`` or ``extrapolated``."""

    value: float
    how: str
    low: float | None = None
    high: float | None = None

    @property
    def verdict_ok(self) -> bool:
        return self.how in ("measured", "interpolated", "at_most")


def safe_exp(x: float) -> float:
    """``math.exp`` held within the floats (a finite answer for any finite log: no OverflowError)."""
    return math.exp(min(max(x, -745.0), 709.0))


def _log_segment(x0, y0, x1, y1, x) -> float:
    t = (math.log(x) - math.log(x0)) / (math.log(x1) - math.log(x0))
    return safe_exp(math.log(y0) + t * (math.log(y1) - math.log(y0)))


def error_at(curve: dict[int, float], spp: float) -> Estimate | None:
    """Error at ``spp`` on a measured curve {spp: error > 0}: log-log between rungs, extrapolated outside."""
    points = sorted((s, e) for s, e in curve.items() if e is not None and e > 0)
    if not points:
        return None
    for s, e in points:
        if math.isclose(s, spp):
            return Estimate(value=e, how="measured")
    if len(points) == 1:
        return None
    if spp < points[0][0]:
        (x0, y0), (x1, y1) = points[0], points[1]
        return Estimate(value=_log_segment(x0, y0, x1, y1=y1, x=spp), how="extrapolated")
    if spp > points[-1][0]:
        (x0, y0), (x1, y1) = points[-2], points[-1]
        return Estimate(value=_log_segment(x0, y0, x1, y1=y1, x=spp), how="extrapolated")
    for (x0, y0), (x1, y1) in zip(points, points[1:]):
        if x0 <= spp <= x1:
            return Estimate(value=_log_segment(x0, y0, x1, y1=y1, x=spp), how="interpolated")
    return None


def spp_for(curve: dict[int, float], target: float) -> Estimate | None:
    """The least spp at which a curve {spp: error} reaches ``target`` (error ≤ target).

    ``at_most``: met at the lowest rung already; ``interpolated``: on the first segment that crosses
    it; ``extrapolated``: beyond the top rung along the last segment when that falls (at most
    :data:`EXTRAPOLATION_LIMIT` × the top rung); None when the curve does not reach it so."""
    points = sorted((s, e) for s, e in curve.items() if e is not None and e > 0)
    if not points or target <= 0:
        return None
    if points[0][1] <= target:
        return Estimate(value=float(points[0][0]), how="at_most")
    for (x0, y0), (x1, y1) in zip(points, points[1:]):
        if y1 <= target < y0:
            drop = math.log(y1) - math.log(y0)
            if math.isclose(y1, target) or drop == 0.0:  # adjacent floats: the logs cannot tell them apart
                return Estimate(value=float(x1), how="measured")
            t = (math.log(target) - math.log(y0)) / drop
            return Estimate(value=safe_exp(math.log(x0) + t * (math.log(x1) - math.log(x0))), how="interpolated")
    if len(points) >= 2:
        (x0, y0), (x1, y1) = points[-2], points[-1]
        slope = (math.log(y1) - math.log(y0)) / (math.log(x1) - math.log(x0))
        if slope < 0:
            # on the log scale: a nearly flat last segment puts the target beyond any float (the
            # OverflowError a third-party dataset met), and beyond the limit it is not given anyway
            log_spp = math.log(x1) + (math.log(target) - math.log(y1)) / slope
            if log_spp <= math.log(EXTRAPOLATION_LIMIT * x1):
                return Estimate(value=math.exp(log_spp), how="extrapolated")
    return None


@dataclass(kw_only=True)
class Curves:
    """Per label {spp: (mean, low, high)} of one metric from the summary rows."""

    metric: str
    cells: dict[str, dict[int, tuple[float, float | None, float | None]]]

    def curve(self, label: str) -> dict[int, float]:
        return {s: c[0] for s, c in self.cells.get(label, {}).items() if c[0] is not None and c[0] > 0}

    @classmethod
    def from_summary(cls, summary, metric: str) -> Curves:
        cells: dict[str, dict] = {}
        for row in summary:
            cell = row.metrics.get(metric)
            if cell is None or cell.value is None or row.failed_units:
                continue
            cells.setdefault(row.denoiser, {})[int(row.spp)] = (float(cell.value), cell.low, cell.high)
        return cls(metric=metric, cells=cells)


@dataclass(kw_only=True)
class EqualTimeRow:
    budget_spp: int
    budget_seconds: float
    render_error: Estimate
    best: str | None  # a denoiser label, or None when rendering alone is best
    best_spp: int | None
    best_seconds: float | None
    best_error: Estimate | None
    candidates: int
    contested: bool = False  # a better candidate fits only at the bottom of the timings' spread

    @property
    def ratio(self) -> float | None:
        """Best error / rendering's error (< 1: the denoiser wins at this budget)."""
        if self.best_error is None or not self.render_error.value:
            return None
        return self.best_error.value / self.render_error.value


@dataclass(kw_only=True)
class EqualQualityRow:
    target: float
    target_spp: float  # spp rendering alone needs
    render_seconds: float
    render_how: str  # measured (a rung) or extrapolated
    needs: dict[str, tuple[Estimate, Estimate] | None] = field(default_factory=dict)  # label → (spp, seconds)
    ratio_bounds: dict[str, tuple[float, float]] = field(default_factory=dict)  # label → time ratio across spreads


@dataclass(kw_only=True)
class Tables:
    metric: str
    time_at: tuple[int, int]
    projected: bool
    equal_time: list[EqualTimeRow]
    equal_quality: list[EqualQualityRow]
    denoisers: list[str]


def _fits(model, label: str, spp: int, budget_spp: int, seconds: float, budget: float) -> tuple[bool, bool]:
    """(fits at the top of the timings' spread, fits at its bottom) of ``label`` at ``spp`` within the budget."""
    bounds = model.ratio_bounds(label, spp, budget_spp) if hasattr(model, "ratio_bounds") else None
    if bounds is None:
        fits = seconds <= budget * (1 + 1e-9)
        return fits, fits
    return bounds[1] <= 1 + 1e-9, bounds[0] <= 1 + 1e-9


def equal_time(curves: Curves, model, rungs: list[int]) -> list[EqualTimeRow]:
    """One row per measured rung: the best (denoiser, spp) that fits rendering's seconds at that rung at
    the top of its timing spread; ``contested`` when a better one fits only at the bottom of it."""
    rows = []
    noisy = curves.cells.get(NOISY, {})
    for s in rungs:
        if s not in noisy or model.render_seconds(s) is None:
            continue
        budget = model.render_seconds(s)
        mean, low, high = noisy[s]
        render_error = Estimate(value=mean, how="measured", low=low, high=high)
        best = None
        count = 0
        maybe = []
        for label, by_spp in curves.cells.items():
            if label == NOISY:
                continue
            for spp, (e, lo, hi) in by_spp.items():
                seconds = model.total_seconds(label, spp)
                if seconds is None:
                    continue
                surely, possibly = _fits(model, label, spp, budget_spp=s, seconds=seconds, budget=budget)
                if not surely:
                    if possibly:
                        maybe.append(e)
                    continue
                count += 1
                if best is None or e < best[3].value:
                    best = (label, spp, seconds, Estimate(value=e, how="measured", low=lo, high=hi))
        floor = best[3].value if best is not None and best[3].value < mean else mean
        contested = any(e < floor for e in maybe)
        if best is not None and best[3].value < mean:
            label, spp, seconds, error = best
            rows.append(
                EqualTimeRow(
                    budget_spp=s,
                    budget_seconds=budget,
                    render_error=render_error,
                    best=label,
                    best_spp=spp,
                    best_seconds=seconds,
                    best_error=error,
                    candidates=count,
                    contested=contested,
                )
            )
        else:
            rows.append(
                EqualTimeRow(
                    budget_spp=s,
                    budget_seconds=budget,
                    render_error=render_error,
                    best=None,
                    best_spp=None,
                    best_seconds=None,
                    best_error=None,
                    candidates=count,
                    contested=contested,
                )
            )
    return rows


def equal_quality(curves: Curves, model, rungs: list[int]) -> list[EqualQualityRow]:
    """Targets: the input's error at each measured rung, then at EXTRA_TARGETS × the top rung."""
    noisy = curves.curve(NOISY)
    if not noisy:
        return []
    targets = [(float(s), Estimate(value=noisy[s], how="measured")) for s in sorted(noisy) if s in rungs]
    top = max(noisy)
    for factor in EXTRA_TARGETS:
        found = error_at(noisy, top * factor)
        if found is not None and found.value < noisy[top]:
            targets.append((float(top * factor), found))
    rows = []
    for target_spp, target in targets:
        render = model.render_seconds(target_spp)
        if render is None:
            continue
        row = EqualQualityRow(target=target.value, target_spp=target_spp, render_seconds=render, render_how=target.how)
        for label in curves.cells:
            if label == NOISY:
                continue
            need = spp_for(curves.curve(label), target.value)
            if need is None:
                row.needs[label] = None
                continue
            seconds = model.total_seconds(label, need.value)
            row.needs[label] = None if seconds is None else (need, Estimate(value=seconds, how=need.how))
            bounds = model.ratio_bounds(label, need.value, target_spp) if hasattr(model, "ratio_bounds") else None
            if seconds is not None and bounds is not None:
                row.ratio_bounds[label] = bounds
        rows.append(row)
    return rows


def build_tables(summary, model, rungs: list[int], metric: str) -> Tables:
    curves = Curves.from_summary(summary, metric)
    labels = [label for label in curves.cells if label != NOISY]
    return Tables(
        metric=metric,
        time_at=tuple(model.time_at),
        projected=bool(model.projected),
        equal_time=equal_time(curves, model, rungs),
        equal_quality=equal_quality(curves, model, rungs),
        denoisers=labels,
    )


def ratio_text(ratio: float) -> str:
    """A time or error ratio in words: ``"1/10"`` below a half, else ``"57 %"``; ``"0 %"`` for none, and
    ``"under 1/1000000"``/``"over 1000000 %"`` beyond those (never "inf" or "nan" in a sentence)."""
    if not ratio > 0:
        return "0 %"
    if ratio < 1e-6:
        return "under 1/1000000"
    if ratio > 1e4:
        return "over 1000000 %"
    return f"1/{1 / ratio:.0f}" if ratio < 0.5 else f"{100 * ratio:.0f} %"


def _res(tables: Tables) -> str:
    w, h = tables.time_at
    return f"{w}×{h}" + (", projected" if tables.projected else "")


def verdicts(tables: Tables) -> list[str]:
    """Sentences from rows whose every figure lies within the measured rungs (none from an extrapolation)."""
    out = []

    wins = [
        r
        for r in tables.equal_time
        if r.best is not None and r.best_error.verdict_ok and not r.contested and r.ratio is not None
    ]
    if wins:
        r = max(wins, key=lambda r: r.budget_spp)
        interval = f" [{num(r.best_error.low)}, {num(r.best_error.high)}]" if r.best_error.low is not None else ""
        out.append(
            f"Equal time ({tables.metric}): within the {num(r.budget_seconds)} s per frame that rendering "
            f"{r.budget_spp} spp takes ({_res(tables)}), {r.best} at {r.best_spp} spp reaches "
            f"{num(r.best_error.value)}{interval} against rendering's {num(r.render_error.value)}: "
            f"{ratio_text(r.ratio)} of its error."
        )
    losses = [r for r in tables.equal_time if r.best is None and r.candidates]
    if losses and not wins and not any(r.contested for r in tables.equal_time):
        out.append(
            f"Equal time ({tables.metric}): at every measured budget rendering alone has the lowest error "
            f"({_res(tables)})."
        )
    for label in tables.denoisers:
        best = None
        for row in tables.equal_quality:
            need = row.needs.get(label)
            if row.render_how != "measured" or need is None or not need[1].verdict_ok or not row.render_seconds > 0:
                continue  # no time to compare with (a render of no seconds) is no verdict
            ratio = need[1].value / row.render_seconds
            if best is None or ratio < best[0]:
                best = (ratio, row, need)
        if best is None:
            continue
        ratio, row, (spp, seconds) = best
        bound = "at most " if spp.how == "at_most" else ""
        low, high = row.ratio_bounds.get(label, (ratio, ratio))
        spread = (
            f"; {ratio_text(low)}–{ratio_text(high)} across the timings' spread"
            if ratio_text(low) != ratio_text(high)
            else ""
        )
        if high < 1 - ABOUT:
            tail = f"{ratio_text(ratio)} of rendering's time{spread}"
        elif low > 1 + ABOUT:
            tail = f"{ratio:.2g}× rendering's time{spread}: rendering more samples is cheaper"
        else:
            span = f"{ratio_text(low)}–{ratio_text(high)} across the timings' spread"
            side = withheld_side(low, high)
            if side == "slower":
                tail = f"no faster than rendering ({span}: no saving, perhaps a loss)"
            elif side == "faster":
                tail = f"below rendering's time, perhaps only slightly ({span}: a saving too small to call)"
            else:
                tail = f"about rendering's time ({span}: no saving shown)"
        out.append(
            f"Equal quality ({tables.metric}): {label} reaches the error of {row.target_spp:g}-spp rendering "
            f"({num(row.target)}) in {bound}{num(seconds.value)} s per frame against {num(row.render_seconds)} s "
            f"({_res(tables)}), {tail}."
        )
    return out


def as_dict(tables: Tables) -> dict:
    """results.json's form of the tables."""

    def est(e: Estimate | None):
        return None if e is None else {"value": e.value, "how": e.how, "ci95": [e.low, e.high]}

    return {
        "metric": tables.metric,
        "time_at": list(tables.time_at),
        "projected": tables.projected,
        "equal_time": [
            {
                "budget_spp": r.budget_spp,
                "budget_seconds": r.budget_seconds,
                "render_error": est(r.render_error),
                "best": r.best,
                "best_spp": r.best_spp,
                "best_seconds": r.best_seconds,
                "best_error": est(r.best_error),
                "error_ratio": r.ratio,
                "contested": r.contested,
            }
            for r in tables.equal_time
        ],
        "equal_quality": [
            {
                "target": r.target,
                "target_spp": r.target_spp,
                "target_how": r.render_how,
                "render_seconds": r.render_seconds,
                "denoisers": {
                    label: None
                    if need is None
                    else {
                        "spp": est(need[0]),
                        "seconds": est(need[1]),
                        "time_ratio_bounds": list(r.ratio_bounds[label]) if label in r.ratio_bounds else None,
                    }
                    for label, need in r.needs.items()
                },
            }
            for r in tables.equal_quality
        ],
        "verdicts": verdicts(tables),
    }
