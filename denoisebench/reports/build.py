"""Write a run's report folder: index.html, report.md, results.json, results.csv, figures/.

:func:`build_report` gathers everything (plain data, images as data URIs) from the results store
and the dataset into a :class:`~.model.ReportModel`; :mod:`.html` and :mod:`.markdown` render it;
this module writes the files (results.json from the model's typed parts: :func:`results_json`).

Notes
-----
* **Self-contained.** index.html embeds its figures and images as base64 data URIs and its style
  and script inline: it opens offline, from any folder, with no network request.
* **Atomic files.** Each file is written under a temporary name and renamed
  (:func:`denoisebench.dataset.atomic.atomic_write_bytes`): a killed report leaves the previous
  version of each file or the new one, never a torn file.
* **Comparison frame.** Images compare the last frame of each test sequence (a temporal denoiser
  has seen the frames before it) at the lowest input spp, where denoisers differ most.
* **Flicker.** The figure has one panel per input spp and one row per per-frame flicker metric
  (``temporal_relmse`` and tPSNR, both scale-free, so their mean over scenes is meaningful); the
  table lists every temporal metric the run measured, the scale-free ones first (ColorVideoVDP's
  ``cvvdp`` in JOD beside ``temporal_relmse``), each aggregated by its rule. Frame strips (:mod:`.strips`) show one crop of consecutive frames per denoiser.
* **Floors.** results.json, results.csv and the tables give each MSE-family score's
  reference-noise floor and its floor-corrected value (``score − floor``, an unbiased estimate of
  the score against the noise-free image; :mod:`denoisebench.metrics.floors.closed_form`).
"""

from __future__ import annotations

import base64
import csv
import io
import json
import math
from dataclasses import fields, is_dataclass
from pathlib import Path

import numpy as np

from denoisebench.analysis import accuracy, equal_tables, time_model
from denoisebench.analysis import aggregate as agg
from denoisebench.analysis.aggregate import rule_of
from denoisebench.analysis.summary import (
    RunData,
    effect_breakdown,
    flicker_metrics,
    flicker_series,
    indistinguishable_pairs,
    summary_table,
)
from denoisebench.dataset import Dataset
from denoisebench.dataset.atomic import atomic_write_bytes
from denoisebench.metrics.field.colorvideovdp import viewing_conditions
from denoisebench.reports import comparisons, figures, figures_accuracy, images, screen_parts
from denoisebench.reports import samplers as report_samplers
from denoisebench.reports.html import render_html
from denoisebench.reports.markdown import render_markdown
from denoisebench.reports.model import (
    CvvdpViewing,
    DecidingFrame,
    Failure,
    FlickerSection,
    NotApplicableDetail,
    ReferenceInfo,
    ReportModel,
    SceneViewing,
    StabilityCase,
    UnresolvedReferences,
    ViewingDisplay,
)
from denoisebench.reports.run_inputs import run_data, set_apart_of
from denoisebench.results.names import ERROR_METRICS, NOISY
from denoisebench.results.store import ResultsStore
from denoisebench.results.timings import read_timings


def _clean(value):
    """JSON-safe: NaN/Inf → None, numpy scalars → Python, a typed part → a dict (its ``as_dict``, else its
    fields in order)."""
    if callable(getattr(value, "as_dict", None)):
        return _clean(value.as_dict())
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: _clean(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, (np.floating, float)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def _scene_effects(dataset: Dataset, scenes: list[str]) -> dict[str, list[str]]:
    effects = {}
    for scene in scenes:
        record = dataset.scene(scene).effects
        if isinstance(record, dict):
            names = set(record.get("declared", [])) | set(record.get("inferred", []))
        else:
            names = set(record or [])
        effects[scene] = sorted(names)
    return effects


def _transport(plan: dict) -> str:
    """The plan's light transport in words: full, or the restriction and who asked for it."""
    depth = plan.get("max_depth", -1)
    if depth == -1:
        return "full transport"
    who = {"user": "--max-depth", "stage": "stage metadata"}.get(plan.get("max_depth_source"), "an older plan rule")
    return f"max_depth {depth} ({who})"


def _reference_info(dataset: Dataset, scenes: list[str]) -> ReferenceInfo:
    """Reference seconds and spp, the light transport of every scene's plan (``transport``: one line,
    naming restricted scenes), and the adaptive references' spp used and worst floor reached."""
    seconds, spps, used, floors, restricted = [], set(), [], [], {}
    for scene in scenes:
        info = dataset.scene(scene)
        for record in info.record.get("renders", {}).get("reference", {}).values():
            if record.get("seconds") is not None:
                seconds.append(float(record["seconds"]))
            adaptive = record.get("reference_adaptive") or {}
            if adaptive:
                used.append(int(adaptive["spp"]))
                if adaptive.get("floor") is not None:  # None: a 1-spp reference has no variance estimate
                    floors.append(float(adaptive["floor"]))
        if info.ref_spp:
            spps.add(int(info.ref_spp))
        transport = _transport(info.record.get("plan") or {})
        if transport != "full transport":
            restricted[scene] = transport
    line = (
        "full transport"
        if not restricted
        else "restricted transport: " + "; ".join(f"{scene} {what}" for scene, what in sorted(restricted.items()))
    )
    spp = max(spps) if spps else None
    if used:
        low, high = min(used), max(used)
        words = f"adaptive {low}\u2013{high} spp (cap {spp})" if low != high else f"adaptive {low} spp (cap {spp})"
        if floors:
            words += f", noise floor \u2264 {max(floors):.2g}"
    else:
        words = f"{spp} spp"
    return ReferenceInfo(
        seconds=float(np.mean(seconds)) if seconds else None,
        spp=spp,
        transport=line,
        restricted=restricted,
        description=f"{words}, {line}",
        spp_used=[min(used), max(used)] if used else None,
        floor_max=max(floors) if floors else None,
    )


#: Temporal metrics the flicker table leads with (scale-free; cvvdp is ColorVideoVDP's JOD, how visible
#: the flicker is to a viewer); the others follow, linear ones last.
FLICKER_LEAD = ("temporal_relmse_robust", "temporal_relmse", "cvvdp", "tpsnr")


def temporal_metric_order(names: list[str]) -> list[str]:
    """The flicker table's columns: FLICKER_LEAD, then other mean-aggregated (scale-free) metrics,
    then the rest (linear diagnostics such as temporal_l1), each group in name order."""
    lead = [m for m in FLICKER_LEAD if m in names]
    rest = sorted(m for m in names if m not in lead)
    return lead + [m for m in rest if rule_of(m) == "mean"] + [m for m in rest if rule_of(m) != "mean"]


def _flicker(data: RunData) -> FlickerSection:
    """The spp, the flicker metrics with a series, and {metric: {spp: {label: [per-frame means]}}}."""
    metrics = flicker_metrics(data)
    series: dict[str, dict[int, dict]] = {}
    for metric in metrics:
        for spp in data.spp:
            found = flicker_series(data, spp, metric)
            if found:
                series.setdefault(metric, {})[spp] = found
    return FlickerSection(spp=list(data.spp), metrics=[m for m in metrics if m in series], series=series)


def _cvvdp_viewing(dataset: Dataset, data: RunData) -> CvvdpViewing:
    """cvvdp's viewing conditions (:func:`denoisebench.metrics.field.colorvideovdp.viewing_conditions`): the
    display once, and per scene the frame's visual angle and the exposure from its reference sequence
    (the one cvvdp set for every denoiser of that scene)."""
    display = ViewingDisplay(**viewing_conditions())
    scenes = {}
    spp = data.spp[0] if data.spp else None
    for scene in data.scenes:
        if spp is None:
            break
        count = dataset.scene(scene).frame_count
        refs = [dataset.frame(scene, spp, i, samples=False, buffers=["color"]).reference for i in range(count)]
        found = viewing_conditions(np.stack(refs))
        scenes[scene] = SceneViewing(
            frame_px=found["frame_px"],
            field_deg=found["field_deg"],
            exposure=found["exposure"],
            key=found["key"],
            lit_fraction=found["lit_fraction"],
            clipped_fraction=found["clipped_fraction"],
            text=found["text"],
        )
    return CvvdpViewing(display=display, scenes=scenes)


def _not_applicable_detail(store: ResultsStore, run_id: str) -> list[NotApplicableDetail]:
    """Per metric that did not apply somewhere: the scenes, the frames and sequences concerned, the reasons."""
    rows: dict[str, list] = {}
    for row in store.not_applicable(run_id):
        rows.setdefault(row.metric, []).append(row)
    return [
        NotApplicableDetail(
            metric=metric,
            scenes=sorted({r.scene for r in found}),
            frames=sum(r.frame >= 0 for r in found),
            sequences=sum(r.frame < 0 for r in found),
            reasons=sorted({r.reason for r in found}),
        )
        for metric, found in sorted(rows.items())
    ]


def _dataset_size(dataset: Dataset, scenes: list[str]) -> tuple[int, int]:
    """(width, height) of the run's frames (the first scene's: a run's scenes share one size)."""
    record = dataset.scene(scenes[0]).record if scenes else {}
    return int(record.get("width", 0)), int(record.get("height", 0))


def _deciding_frames(data: RunData, metrics: list[str]) -> list[DecidingFrame]:
    """Frames over 10× their scene's median of each lead metric (:meth:`.run_index.RunIndex.deciding_frames`)."""
    found = []
    for metric, label in ((m, label) for m in metrics if m in data.frame_metric_names for label in data.labels):
        for spp in data.spp:
            for scene in data.scenes:
                for frame, value, median in data.deciding_frames(label, spp, scene, metric=metric):
                    found.append(
                        DecidingFrame(
                            label=label, spp=spp, scene=scene, frame=frame, metric=metric, value=value, median=median
                        )
                    )
    return found


def _stability(table: dict[str, list[dict]] | None) -> dict[str, list[StabilityCase]] | None:
    """The hard-case table (:func:`denoisebench.benchmark.stability.stability_table`'s plain rows), typed."""
    if table is None:
        return None
    return {
        label: [
            StabilityCase(case=r["case"], status=r["status"], detail=r["detail"], seconds=r.get("seconds"))
            for r in rows
        ]
        for label, rows in table.items()
    }


def build_report(
    store: ResultsStore,
    run_id: str,
    dataset: Dataset,
    stability: dict[str, list[dict]] | None = None,
    time_at: tuple[int, int] | None = None,
    include_unresolved: bool = False,
) -> ReportModel:
    """Everything the report shows, as a ReportModel (figures as PNG/SVG, images as data URIs).

    ``stability``: the hard-case table of the run's denoisers
    (:func:`denoisebench.benchmark.stability.stability_table`; the report runs nothing itself).
    ``time_at``: the resolution of the report's time axis (default
    :data:`~denoisebench.analysis.time_model.DEFAULT_TIME_AT`), projected from the run's timings."""
    data = run_data(store, run_id)
    # scenes whose reference cannot resolve the headline scores: listed apart, out of the aggregates
    unresolved = set_apart_of(data, dataset)
    summary = summary_table(data, exclude=() if include_unresolved else agg.excluded_scenes(unresolved))
    reference = _reference_info(dataset, data.scenes)
    model = time_model.build_time_model(
        data, read_timings(store, run_id), time_at, dataset_size=_dataset_size(dataset, data.scenes)
    )
    lead = equal_tables.lead_metrics(data.frame_metric_names + data.sequence_metric_names)
    deciding = _deciding_frames(data, lead)
    measured = data.frame_metric_names + data.sequence_metric_names
    # the figure: the robust relMSE first, raw relMSE beside it, FLIP; the tables: the lead metrics
    shown = [m for m in ERROR_METRICS if m in measured]
    panels = [
        accuracy.accuracy_time(
            data, summary, metric, reference_seconds=reference.seconds, reference_spp=reference.spp, model=model
        )
        for metric in shown
    ]
    tables = [equal_tables.build_tables(summary, model, data.spp, metric=metric) for metric in lead]
    palette = figures_accuracy.colors(data.labels)
    figure_files = {}
    if any(p.points for p in panels):
        figure_files["accuracy_time"] = figures_accuracy.accuracy_time_figure(panels, palette)
    # the first screen, identical denoisers and where each denoiser wins per scene (lead metric)
    parts = screen_parts.screen_parts(store, data, panels, metric=lead[0] if lead else None, summary=summary)
    if parts.scenes_figure is not None:
        figure_files["scenes"] = parts.scenes_figure
    flicker = _flicker(data)
    if flicker.series:
        figure_files["flicker"] = figures.flicker_figure(flicker.series, palette)
    scene_effects = _scene_effects(dataset, data.scenes)
    samplers = report_samplers.sampler_section(store, data.run)
    failures = [
        Failure(denoiser=u.denoiser, scene=u.scene, spp=u.spp, error=u.error)
        for u in data.unit_rows
        if u.status != "ok"
    ]
    return ReportModel(
        run=data.run,
        denoisers=data.entries,
        scenes=data.scenes,
        spp=data.spp,
        scene_effects=scene_effects,
        reference=reference,
        frame_metrics=data.frame_metric_names,
        sequence_metrics=data.sequence_metric_names,
        summary=summary,
        accuracy=panels,
        readings={p.metric: accuracy.readings(p) for p in panels},
        time_model=model,
        equal_tables=tables,
        verdicts=[v for t in tables for v in equal_tables.verdicts(t)],
        effects=effect_breakdown(data, scene_effects),
        flicker=flicker,
        temporal_metrics=temporal_metric_order(data.sequence_metric_names),
        indistinguishable=indistinguishable_pairs(data, summary),
        strips=comparisons.scene_strips(store, data, dataset, spp=data.spp[0]) if data.spp else [],
        failures=failures,
        unresolved_references=UnresolvedReferences(included=include_unresolved, scenes=unresolved),
        # metrics whose preconditions the frames do not meet (SSIM under 11×11 px): frames count, reason
        not_applicable=store.not_applicable_summary(run_id),
        comparisons=comparisons.comparisons(store, data, dataset, deciding=deciding, samplers=samplers),
        # live samplers: per-frame spp counts, maps (on comparison entries) and pixels left without a sample
        samplers=samplers,
        # cvvdp's display, pixels per degree and each scene's exposure (None: cvvdp not measured)
        cvvdp_viewing=_cvvdp_viewing(dataset, data) if "cvvdp" in data.sequence_metric_names else None,
        # which scenes and frames each not-applicable metric lacks, and why
        not_applicable_detail=_not_applicable_detail(store, run_id),
        stability=_stability(stability),
        figures=figure_files,
        palette=palette,
        frames=data.frame_rows,
        sequences=data.sequence_rows,
        deciding_frames=deciding,
        first_screen=parts.first_screen,
        identical=parts.identical,
    )


def results_json(report: ReportModel) -> dict:
    """The machine-readable part of the report (no images)."""
    return _clean(
        {
            "run": report.run,
            "denoisers": report.denoisers,
            "scenes": report.scenes,
            "scene_effects": report.scene_effects,
            "spp": report.spp,
            "reference": report.reference,
            "summary": [
                {
                    "denoiser": r.denoiser,
                    "spp": r.spp,
                    "frames": r.frames,
                    "failed_units": r.failed_units,
                    "errors": r.errors,
                    "denoise_seconds_per_frame": r.denoise_seconds,
                    "total_seconds_per_frame": r.total_seconds,
                    "render_seconds_per_frame": r.render_seconds,
                    "metrics": {
                        m: {
                            "mean": c.value,
                            "ci95": [c.low, c.high],
                            "scenes": c.scenes,
                            "aggregate": c.rule,
                            **(
                                {
                                    "corrected": True,
                                    "raw": c.raw,
                                    "raw_ci95": [c.raw_low, c.raw_high],
                                    "floor": c.floor,
                                    "floor_closed_form": c.floor_closed_form,
                                    "floor_measured": c.floor_measured,
                                    "measured_floor_leads": c.measured_floor_leads,
                                    "at_resolution": c.at_resolution,
                                }
                                if c.floor is not None
                                else {"corrected": False}
                            ),
                            **_beside(c),
                        }
                        for m, c in r.metrics.items()
                    },
                }
                for r in report.summary
            ],
            "accuracy_time": [
                {
                    "metric": p.metric,
                    "points": [vars(q) for q in p.points],
                    "hidden": p.hidden,
                    "noisy_fit": vars(p.fit) if p.fit else None,
                    "reference_seconds": p.reference_seconds,
                    "reference_spp": p.reference_spp,
                    "time_axis": p.time_label,
                }
                for p in report.accuracy
            ],
            "readings": report.readings,
            "time_model": report.time_model.as_dict(),
            "equal_tables": [equal_tables.as_dict(t) for t in report.equal_tables],
            "effects": report.effects,
            "flicker": report.flicker,
            "not_distinguishable": [vars(p) for p in report.indistinguishable],
            "failures": report.failures,
            "unresolved_references": report.unresolved_references,
            "not_applicable": report.not_applicable,
            **({"samplers": report_samplers.as_json(report.samplers)} if report.samplers else {}),
            **({"cvvdp_viewing": report.cvvdp_viewing} if report.cvvdp_viewing else {}),
            "stability": report.stability,
            "deciding_frames": report.deciding_frames,
            "frames": report.frames,
            "sequence_metrics": report.sequences,
        }
    )


def _beside(c) -> dict:
    """A metric cell's numbers beside the one that leads (:class:`denoisebench.analysis.summary.Cell`):
    the arithmetic mean over scenes in the score's units, the scenes carrying more than half of it, and
    for a lead score the aggregate under the metric's own rule, the anchor and the drop-one factor."""
    out = {
        "arithmetic_mean": c.arithmetic,
        "arithmetic_ci95": [c.arithmetic_low, c.arithmetic_high],
        "deciding_scenes": [{"scene": scene, "share": share} for scene, share in c.deciding_scenes],
    }
    if c.by_rule_name is not None:
        out["relative_to"] = {"label": NOISY, "spp": c.anchor_spp}
        out["by_rule"] = {"aggregate": c.by_rule_name, "mean": c.by_rule}
        out["drop_one_scene_factor"] = c.drop_one
    return out


#: First characters that make a spreadsheet read a cell as a formula (or that it strips first).
_FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value):
    """``value`` safe for a spreadsheet: a text cell starting with = + - @ tab or CR gets a leading
    single quote (OWASP's advice against formula injection, e.g. through a plugin's name).

    Numbers are written by the caller as numbers (a negative metric stays a number); only text
    (names, errors) passes through here."""
    if isinstance(value, str) and value.startswith(_FORMULA_STARTS):
        return "'" + value
    return value


def results_csv(report: ReportModel) -> str:
    """One row per frame: ids, status, seconds, then every frame metric, the floor and corrected value
    (``<metric>_floor``, ``<metric>_corrected``) of those that have a floor, and the per-frame flicker."""
    flicker = sorted({m for f in report.frames for m in f.metrics if m.startswith("flicker")})
    floored = [m for m in report.frame_metrics if any(m in f.floors for f in report.frames)]
    metrics = report.frame_metrics + flicker
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(
        [
            "run_id",
            "denoiser",
            "scene",
            "spp",
            "frame",
            "status",
            "error",
            "render_seconds",
            "denoise_seconds",
            "total_seconds",
            "sanitized",
            *metrics,
            *(f"{m}_{part}" for m in floored for part in ("floor", "corrected")),
        ]
    )
    for f in report.frames:
        values = [f.metrics.get(m) for m in metrics]
        for m in floored:
            value, floor = f.metrics.get(m), f.floors.get(m)
            values += [floor, None if value is None or floor is None else value - floor]
        writer.writerow(
            [
                report.run.run_id,
                csv_cell(f.denoiser),
                csv_cell(f.scene),
                f.spp,
                f.frame,
                f.status,
                csv_cell(f.error or ""),
                f.render_seconds,
                f.denoise_seconds,
                f.total_seconds,
                f.sanitized,
                *("" if v is None else repr(float(v)) for v in values),
            ]
        )
    return buffer.getvalue()


def spp_map_files(report: ReportModel) -> dict[str, bytes]:
    """report.md's spp map images: ``figures/spp_maps/<comparison>_<entry>.png`` (numbers, not user-given
    names), the sampler's image beside it (``..._image.png``) and the colour bar
    ``figures/spp_maps/colour_bar.png``; {} without maps."""
    files = {}
    for n, comp in enumerate(report.comparisons):
        for k, entry in enumerate(comp.entries):
            if entry.spp_map is not None:
                files[f"figures/spp_maps/{n}_{k}.png"] = entry.spp_map.png
                files[f"figures/spp_maps/{n}_{k}_image.png"] = base64.b64decode(entry.image.split(",", 1)[1])
    if files:
        files["figures/spp_maps/colour_bar.png"] = images.colour_bar_png()
    return files


def write_report(
    store: ResultsStore,
    run_id: str,
    dataset: Dataset,
    out_dir: str | Path,
    stability: dict[str, list[dict]] | None = None,
    time_at: tuple[int, int] | None = None,
    include_unresolved: bool = False,
) -> Path:
    """Write the report folder; return the path of index.html (``time_at``: see :func:`build_report`)."""
    out = Path(out_dir)
    report = build_report(
        store, run_id, dataset, stability=stability, time_at=time_at, include_unresolved=include_unresolved
    )
    for name, (png, svg) in report.figures.items():
        atomic_write_bytes(out / "figures" / f"{name}.png", png)
        atomic_write_bytes(out / "figures" / f"{name}.svg", svg.encode("utf-8"))
    for path, png in spp_map_files(report).items():
        atomic_write_bytes(out / path, png)
    atomic_write_bytes(
        out / "results.json", (json.dumps(results_json(report), indent=1, allow_nan=False) + "\n").encode("utf-8")
    )
    atomic_write_bytes(out / "results.csv", results_csv(report).encode("utf-8"))
    atomic_write_bytes(out / "report.md", render_markdown(report).encode("utf-8"))
    return atomic_write_bytes(out / "index.html", render_html(report).encode("utf-8"))
