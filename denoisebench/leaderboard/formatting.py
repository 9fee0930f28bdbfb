"""Number and table formatting shared by the HTML and Markdown reports (plain strings, no markup)."""

from __future__ import annotations

import math

from .runner import NOISY

#: Metrics shown in the summary tables, in this order.
LEAD_METRICS = ("relmse", "flip", "ssim", "psnr", "smape", "deltae2000", "grad_l1", "hfen", "temporal_l1", "temporal_l1_warped", "tpsnr")


#: Left out of the summary tables to keep them readable (still in results.json/csv).
HIDDEN_IN_TABLES = ("smape", "grad_l1", "temporal_l1_warped")


def num(value, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return f"{value:.{digits}g}"


def cell_text(cell) -> str:
    """``mean [low, high]`` (the interval only when there were ≥ 2 scenes)."""
    if cell is None or cell.mean is None:
        return "—"
    if cell.low is None:
        return num(cell.mean)
    return f"{num(cell.mean)} [{num(cell.low)}, {num(cell.high)}]"


def metric_heading(name: str) -> str:
    from denoisebench.metrics import get_metric

    try:
        return f"{name} {'↑' if get_metric(name).higher_is_better else '↓'}"
    except ValueError:
        return name


def summary_rows(report: dict, spp: int) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the summary table at ``spp``: noisy first, then by relMSE."""
    # the tables show the lead metrics; results.json/results.csv hold every one
    metrics = [m for m in LEAD_METRICS if m in report["frame_metrics"] + report["sequence_metrics"] and m not in HIDDEN_IN_TABLES]
    header = ["denoiser", *(metric_heading(m) for m in metrics), "denoise s/frame", "total s/frame", "frames"]
    rows = [r for r in report["summary"] if r.spp == spp]
    key = lambda r: (r.denoiser != NOISY, r.metrics.get("relmse").mean if r.metrics.get("relmse") and r.metrics["relmse"].mean is not None else math.inf)  # noqa: E731
    body = []
    for r in sorted(rows, key=key):
        name = r.denoiser + (f" ({r.failed_units} failed)" if r.failed_units else "")
        body.append([name, *(cell_text(r.metrics.get(m)) for m in metrics), num(r.denoise_seconds), num(r.total_seconds), str(r.frames)])
    return header, body


def effect_rows(report: dict) -> tuple[list[str], list[list[str]], dict[str, str]]:
    """(header, rows, worst effect per denoiser) of the per-effect breakdown, values in % of input error."""
    effects = report["effects"]
    names = effects["effects"]
    header = ["denoiser", "overall", *names]
    rows, worst = [], {}
    for label, values in effects["table"].items():
        present = {e: values.get(e) for e in names if values.get(e) is not None}
        if present:
            worst[label] = max(present, key=present.get)
        rows.append([label, *(("—" if values.get(k) is None else f"{100 * values[k]:.3g}%") for k in ["overall", *names])])
    return header, rows, worst


def stability_rows(table: dict[str, list[dict]]) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the hard-case table: one column per case, ``ok`` or ``FAILED: detail``."""
    cases = sorted({row["case"] for rows in table.values() for row in rows})
    rows = []
    for label, results in table.items():
        by_case = {r["case"]: r for r in results}
        rows.append([
            label,
            *(("ok" if by_case[c]["status"] == "ok" else f"FAILED: {by_case[c].get('detail', '')}") if c in by_case else "—" for c in cases),
        ])
    return ["denoiser", *cases], rows
