"""report.md: the report's text and tables in Markdown; figures linked from ``figures/``.

Notes
-----
* Names are user input (a plugin picks its own name): ``|``, ``<``, ``>``, backticks and ``*_[]``
  are escaped so that a name can neither break a table nor inject markup into a Markdown renderer
  that passes HTML through.
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

from denoisebench.plugins.proxy import isolation_text
from denoisebench.reports import formatting as fmt
from denoisebench.reports import notes, summary_screen, wide_tables
from denoisebench.reports.samplers import undersampled_lines

if TYPE_CHECKING:
    from denoisebench.reports.model import ReportModel, StabilityCase

_SPECIAL = re.compile(r"([\\`*_\[\]|<>#])")


def md(text) -> str:
    return _SPECIAL.sub(r"\\\1", str(text)).replace("\n", " ")


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = ["| " + " | ".join(md(h) for h in header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(md(c) for c in row) + " |" for row in rows]
    return lines + [""]


#: The lead columns of wide tables (as index.html's).
SHORT_METRICS = ("relmse_robust", "relmse", "flip", "ssim", "temporal_relmse_robust", "cvvdp", "tpsnr")
SHORT_EXTRA = ("total s/frame",)


def _wide(header: list[str], rows: list[list[str]]) -> list[str]:
    """A wide table as two: its lead columns, then "More columns" (the label and the rest)."""
    lines = _table(*wide_tables.lead_view(header, rows, metrics=SHORT_METRICS, extra=SHORT_EXTRA))
    rest = wide_tables.rest_view(header, rows, metrics=SHORT_METRICS, extra=SHORT_EXTRA)
    if rest is not None:
        lines += ["More columns (raw scores, floors, every metric):", ""] + _table(*rest)
    return lines


def _summary(report: ReportModel) -> list[str]:
    """The first screen (:mod:`.summary_screen`)."""
    screen = report.first_screen
    if screen is None:
        return []
    lines = ["## Summary", ""] + _table(*summary_screen.screen_rows(screen))
    return lines + [f"- {md(line)}" for line in summary_screen.screen_lines(screen)] + [""]


def render_markdown(report: ReportModel) -> str:
    run = report.run
    lines = [
        "# denoisebench report",
        "",
        f"Run `{run.run_id}` on dataset `{run.dataset_hash[:12]}` ({md(run.dataset_path)}), split "
        f"{md(run.config.get('split'))}: {len(report.scenes)} scene(s), input spp {', '.join(map(str, report.spp))}, "
        f"reference {report.reference.description}. Started {run.created_at}, finished {run.finished_at or 'not yet (partial)'}.",
        "",
        md(isolation_text(run.config, run.versions)),
        "",
        *_summary(report),
        "## Accuracy against time",
        "",
        "![error against seconds per frame](figures/accuracy_time.png)",
        "",
        "Each point is a denoiser at one input spp: its mean error against its total seconds per frame "
        "(render at that spp + denoise, at the resolution stated under Times); along a denoiser's curve its spp rise "
        "left to right. The grey curve, on top, is the noisy input at rising spp: what rendering more samples buys "
        "(dashed stub: extrapolated). The axes span the measured points; the reference's time is written at the "
        "edge when it lies beyond them. Circled points are on the Pareto front.",
        "",
    ]
    for metric, sentences in report.readings.items():
        lines += [f"**{metric}**", ""] + [f"- {md(s)}" for s in sentences] + [""]
    for panel in report.accuracy:
        for hidden in panel.hidden:
            lines.append(f"- not drawn: {md(hidden)}")
    if report.time_model is not None:
        lines += [""] + _times(report)
    lines += [
        "## Results",
        "",
        "Scores combined over scenes by each metric's rule (scale-free ones by their mean; linear ones by the "
        "geometric mean or relative to the noisy input, as marked), with a bootstrap 95 % interval over scenes "
        "that includes the reference's uncertainty (↓ lower is better, ↑ higher). *floor*: what the reference's "
        "own noise adds to a score; *corrected*: the score less its floor (against the noise-free image); *raw*: "
        "as measured against the reference.",
        "",
        md(notes.correction_text(report)),
        "",
    ]
    lines += [f"> **Not held-out:** {md(line)}\n" for line in fmt.not_held_out_lines(report)]
    lines += [f"> **Pixels without a sample:** {md(line)}\n" for line in undersampled_lines(report.samplers)]
    if "scenes" in report.figures:
        lines += [
            "### Where each denoiser wins, per scene",
            "",
            "![where each denoiser wins, per scene](figures/scenes.png)",
            "",
            "Each cell: the denoiser's lead score on that scene at that spp over the noisy input's there; framed: "
            "the scene's lowest at that spp.",
            "",
        ]
    for spp in report.spp:
        header, rows = fmt.summary_rows(report, spp)
        lines += [f"### {spp} spp", ""] + _wide(header, rows)
    deciding = notes.deciding_frame_lines(report)
    if deciding:
        lines += (
            [
                "### Frames that would decide a mean",
                "",
                "A scene's score is the trimmed mean of its frames (one frame in eight dropped at each end; for flicker, "
                "of its frame pairs, two in seven), so these frames (for flicker: the later frame of the pair), far "
                "above the rest of their scene, do not decide it; index.html's image comparisons show each unit's worst "
                "frame of each lead score.",
                "",
            ]
            + [f"- {md(line)}" for line in deciding]
            + [""]
        )
    pairs = fmt.indistinguishable_lines(report)
    if pairs:
        lines += ["### Not distinguishable at this reference quality", ""] + [f"- {md(p)}" for p in pairs] + [""]
    unresolved = notes.unresolved_text(report)
    if unresolved:
        lines += ["### References that cannot resolve a score", "", md(unresolved), ""]
        lines += [f"- {md(line)}" for line in notes.unresolved_lines(report)] + [""]
    missing = notes.not_applicable_lines(report)
    if missing:
        lines += ["### Metrics that did not apply", ""]
        lines += ["These metrics have no value where their preconditions fail; the frames keep their other scores.", ""]
        lines += [f"- {md(line)}" for line in missing] + [""]
    header, rows, worst = fmt.effect_rows(report)
    lines += [
        "## Per-effect breakdown",
        "",
        f"Share of the noisy input's {report.effects.metric} left after denoising (geometric mean over the scenes "
        "with the effect and over spp; lower is better).",
        "",
    ]
    if report.effects.effects:
        lines += _table(header, rows)
        lines += [f"- {md(label)} suffers most from **{md(effect)}**" for label, effect in worst.items()] + [""]
    elif not report.effects.too_few:
        lines += ["The scenes declare no effects.", ""]
    lines += [f"- {md(note)}" for note in report.effects.notes] + [""]
    lines += ["## Temporal flicker", ""]
    if report.flicker.series:
        lines += [
            "![flicker per frame](figures/flicker.png)",
            "",
            "Temporal relMSE (warped frame differences over the reference's local magnitude, scale-free), "
            "cvvdp (ColorVideoVDP, JOD: 10 = no visible difference, how visible the flicker is) and "
            "tPSNR lead; linear temporal scores follow relative to the noisy input.",
            "",
        ]
        for spp in report.spp:
            header, rows = fmt.flicker_rows(report, spp)
            lines += [f"### {spp} spp", ""] + _wide(header, rows)
        if report.strips:
            lines += ["Frame strips of one crop per denoiser are in index.html.", ""]
        if report.cvvdp_viewing:
            lines += ["### cvvdp viewing conditions", "", md(notes.viewing_text(report)), ""]
            lines += _table(*notes.viewing_rows(report))
    else:
        lines += ["Sequences of one frame: no flicker to measure.", ""]
    lines += [
        "## Image comparisons",
        "",
        "Open index.html for the images, zoomed crops and the interactive compare: the last frame of each scene at "
        "each input spp, then the frames that would decide a scene's mean:",
        "",
    ]
    lines += [
        f"- {md(comp.scene)}, frame {comp.frame}, {comp.spp} spp: {md(comp.why)}"
        for comp in report.comparisons
        if comp.why
    ] + ([""] if any(comp.why for comp in report.comparisons) else [])
    if report.samplers:
        lines += _samplers(report)
    lines += ["## Hard-case stability", ""]
    lines += _stability(report.stability)
    if report.failures:
        lines += ["## Failures", ""] + _table(
            ["denoiser", "scene", "spp", "error"],
            [[f.denoiser, f.scene, str(f.spp), f.error or ""] for f in report.failures],
        )
    not_loaded = [d for d in report.denoisers if d.load_error]
    if not_loaded:
        lines += ["## Not run", ""] + [f"- {md(d.spec)}: {md(d.load_error)}" for d in not_loaded] + [""]
    versions = ", ".join(f"{k} {v}" for k, v in sorted(run.versions.items()))
    lines += ["## Software", "", md(versions), ""]
    return "\n".join(lines)


def _times(report: ReportModel) -> list[str]:
    """The time axis' resolution and machine, the fixed and per-pixel costs, and the two tables."""
    lines = ["### Times", "", md(fmt.time_axis_text(report)) + " " + md(fmt.machine_text(report)), ""]
    lines += [f"- {md(note)}" for note in [*report.time_model.notes, report.time_model.measurement_text()]]
    lines += _table(*fmt.time_model_rows(report))
    lines += [
        "## Equal time and equal quality",
        "",
        "*Equal time*: for each budget (the seconds rendering s spp takes), the (denoiser, spp) of lowest error "
        "whose render + denoise seconds fit it, against rendering alone. *Equal quality*: for each error target "
        "(rendering alone at each measured rung, then beyond it), the seconds each denoiser needs. Between "
        "measured rungs figures are interpolated on log-log axes; outside them they are marked extrapolated "
        "and make no verdict; ≤: met at the lowest measured spp already.",
        "",
    ]
    for table in report.equal_tables:
        if not table.equal_time and not table.equal_quality:
            lines += [f"- {md(fmt.empty_table_text(table))}", ""]
            continue
        lines += [f"### Equal time: {md(table.metric)}", ""] + _table(*fmt.equal_time_rows(table))
        lines += [f"### Equal quality: {md(table.metric)}", ""] + _equal_quality(table)
    if report.verdicts:
        lines += ["**Verdicts** (measured rungs only)", ""] + [f"- {md(v)}" for v in report.verdicts] + [""]
    return lines


def _equal_quality(table) -> list[str]:
    """The equal-quality table split: the measured targets, then those beyond the rungs (extrapolated)."""
    header, rows = fmt.equal_quality_rows(table)
    measured = [i for i, h in enumerate(header) if "(extrapolated)" not in h]
    if len(measured) == len(header):
        return _table(header, rows)
    extra = [0] + [i for i in range(1, len(header)) if i not in measured]
    lines = _table(*wide_tables.pick(header, rows, measured))
    return (
        lines
        + ["Targets beyond the measured rungs (extrapolated):", ""]
        + _table(*wide_tables.pick(header, rows, extra))
    )


def _samplers(report: ReportModel) -> list[str]:
    """The live samplers: unsampled-pixel warnings, spp counts, and each map beside its image."""
    lines = ["## Samplers", ""]
    lines += [f"- **Pixels without a sample:** {md(line)}" for line in undersampled_lines(report.samplers)]
    lines += [""] + _table(*notes.sampler_rows(report))
    lines += [
        md(notes.sampler_scale_text()),
        "",
        "Colour bar (0 → top): ![spp colour bar](figures/spp_maps/colour_bar.png)",
        "",
    ]
    for n, comp in enumerate(report.comparisons):
        mapped = [(k, entry) for k, entry in enumerate(comp.entries) if entry.spp_map is not None]
        if not mapped:
            continue
        lines += [f"### {md(comp.scene)}, frame {comp.frame}, {comp.spp} spp", ""]
        header = ["sampler", "image", "spp map", "mean spp", "min–max spp", "pixels < 1 spp", "scale"]
        lines += ["| " + " | ".join(md(h) for h in header) + " |", "|" + "---|" * len(header)]
        for k, entry in mapped:
            m = entry.spp_map
            lines.append(
                f"| {md(entry.label)} | ![{md(entry.label)}](figures/spp_maps/{n}_{k}_image.png) "
                f"| ![spp map of {md(entry.label)}](figures/spp_maps/{n}_{k}.png) | {m.mean:.3g} | "
                f"{m.min}–{m.max} | {m.pixels_without_samples} | 0–{m.top} spp |"
            )
        lines.append("")
    return lines


def _stability(table: dict[str, list[StabilityCase]] | None) -> list[str]:
    if table is None:
        return ["The hard-case suite (denoisebench.denoisers.hard_cases) is not available in this installation.", ""]
    return _table(*fmt.stability_rows(table))
