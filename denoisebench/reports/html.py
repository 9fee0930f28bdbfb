"""index.html: one self-contained page (inline style and script, images as data URIs, no network).

Notes
-----
* **Escaping.** Every name and message comes from user input (a plugin names itself); all text goes
  through :func:`html.escape` with ``quote=True`` and is placed only in element text or quoted
  attributes, never inside ``<script>``. The script reads what it needs from the DOM.
* **Compare control.** Per scene: a select for the image on the left of the wipe (the noisy input
  or a denoiser), the reference on the right, a range slider moving the wipe (``clip-path``), and a
  button that flips between the whole left image and the whole reference. Plain JS, no library.
* Images are upscaled by the browser with ``image-rendering: pixelated`` on top of the integer
  upscale done when encoding, so pixels stay sharp.
"""

from __future__ import annotations

from html import escape
from typing import TYPE_CHECKING

from denoisebench.plugins.proxy import isolation_text
from denoisebench.reports import formatting as fmt
from denoisebench.reports import notes, summary_screen, wide_tables
from denoisebench.reports.images import colour_bar_png, data_uri
from denoisebench.reports.samplers import undersampled_lines

if TYPE_CHECKING:
    from denoisebench.reports.model import ComparisonEntry, ReportModel, SppMap

STYLE = """
body{font:14px/1.45 system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0;color:#1d1d1f;background:#fafafa}
main{max-width:1320px;margin:0 auto;padding:18px 28px 60px}
h1{font-size:24px;margin:8px 0 4px}h2{font-size:19px;margin:34px 0 8px;border-bottom:1px solid #ddd;padding-bottom:4px}
h3{font-size:15px;margin:18px 0 6px}
.meta{color:#555;font-size:13px}
nav a{margin-right:14px;color:#0a58ca;text-decoration:none;font-size:13px}
table{border-collapse:collapse;font-size:12.5px;margin:6px 0 14px;background:#fff}
th,td{border:1px solid #ddd;padding:3px 7px;text-align:right;white-space:nowrap}
th{background:#f0f0f3}td:first-child,th:first-child{text-align:left}
tr.input td{background:#f6f6f6;color:#444}
td.worst{background:#ffe3e0;font-weight:600}
.readings li{margin:3px 0}
.figure img{max-width:100%;border:1px solid #e4e4e4;background:#fff}
.gallery{display:flex;flex-wrap:wrap;gap:10px;margin:8px 0}
.tile{background:#fff;border:1px solid #e4e4e4;padding:5px;text-align:center;font-size:12px}
.tile img{display:block;image-rendering:pixelated}
.tile .crops{display:flex;gap:3px;justify-content:center;margin-top:3px}
.tile.reference{border-color:#2a9d8f}.tile.input{border-color:#999}
.compare{background:#fff;border:1px solid #e4e4e4;padding:8px;display:inline-block;margin:6px 0}
.cmp-stage{position:relative;overflow:hidden;cursor:col-resize;user-select:none}
.cmp-stage img{position:absolute;left:0;top:0;width:100%;height:100%;image-rendering:pixelated}
.cmp-line{position:absolute;top:0;bottom:0;width:2px;background:#ffcc00;pointer-events:none}
.cmp-caption{display:flex;justify-content:space-between;font-size:12px;color:#444;margin-top:3px}
.cmp-controls{margin-top:6px;display:flex;gap:10px;align-items:center;font-size:12px}
.cmp-slider{width:220px}
.error{color:#b00020}
.scroll{overflow-x:auto;max-width:100%}
.note{color:#555;font-size:12.5px}
.tile.sppmap{border-color:#440154}.bar{display:flex;gap:4px;align-items:center;justify-content:center;margin-top:3px}
.bar img{width:96px;height:8px}
details{margin:2px 0 14px}details summary{cursor:pointer;color:#0a58ca;font-size:12.5px}
table.screen td{white-space:normal}table.screen td:first-child{font-weight:600}
"""

SCRIPT = """
(function () {
  function setup(box) {
    var stage = box.querySelector('.cmp-stage');
    var top = box.querySelector('.cmp-top');
    var line = box.querySelector('.cmp-line');
    var slider = box.querySelector('.cmp-slider');
    var select = box.querySelector('.cmp-left');
    var toggle = box.querySelector('.cmp-toggle');
    var leftName = box.querySelector('.cmp-left-name');
    function wipe(percent) {
      percent = Math.max(0, Math.min(100, Number(percent)));
      top.style.clipPath = 'inset(0 ' + (100 - percent) + '% 0 0)';
      line.style.left = 'calc(' + percent + '% - 1px)';
      slider.value = String(percent);
      box.dataset.wipe = String(percent);
    }
    function choose() {
      var source = document.getElementById(select.value);
      if (source) { top.src = source.src; }
      leftName.textContent = select.options[select.selectedIndex].text;
      box.dataset.left = select.value;
    }
    slider.addEventListener('input', function () { wipe(slider.value); });
    select.addEventListener('change', choose);
    toggle.addEventListener('click', function () { wipe(Number(slider.value) >= 100 ? 0 : 100); });
    stage.addEventListener('pointerdown', function (event) {
      var rect = stage.getBoundingClientRect();
      wipe(100 * (event.clientX - rect.left) / rect.width);
    });
    stage.addEventListener('pointermove', function (event) {
      if (event.buttons !== 1) { return; }
      var rect = stage.getBoundingClientRect();
      wipe(100 * (event.clientX - rect.left) / rect.width);
    });
    choose();
    wipe(50);
  }
  document.querySelectorAll('.compare').forEach(setup);
})();
"""


def e(text) -> str:
    return escape(str(text), quote=True)


def _table(header: list[str], rows: list[list[str]], row_classes: list[str] | None = None, cell_classes=None) -> str:
    head = "".join(f"<th>{e(h)}</th>" for h in header)
    body = []
    for i, row in enumerate(rows):
        cls = f' class="{e(row_classes[i])}"' if row_classes and row_classes[i] else ""
        cells = "".join(
            f"<td{' class=' + chr(34) + e(cell_classes(i, j)) + chr(34) if cell_classes and cell_classes(i, j) else ''}>{e(c)}</td>"
            for j, c in enumerate(row)
        )
        body.append(f"<tr{cls}>{cells}</tr>")
    return f'<div class="scroll"><table><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table></div>'


#: The summary and flicker tables' lead columns (the rest collapse under "all columns").
SHORT_METRICS = ("relmse_robust", "relmse", "flip", "ssim", "temporal_relmse_robust", "cvvdp", "tpsnr")
SHORT_EXTRA = ("total s/frame",)


def _wide(header, rows, row_classes=None) -> str:
    """A table that collapses when wide: its lead columns, then the whole table in ``<details>``."""
    if not wide_tables.is_wide(header):
        return _table(header, rows, row_classes)
    short = _table(*wide_tables.lead_view(header, rows, metrics=SHORT_METRICS, extra=SHORT_EXTRA), row_classes)
    return (
        short
        + f"<details><summary>all {len(header)} columns (raw scores, floors, every metric)</summary>"
        + _table(header, rows, row_classes)
        + "</details>"
    )


def _summary(report: ReportModel) -> str:
    """The first screen: one row per denoiser (:mod:`.summary_screen`), then how to read it."""
    screen = report.first_screen
    if screen is None:
        return '<p class="note">No accuracy-against-time panel of the lead metric: no summary.</p>'
    header, rows = summary_screen.screen_rows(screen)
    head = "".join(f"<th>{e(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in rows)
    lines = "".join(f"<li>{e(line)}</li>" for line in summary_screen.screen_lines(screen))
    return (
        f'<div class="scroll"><table class="screen"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>'
        f'<ul class="readings">{lines}</ul>'
    )


def _figure(report: ReportModel, name: str, alt: str) -> str:

    if name not in report.figures:
        return ""
    png, _ = report.figures[name]
    return f'<div class="figure"><img alt="{e(alt)}" src="{data_uri(png)}"></div>'


def _accuracy(report: ReportModel) -> str:
    parts = [
        _figure(report, "accuracy_time", "error against seconds per frame"),
        '<p class="note">Each point is a denoiser at one input spp: mean error over the test frames against total '
        "seconds per frame (render at that spp + denoise, at the resolution stated under Times), log axes; along a "
        "denoiser's curve its spp rise left to right, and the curve is named at the right. The grey curve, drawn on "
        "top, is the noisy input at rising spp (its spp beside each point), the \u201cjust render more samples\u201d "
        "line; its dashed stub is extrapolated. The axes span the measured points: the reference's render time "
        "(its error against itself is zero, which a log axis cannot show) is a dotted line, or is written at the "
        "edge when it lies beyond them. Circled points are on the Pareto front.</p>",
    ]
    for metric, sentences in report.readings.items():
        items = "".join(f"<li>{e(s)}</li>" for s in sentences)
        parts.append(
            f"<details><summary>{e(metric)}: {len(sentences)} reading(s) in words</summary>"
            f'<ul class="readings">{items}</ul></details>'
        )
    hidden = [h for p in report.accuracy for h in p.hidden]
    if hidden:
        parts.append("<p class=\"note\">Not drawn: " + e("; ".join(hidden)) + "</p>")
    if report.time_model is not None:
        notes = "".join(f"<li>{e(n)}</li>" for n in [*report.time_model.notes, report.time_model.measurement_text()])
        parts.append(
            f'<h3>Times</h3><p class="note">{e(fmt.time_axis_text(report))} {e(fmt.machine_text(report))}</p>'
            + (f'<ul class="readings">{notes}</ul>' if notes else "")
            + _table(*fmt.time_model_rows(report))
        )
    return "".join(parts)


def _equal_quality(table) -> str:
    """The equal-quality table: the measured targets' columns, the extrapolated ones one click away."""
    header, rows = fmt.equal_quality_rows(table)
    measured = [i for i, h in enumerate(header) if "(extrapolated)" not in h]
    if len(measured) == len(header):
        return _table(header, rows)
    extra = [0] + [i for i in range(1, len(header)) if i not in measured]
    return (
        _table(*wide_tables.pick(header, rows, measured))
        + f"<details><summary>{len(extra) - 1} target(s) beyond the measured rungs (extrapolated)</summary>"
        + _table(*wide_tables.pick(header, rows, extra))
        + "</details>"
    )


def _equal_tables(report: ReportModel) -> str:
    """Equal-time and equal-quality tables per lead metric, then the verdicts (measured rungs only)."""
    parts = [
        '<p class="note"><em>Equal time</em>: for each budget (the seconds rendering s spp takes), the (denoiser, '
        "spp) of lowest error whose render + denoise seconds fit it, against rendering alone. <em>Equal quality</em>: "
        "for each error target (rendering alone at each measured rung, then beyond it), the seconds each denoiser "
        "needs. Between measured rungs figures are interpolated on log-log axes; outside them they are marked "
        "extrapolated and make no verdict; \u2264: met at the lowest measured spp already. "
        + e(fmt.time_axis_text(report))
        + "</p>"
    ]
    for table in report.equal_tables:
        if not table.equal_time and not table.equal_quality:
            parts.append(f'<p class="note">{e(fmt.empty_table_text(table))}</p>')
            continue
        parts.append(f"<h3>Equal time: {e(table.metric)}</h3>" + _table(*fmt.equal_time_rows(table)))
        parts.append(f"<h3>Equal quality: {e(table.metric)}</h3>" + _equal_quality(table))
    if report.verdicts:
        items = "".join(f"<li>{e(v)}</li>" for v in report.verdicts)
        parts.append(
            f"<h3>Verdicts (measured rungs only)</h3><details><summary>{len(report.verdicts)} verdict sentence(s) "
            f'(the Summary holds each denoiser\'s)</summary><ul class="readings">{items}</ul></details>'
        )
    return "".join(parts)


def _results(report: ReportModel) -> str:
    parts = [
        '<p class="note">Scores combined over scenes by each metric\'s rule: scale-free scores by their mean; '
        "linear-radiance ones (marked) by the geometric mean, or per scene relative to the noisy input (\u00d7 input: "
        "the geometric-mean share of the input's score left), so that no single bright scene decides. A bootstrap "
        "95&nbsp;% interval over scenes, which includes the reference's own uncertainty, is in brackets when there "
        "are at least two scenes; \u2193 lower is better, \u2191 higher is better. Seconds are per frame. "
        "<b>floor</b>: what the reference's own noise adds to a score; <b>corrected</b>: the score less its "
        "floor (against the noise-free image); <b>raw</b>: as measured against the reference.</p>",
        f'<p class="note">{e(notes.correction_text(report))}</p>',
    ]
    parts += [f'<p class="error">Not held-out: {e(line)}</p>' for line in fmt.not_held_out_lines(report)]
    parts += [
        f'<p class="error">Pixels without a sample: {e(line)}</p>' for line in undersampled_lines(report.samplers)
    ]
    if "scenes" in report.figures:
        parts.append(
            "<h3>Where each denoiser wins, per scene</h3>"
            + _figure(report, "scenes", "where each denoiser wins: lead score relative to the noisy input, per scene")
            + '<p class="note">Each cell: the denoiser\'s lead score on that scene at that spp over the noisy '
            "input's there (below 1: better than the input); framed and bold: the scene's lowest at that spp.</p>"
        )
    for spp in report.spp:
        header, rows = fmt.summary_rows(report, spp)
        classes = ["input" if r[0] == "noisy" else "" for r in rows]
        parts.append(f"<h3>{spp} spp</h3>" + _wide(header, rows, classes))
    lines = fmt.indistinguishable_lines(report)
    if lines:
        parts.append(
            "<h3>Not distinguishable at this reference quality</h3><ul class=\"readings\">"
            + "".join(f"<li>{e(line)}</li>" for line in lines)
            + "</ul>"
        )
    deciding = notes.deciding_frame_lines(report)
    if deciding:
        parts.append(
            "<h3>Frames that would decide a mean</h3><p class=\"note\">A scene's score is the trimmed mean of its "
            "frames (one frame in eight dropped at each end; for flicker, of its frame pairs, two in seven), so these "
            "frames (for flicker: the later frame of the pair), far above the rest of their scene, do not decide it.</p><ul class=\"readings\">"
            + "".join(f"<li>{e(x)}</li>" for x in deciding)
            + "</ul>"
        )
    unresolved = notes.unresolved_text(report)
    if unresolved:
        parts.append(
            f'<h3>References that cannot resolve a score</h3><p class="note">{e(unresolved)}</p><ul class="readings">'
            + "".join(f"<li>{e(line)}</li>" for line in notes.unresolved_lines(report))
            + "</ul>"
        )
    missing = notes.not_applicable_lines(report)
    if missing:
        parts.append(
            '<h3>Metrics that did not apply</h3><p class="note">These metrics have no value where their '
            "preconditions fail; the frames keep their other scores.</p><ul class=\"readings\">"
            + "".join(f"<li>{e(line)}</li>" for line in missing)
            + "</ul>"
        )
    return "".join(parts)


def _effects(report: ReportModel) -> str:
    notes = "".join(f"<li>{e(n)}</li>" for n in report.effects.notes)
    notes = f'<ul class="readings">{notes}</ul>' if notes else ""
    if not report.effects.effects:
        return notes or '<p class="note">The scenes declare no effects.</p>'
    header, rows, worst = fmt.effect_rows(report)
    names = ["overall", *report.effects.effects]
    labels = [r[0] for r in rows]

    def worst_cell(i, j):
        return "worst" if j >= 2 and worst.get(labels[i]) == names[j - 1] else ""

    note = (
        f'<p class="note">Share of the noisy input\'s {e(report.effects.metric)} left after denoising: geometric mean '
        "over the scenes that exercise each effect and over spp (lower is better). Highlighted: the effect that costs "
        "each denoiser most.</p>"
    )
    return note + _table(header, rows, cell_classes=worst_cell) + notes


def _strip_section(report: ReportModel) -> str:
    if not report.strips:
        return ""
    parts = [
        '<h3>Frame strips</h3><p class="note">One crop (where the noisy input flickers most, among windows at '
        "least half visible in the reference) of the first frames of each sequence at the lowest input spp, frames "
        "left to right, and the same frames looping in place; "
        "tone-mapped like the metrics. Flicker is a change from frame to frame that the reference's row does not "
        "have.</p>"
    ]
    for strip in report.strips:
        w = strip.window
        parts.append(
            f"<h3>{e(strip.scene)} \u2014 frames {strip.first_frame}\u2013{strip.first_frame + strip.frames - 1}, "
            f"{strip.spp} spp, crop at ({w.left}, {w.top}), {w.side} px</h3>"
        )
        if not strip.visible:
            parts.append(
                '<p class="note">This window shows almost nothing of the reference (under half of its pixels '
                "are visible after the tone map): the run chose it by an older rule, where the input flickers "
                "most; a new run chooses the worst window a reader can see into.</p>"
            )
        rows = "".join(
            f'<div class="tile {e(entry.kind)}" style="display:flex;gap:8px;align-items:center;text-align:left">'
            f'<img alt="animated crop of {e(entry.label)}" src="{entry.animation}">'
            f'<img alt="frames of {e(entry.label)}" src="{entry.strip}"><div>{e(entry.label)}</div></div>'
            for entry in strip.entries
        )
        parts.append(f'<div style="display:flex;flex-direction:column;gap:4px">{rows}</div>')
    return "".join(parts)


def _flicker(report: ReportModel) -> str:
    if not report.flicker.series:
        return '<p class="note">Sequences of one frame: no flicker to measure.</p>' + _strip_section(report)
    parts = [
        _figure(report, "flicker", "flicker per frame, one panel per input spp"),
        '<p class="note">Temporal relMSE: the squared difference of the warped frame differences (motion '
        "buffer, disocclusions masked) over the reference's local magnitude squared plus 0.01, scale-free like "
        "relMSE; cvvdp: ColorVideoVDP's prediction, in JOD (10 = no visible difference), of how visible the "
        "differences and flicker are on a 4K HDR monitor at 30 fps, the reference's typical surface shown at "
        "100 cd/m²; tPSNR: PSNR of the tone-mapped frame differences. These lead; other temporal metrics follow, and "
        "the linear temporal_l1 scores, kept as diagnostics, are shown relative to the noisy input.</p>",
    ]
    for spp in report.spp:
        header, rows = fmt.flicker_rows(report, spp)
        classes = ["input" if r[0] == "noisy" else "" for r in rows]
        parts.append(f"<h3>{spp} spp</h3>" + _wide(header, rows, classes))
    return "".join(parts) + _viewing(report) + _strip_section(report)


def _viewing(report: ReportModel) -> str:
    """cvvdp's display, pixels per degree and each scene's exposure (when cvvdp was measured)."""
    if not report.cvvdp_viewing:
        return ""
    return f'<h3>cvvdp viewing conditions</h3><p class="note">{e(notes.viewing_text(report))}</p>' + _table(
        *notes.viewing_rows(report)
    )


def _tile(entry: ComparisonEntry, element_id: str) -> str:
    crops = "".join(f'<img alt="crop of {e(entry.label)}" src="{c}">' for c in entry.crops)
    caption = e(entry.label) + (f"<br>relMSE {fmt.num(entry.relmse)}" if entry.relmse is not None else "<br>&nbsp;")
    return (
        f'<div class="tile {e(entry.kind)}"><img id="{element_id}" alt="{e(entry.label)}" src="{entry.image}">'
        f'<div class="crops">{crops}</div><div>{caption}</div></div>'
    )


def _spp_tile(entry: ComparisonEntry, m: SppMap) -> str:
    """The spp map ``m`` of a sampler's entry, beside its image: the map, its numbers and the colour bar."""
    return (
        f'<div class="tile sppmap"><img alt="spp map of {e(entry.label)}" src="{m.image}">'
        f'<div class="bar"><span>0</span><img alt="colour bar" src="{data_uri(colour_bar_png())}">'
        f"<span>{m.top} spp</span></div>"
        f"<div>{e(entry.label)}: spp map<br>mean {m.mean:.3g}, {m.min}\u2013{m.max} spp"
        + (f', <span class="error">{m.pixels_without_samples} px &lt; 1 spp</span>' if m.pixels_without_samples else "")
        + "</div></div>"
    )


def _samplers(report: ReportModel) -> str:
    """The live samplers: unsampled-pixel warnings, how to read the maps, and their counts."""
    section = report.samplers
    if not section:
        return ""
    parts = [f'<p class="error">Pixels without a sample: {e(line)}</p>' for line in undersampled_lines(section)]
    parts.append(f'<p class="note">{e(notes.sampler_scale_text())} The maps are under Image comparisons.</p>')
    return "".join(parts) + _table(*notes.sampler_rows(report))


def _comparisons(report: ReportModel) -> str:
    parts = [
        '<p class="note">The last frame of each test sequence at each input spp (temporal denoisers have seen '
        "the frames before it), then each frame that would decide its scene's mean of a lead score (the trimmed mean "
        "leaves it out; the reason is under its heading), tone-mapped like the metrics. Below each image: zoomed crops "
        "of the regions where the "
        "denoisers' mean relMSE is worst. In the compare box, pick the left image, drag the wipe or the slider, or press "
        "the button to flip between the left image and the reference.</p>"
    ]
    for n, comp in enumerate(report.comparisons):
        ids = [f"img-{n}-{i}" for i in range(len(comp.entries))]
        tiles = "".join(
            _tile(entry, ids[i]) + (_spp_tile(entry, entry.spp_map) if entry.spp_map is not None else "")
            for i, entry in enumerate(comp.entries)
        )
        choices = [(ids[i], entry) for i, entry in enumerate(comp.entries) if entry.kind != "reference"]
        ref_id = ids[-1]
        # open on the denoiser closest to the reference in this frame
        scored = [
            (entry.relmse, k)
            for k, (_, entry) in enumerate(choices)
            if entry.kind == "denoiser" and entry.relmse is not None
        ]
        default = min(scored)[1] if scored else 0
        options = "".join(
            f'<option value="{i}"{" selected" if k == default else ""}>{e(entry.label)}</option>'
            for k, (i, entry) in enumerate(choices)
        )
        w, h = comp.width, comp.height
        ref_src = comp.entries[-1].image
        parts.append(
            f"<h3>{e(comp.scene)} \u2014 frame {comp.frame}, {comp.spp} spp</h3>"
            + (f'<p class="note">Decides a mean: {e(comp.why)}.</p>' if comp.why else "")
            + f'<div class="compare" data-reference="{ref_id}">'
            f'<div class="cmp-stage" style="width:{2 * w}px;height:{2 * h}px">'
            f'<img class="cmp-base" alt="reference" src="{ref_src}"><img class="cmp-top" alt="left image" src="{ref_src}">'
            '<div class="cmp-line"></div></div>'
            '<div class="cmp-caption"><span class="cmp-left-name"></span><span>reference</span></div>'
            f'<div class="cmp-controls"><label>left: <select class="cmp-left">{options}</select></label>'
            '<input class="cmp-slider" type="range" min="0" max="100" value="50" aria-label="wipe position">'
            '<button class="cmp-toggle" type="button">flip left / reference</button></div></div>'
            f'<div class="gallery">{tiles}</div>'
        )
    if not report.comparisons:
        parts.append('<p class="note">No denoised images were stored for this run.</p>')
    return "".join(parts)


def _stability(report: ReportModel) -> str:
    table = report.stability
    if table is None:
        return (
            '<p class="note">The hard-case suite (<code>denoisebench.denoisers.hard_cases</code>) is not available in '
            "this installation; this table appears when it is.</p>"
        )
    return _table(*fmt.stability_rows(table))


def _failures(report: ReportModel) -> str:
    parts = []
    if report.failures:
        parts.append(
            _table(
                ["denoiser", "scene", "spp", "error"],
                [[f.denoiser, f.scene, str(f.spp), f.error or ""] for f in report.failures],
            )
        )
    for d in report.denoisers:
        if d.load_error:
            parts.append(f'<p class="error">{e(d.spec)} was not run: {e(d.load_error)}</p>')
    return "".join(parts) or '<p class="note">Every denoiser ran on every sequence.</p>'


def render_html(report: ReportModel) -> str:
    run = report.run
    meta = (
        f"run {e(run.run_id)} \u00b7 dataset {e(run.dataset_hash[:12])} ({e(run.dataset_path)}) \u00b7 split "
        f"{e(run.config.get('split'))} \u00b7 {len(report.scenes)} scene(s) \u00b7 input spp "
        f"{e(', '.join(map(str, report.spp)))} \u00b7 reference {e(report.reference.description)} \u00b7 started "
        f"{e(run.created_at)}, finished {e(run.finished_at or 'not yet (partial results)')}"
        f" \u00b7 {e(isolation_text(run.config, run.versions))}"
    )
    versions = ", ".join(f"{k} {v}" for k, v in sorted(run.versions.items()))
    sections = [
        ("summary", "Summary", _summary(report)),
        ("accuracy", "Accuracy against time", _accuracy(report)),
        ("equal", "Equal time and equal quality", _equal_tables(report)),
        ("results", "Results", _results(report)),
        ("effects", "Per-effect breakdown", _effects(report)),
        ("flicker", "Temporal flicker", _flicker(report)),
        ("images", "Image comparisons", _comparisons(report)),
        *([("samplers", "Samplers", _samplers(report))] if report.samplers else []),
        ("stability", "Hard-case stability", _stability(report)),
        ("failures", "Failures", _failures(report)),
    ]
    nav = "".join(f'<a href="#{key}">{e(title)}</a>' for key, title, _ in sections)
    body = "".join(f'<section id="{key}"><h2>{e(title)}</h2>{content}</section>' for key, title, content in sections)
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>denoisebench report {e(run.run_id)}</title><style>{STYLE}</style></head>"
        f"<body><main><h1>denoisebench report</h1><p class=\"meta\">{meta}</p><nav>{nav}</nav>{body}"
        f"<p class=\"meta\">software: {e(versions)}</p></main><script>{SCRIPT}</script></body></html>\n"
    )
