"""Text both renderers share for the report's conditions: cvvdp's viewing, metrics that did not apply, samplers.

Each function takes the report model (:func:`.build.build_report`) and returns sentences or
(header, rows) for :mod:`.markdown` and :mod:`.html`, which escape them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from denoisebench.metrics import get_metric
from denoisebench.reports import formatting as fmt
from denoisebench.reports.samplers import frame_groups

if TYPE_CHECKING:
    from denoisebench.reports.model import ReportModel


def viewing_text(report: ReportModel) -> str:
    """cvvdp's display in one sentence: model, size, peak, ambient light, pixels per degree, fps, exposure rule."""
    d = report.cvvdp_viewing.display
    width, height = d.resolution
    return (
        f"cvvdp models the viewer of display {d.display}: {width}×{height} px, peak {d.peak_cd_m2:.0f} cd/m², "
        f"black {d.black_cd_m2:.3g} cd/m², {d.ambient_lux:.0f} lux ambient, {d.ppd:.1f} pixels per degree, "
        f"{d.fps:.0f} fps. Exposure (cd/m² per unit radiance), one per scene from its reference: the "
        f"log-average luminance of the reference's lit pixels is shown at {d.target_key_cd_m2:.0f} cd/m²; "
        "every denoiser of a scene gets the same exposure."
    )


def viewing_rows(report: ReportModel) -> tuple[list[str], list[list[str]]]:
    """Per scene: frame size, the visual angle it spans, exposure, lit and clipped share of the reference."""
    header = ["scene", "frame px", "field of view", "exposure (cd/m² per unit)", "lit pixels", "clipped at peak"]
    rows = []
    for scene, v in report.cvvdp_viewing.scenes.items():
        w, h = v.frame_px
        rows.append(
            [
                scene,
                f"{w}×{h}",
                f"{v.field_deg[0]:.2f}°×{v.field_deg[1]:.2f}°",
                fmt.num(v.exposure),
                f"{100 * v.lit_fraction:.0f} %",
                f"{100 * v.clipped_fraction:.1f} %",
            ]
        )
    return header, rows


def not_applicable_lines(report: ReportModel) -> list[str]:
    """One sentence per metric that had no value somewhere: where (scenes, frames, sequences) and why."""
    lines = []
    for item in report.not_applicable_detail:
        where = []
        if item.frames:
            where.append(f"{item.frames} frame(s)")
        if item.sequences:
            where.append(f"{item.sequences} sequence(s)")
        lines.append(
            f"{item.metric}: no value on {' and '.join(where)} of scene(s) {', '.join(item.scenes)} "
            f"(all labels counted): {'; '.join(item.reasons)}"
        )
    return lines


def unresolved_text(report: ReportModel) -> str | None:
    """The heading sentence of the scenes whose reference cannot resolve a score (None: there are none)."""
    unresolved = report.unresolved_references
    if not unresolved.scenes:
        return None
    where = (
        "They are included in the aggregates above (--include-unresolved)."
        if unresolved.included
        else "They are left out of the aggregates above and of the verdicts (run-benchmark --include-unresolved "
        "puts them back); their rows stay in results.json and results.csv."
    )
    return (
        "These scenes' scores cannot be used even floor-corrected: their reference's floor is not known well "
        f"enough, or no two entries there differ by more than the reference resolves. {where}"
    )


def unresolved_lines(report: ReportModel) -> list[str]:
    """One sentence per unresolved scene and reason, with the reference spp it would need."""
    return [item.sentence() for item in report.unresolved_references.scenes]


def sampler_scale_text() -> str:
    """How to read the spp maps."""
    return (
        "Each sampler's samples per pixel at the frame shown, beside its image: viridis colours, linear from "
        "0 spp (dark violet) to the largest count any sampler gave a pixel of that scene at that spp (yellow, stated under "
        "each map); red: a pixel with fewer than 1 sample (its value is 0, not an estimate). A sampler's pairs "
        "with denoisers share its render and its map."
    )


def sampler_rows(report: ReportModel) -> tuple[list[str], list[list[str]]]:
    """Per sampler, scene and spp: frames, mean and largest spp, frames and pixels left without a sample."""
    header = [
        "sampler",
        "scene",
        "spp",
        "frames",
        "mean spp",
        "max spp",
        "frames with pixels < 1 spp",
        "pixels < 1 spp",
    ]
    rows = []
    for (sampler, scene, spp), group in frame_groups(report.samplers.frames).items():
        rows.append(
            [
                sampler,
                scene,
                str(spp),
                str(len(group)),
                f"{sum(f.mean_spp for f in group) / len(group):.3g}",
                str(max(f.max_spp for f in group)),
                str(sum(f.pixels_without_samples > 0 for f in group)),
                str(sum(f.pixels_without_samples for f in group)),
            ]
        )
    return header, rows


def correction_text(report: ReportModel) -> str:
    """Which scores lead corrected for the reference's noise, and how (the rule, stated once)."""
    closed, measured, none = [], [], []
    shown = report.frame_metrics + report.sequence_metrics
    for metric in shown:
        cells = [r.metrics.get(metric) for r in report.summary]
        if any(c is not None and c.floor is not None for c in cells):
            (closed if _has_closed_floor(metric) else measured).append(metric)
        else:
            none.append(metric)
    parts = [
        "Scores are corrected for the reference's own noise, and the corrected value leads every table, figure and "
        "verdict (raw score and floor beside it): corrected = score − floor, where the floor is what the "
        "reference's noise adds to the score, and the interval carries the reference's uncertainty."
    ]
    if closed:
        parts.append(f"Closed-form floor from the reference's variance: {', '.join(closed)}.")
    if measured:
        parts.append(
            f"Floor measured from the reference's two independent halves (score against each half and the full "
            f"reference: its 1/spp trend): {', '.join(measured)}."
        )
    if none:
        parts.append(f"Not corrected (no floor, and no half references or a sequence score): {', '.join(none)}.")
    parts.append(
        "A corrected error below the reference's standard error is shown at that resolution (it cannot be told "
        "from 0). A scene is set apart only when its floor is still growing, its reference is too noisy for a "
        "floor, or no two entries there differ by more than it resolves."
    )
    return " ".join(parts)


def _has_closed_floor(metric: str) -> bool:
    try:
        return get_metric(metric).floor_fn is not None
    except ValueError:
        return False


def deciding_frame_lines(report: ReportModel) -> list[str]:
    """One sentence per frame that would decide its scene's plain mean of the lead score (at most 12)."""
    items = report.deciding_frames
    lines = [
        f"{d.label} at {d.spp} spp on {d.scene}, frame {d.frame}: {d.metric} {d.value:.3g} against "
        f"the scene's median {d.median:.3g}"
        for d in items[:12]
    ]
    if len(items) > 12:
        lines.append(f"... and {len(items) - 12} more (results.json, deciding_frames)")
    return lines
