"""Number and table formatting shared by the HTML and Markdown reports (plain strings, no markup)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from denoisebench.analysis.aggregate import rule_of
from denoisebench.metrics import get_metric
from denoisebench.results.finite import num  # noqa: F401 (fmt.num for the report modules)
from denoisebench.results.names import NOISY

if TYPE_CHECKING:
    from denoisebench.reports.model import ReportModel, StabilityCase

#: Metrics shown in the summary tables, in this order.
LEAD_METRICS = (
    "relmse_robust",  # the headline (metrics.robust): a handful of fireflies cannot decide it
    "relmse",
    "smape",
    "flip",
    "ssim",
    "psnr",
    "deltae2000",
    "grad_l1",
    "hfen",
    "temporal_relmse_robust",
    "temporal_relmse",
    "tpsnr",
    "temporal_l1",
    "temporal_l1_warped",
)


#: Left out of the summary tables to keep them readable (still in results.json/csv; the temporal
#: ones are in the flicker table).
HIDDEN_IN_TABLES = ("grad_l1", "temporal_l1", "temporal_l1_warped")
#: Most "not distinguishable" sentences a report lists (the rest are in results.json).
MAX_PAIR_LINES = 12
#: How a heading names an aggregation rule other than the mean (see analysis.aggregate).
RULE_NOTE = {"geomean": "geo. mean", "relative_to_input": "× input"}


def cell_text(cell) -> str:
    """``mean [low, high]`` (the interval only when there were ≥ 2 scenes)."""
    if cell is None or cell.value is None:
        return "—"
    if cell.low is None:
        return num(cell.value)
    return f"{num(cell.value)} [{num(cell.low)}, {num(cell.high)}]"


def metric_heading(name: str) -> str:
    """``name ↓`` (or ↑), with the aggregation rule when it is not the mean: ``hfen ↓ (× input)``."""
    try:
        metric = get_metric(name)
    except ValueError:
        return name
    note = RULE_NOTE.get(metric.aggregate)
    return f"{name} {'↑' if metric.higher_is_better else '↓'}" + (f" ({note})" if note else "")


def _has_floor(rows, metric: str) -> bool:
    return any(r.metrics.get(metric) is not None and r.metrics[metric].floor is not None for r in rows)


def _metric_columns(rows, metrics: list[str]) -> tuple[list[str], list]:
    """Headings and cell makers: each metric; one with a floor leads with its corrected value (heading
    ``… corrected``, with its interval), then the raw score and the floor beside it."""
    header, makers = [], []
    for m in metrics:
        floored = _has_floor(rows, m)
        header.append(metric_heading(m) + (" corrected" if floored else ""))
        makers.append(lambda r, m=m: cell_text(r.metrics.get(m)))
        if floored:
            header += [f"{m} raw", f"{m} floor"]
            makers.append(lambda r, m=m: num(r.metrics[m].raw) if r.metrics.get(m) else "—")
            makers.append(lambda r, m=m: num(r.metrics[m].floor) if r.metrics.get(m) else "—")
    return header, makers


def summary_rows(report: ReportModel, spp: int) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the summary table at ``spp``: noisy first, then by the lead metric
    (LEAD_METRICS' first that the run has: the robust relMSE, else relMSE)."""
    # the tables show the lead metrics; results.json/results.csv hold every one
    metrics = [
        m for m in LEAD_METRICS if m in report.frame_metrics + report.sequence_metrics and m not in HIDDEN_IN_TABLES
    ]
    rows = [r for r in report.summary if r.spp == spp]
    headings, makers = _metric_columns(rows, metrics)
    header = ["denoiser", *headings, "denoise s/frame", "total s/frame", "frames"]
    lead = next((m for m in metrics if m in ("relmse_robust", "relmse")), "relmse")
    key = lambda r: (
        r.denoiser != NOISY,
        r.metrics.get(lead).value if r.metrics.get(lead) and r.metrics[lead].value is not None else math.inf,
    )  # noqa: E731
    body = []
    for r in sorted(rows, key=key):
        name = r.denoiser + (f" ({r.failed_units} failed)" if r.failed_units else "")
        body.append([name, *(make(r) for make in makers), num(r.denoise_seconds), num(r.total_seconds), str(r.frames)])
    return header, body


def flicker_rows(report: ReportModel, spp: int) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the flicker table at ``spp``: every temporal metric of the run, scale-free first
    (``report.temporal_metrics``), each aggregated by its rule; noisy first, then by the lead metric."""
    metrics = report.temporal_metrics or report.sequence_metrics
    rows = [r for r in report.summary if r.spp == spp]
    headings, makers = _metric_columns(rows, metrics)
    lead = metrics[0] if metrics else None
    sign = -1.0 if lead == "tpsnr" else 1.0

    def key(r):
        cell = r.metrics.get(lead) if lead else None
        return (r.denoiser != NOISY, sign * cell.value if cell is not None and cell.value is not None else math.inf)

    return ["denoiser", *headings], [[r.denoiser, *(make(r) for make in makers)] for r in sorted(rows, key=key)]


def not_held_out_lines(report: ReportModel) -> list[str]:
    """One sentence per denoiser that was trained on some of the run's scenes (store ``trained_on``)."""
    lines = []
    for d in report.denoisers:
        scenes = d.trained_on
        if scenes:
            lines.append(
                f"{d.label} was trained on {len(scenes)} of the {len(report.scenes)} scene(s) scored here "
                f"({', '.join(scenes)}): its scores are not held-out there and flatter it."
            )
    return lines


def indistinguishable_lines(report: ReportModel) -> list[str]:
    """One sentence per pair of denoisers the reference cannot tell apart (analysis.indistinguishable_pairs);
    pairs of identical denoisers (``report.identical``, said once under Summary) are left out."""
    same = {frozenset((a, b)) for g in report.identical for a in g.labels for b in g.labels if a != b}
    lines = []
    for p in report.indistinguishable:
        if frozenset((p.a, p.b)) in same:
            continue
        scale = "" if rule_of(p.metric) == "mean" else " in log ratio"
        lines.append(
            f"{p.spp} spp, {p.metric}: {p.a} and {p.b} are not distinguishable at this reference quality "
            f"(difference {num(p.difference)}{scale}; the reference resolves ±{num(p.resolution)})."
        )
    if len(lines) > MAX_PAIR_LINES:  # a reference that resolves little makes dozens: the table reads them
        lines = lines[:MAX_PAIR_LINES] + [
            f"... and {len(lines) - MAX_PAIR_LINES} more pairs (results.json, not_distinguishable)"
        ]
    return lines


def effect_rows(report: ReportModel) -> tuple[list[str], list[list[str]], dict[str, str]]:
    """(header, rows, worst effect per denoiser) of the per-effect breakdown, values in % of input error."""
    effects = report.effects
    names = effects.effects
    header = ["denoiser", "overall", *names]
    rows, worst = [], {}
    for label, values in effects.table.items():
        present = {e: values.get(e) for e in names if values.get(e) is not None}
        if len(present) >= 2:  # "suffers most" compares columns: one column has nothing to compare
            worst[label] = max(present, key=present.get)
        rows.append(
            [label, *(("—" if values.get(k) is None else f"{100 * values[k]:.3g}%") for k in ["overall", *names])]
        )
    return header, rows, worst


def stability_rows(table: dict[str, list[StabilityCase]]) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the hard-case table: one column per case, ``ok`` or ``FAILED: detail``."""
    cases = sorted({row.case for rows in table.values() for row in rows})
    rows = []
    for label, results in table.items():
        by_case = {r.case: r for r in results}
        rows.append(
            [
                label,
                *(
                    ("ok" if by_case[c].status == "ok" else f"FAILED: {by_case[c].detail}") if c in by_case else "—"
                    for c in cases
                ),
            ]
        )
    return ["denoiser", *cases], rows


# --------------------------------------------------------------------------------------------------
# time model and equal-time / equal-quality tables

#: How a table marks a figure read off the measured rungs in another way than measured.
HOW_MARK = {"measured": "", "interpolated": "", "at_most": "≤ ", "extrapolated": ""}


def _estimate(e, digits: int = 3) -> str:
    """``value`` (``≤ value`` for a bound, ``value (extrapolated)`` outside the measured rungs)."""
    if e is None:
        return "—"
    text = HOW_MARK.get(e.how, "") + num(e.value, digits)
    if e.low is not None and e.high is not None:
        text += f" [{num(e.low)}, {num(e.high)}]"
    return text + (" (extrapolated)" if e.how == "extrapolated" else "")


def time_axis_text(report: ReportModel) -> str:
    """One sentence: the resolution the report's times are for, the size they were timed at, and whether they
    are projected."""
    model = report.time_model
    width, height = model.time_at
    w0, h0 = model.dataset_size
    if not model.projected:
        return f"Times are per frame at the dataset's {w0}×{h0}, as measured."
    beyond = (
        " and beyond the largest size timed (extrapolated along the measured line)"
        if model.extrapolated_pixels()
        else ""
    )
    at = f" at {model.timed_size[0]}×{model.timed_size[1]}" if model.timed_size else " at a larger size"
    return (
        f"Times are per frame at {width}×{height}, projected from {w0}×{h0} frames and timings{at} "
        f"(fixed cost per call + cost per pixel){beyond}: every time in the tables and figure is projected."
    )


def machine_text(report: ReportModel) -> str:
    m = report.time_model.machine or {}
    gpu = m.get("gpu") or "none"
    return f"Machine: {m.get('cores', '?')} cores ({m.get('cpu') or '?'}, {m.get('system') or '?'}), GPU {gpu}."


def buffers_text(buffers) -> str:
    """A render line's buffer set in words: "colour only", "colour + albedo, normal", "+ per-sample data"."""
    extra = [b for b in buffers if b not in ("color", "diffuse", "specular", "samples")]
    if not buffers:
        return "the dataset's buffers"
    text = "colour + " + ", ".join(extra) if extra else "colour only"
    return text + (" + per-sample data" if "samples" in buffers else "")


def time_model_rows(report: ReportModel) -> tuple[list[str], list[list[str]]]:
    """(header, rows): each render line's and each denoiser's fixed and per-pixel cost, and the time at the axis'
    size; a render line's row names what it renders and who pays it (rendering alone: the noisy input's curve
    and every budget of the equal tables)."""
    model = report.time_model
    width, height = model.time_at
    header = ["", "fixed s (per call/frame)", "s per megapixel", f"s per frame at {width}×{height}", "measured how"]
    rows = []
    payers = model.payers()
    for key, r in model.lines.items():
        top = max(r.measured_spp) if r.measured_spp else 1
        paid = ["rendering alone" if label == NOISY else label for label in payers.get(key, [])]
        rows.append(
            [
                f"render: {buffers_text(r.buffers)}",
                num(r.fixed),
                f"{num(r.offset_per_megapixel)} + {num(r.per_megapixel_per_spp)} per spp",
                f"{num(r.seconds(model.pixels, top))} at {top} spp",
                f"paid by {', '.join(paid) if paid else 'none'}; {r.note}",
            ]
        )
    for label, c in model.denoisers.items():
        lowest = min(c.small)
        timed = (
            f"{num(c.small[lowest])} s at {model.dataset_size[0]}×{model.dataset_size[1]}"
            + (f", {num(c.large_seconds)} s at {num(c.large_pixels / 1e6, 2)} MP" if c.large_pixels else "")
            + (
                f" ({lowest} spp), {num(c.highest.seconds)} s at {num(c.highest.pixels / 1e6, 2)} MP ({c.highest.spp} spp)"
                if c.highest
                else ""
            )
            + (f"; {c.note}" if c.note else "")
        )
        rows.append([label, num(c.fixed), num(c.per_megapixel), num(model.denoise_seconds(label, lowest)), timed])
    return header, rows


def empty_table_text(table) -> str:
    return (
        f"No equal-time or equal-quality table for {table.metric}: the noisy input has no aggregated score at the "
        "measured rungs (every scene left out, e.g. references that cannot resolve the score, or no render times)."
    )


def equal_time_rows(table) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of one metric's equal-time table."""
    header = [
        "budget (render s spp)",
        "s per frame",
        f"rendering alone: {table.metric}",
        "best within budget",
        f"its {table.metric}",
        "its s per frame",
        "error ratio",
    ]
    rows = []
    for r in table.equal_time:
        best = f"{r.best} at {r.best_spp} spp" if r.best else "rendering alone"
        rows.append(
            [
                f"{r.budget_spp} spp",
                num(r.budget_seconds),
                _estimate(r.render_error),
                best,
                _estimate(r.best_error) if r.best else "—",
                num(r.best_seconds) if r.best else "—",
                num(r.ratio) if r.best else "—",
            ]
        )
    return header, rows


def equal_quality_rows(table) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of one metric's equal-quality table: one column per error target (rendering alone's
    error at a rung, or beyond the rungs, marked), one row per denoiser after rendering alone's own row;
    each cell the seconds per frame needed (and the spp it renders)."""
    header = [f"{table.metric} target →"]
    for r in table.equal_quality:
        mark = " (extrapolated)" if r.render_how == "extrapolated" else ""
        header.append(f"{num(r.target)} = {r.target_spp:g} spp{mark}")
    rows = [
        [
            "rendering alone",
            *(
                num(r.render_seconds) + (" (extrapolated)" if r.render_how == "extrapolated" else "")
                for r in table.equal_quality
            ),
        ]
    ]
    for label in table.denoisers:
        cells = []
        for r in table.equal_quality:
            need = r.needs.get(label)
            if need is None:
                cells.append("not reached")
                continue
            spp, seconds = need
            cells.append(f"{_estimate(seconds)} ({HOW_MARK.get(spp.how, '')}{num(spp.value)} spp)")
        rows.append([label, *cells])
    return header, rows
