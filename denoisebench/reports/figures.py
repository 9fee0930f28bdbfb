"""Report figures with matplotlib (Agg backend): flicker per frame (accuracy against time:
:mod:`.figures_accuracy`; where each denoiser wins per scene: :mod:`.figures_scenes`).

Each figure is returned as (PNG bytes, SVG text): the HTML embeds the PNG as a data URI (so the
page works offline and loads fast), the SVG goes to ``figures/`` for papers.

Notes
-----
* matplotlib is imported inside the functions and the Agg backend forced, so that no display is
  needed and importing this module stays cheap.
* Log axes: points with zero error cannot be placed; the analysis leaves them out and lists them.
* Colours and markers come from :func:`.figures_accuracy.colors` and :func:`.figures_accuracy.marker_of`
  (keyed by the denoiser's position in the run), so a denoiser keeps them across the report's figures;
  the noisy input is drawn on top.
"""

from __future__ import annotations

from denoisebench.reports.figures_accuracy import marker_of, pyplot, save
from denoisebench.results.names import NOISY

# Lazy imports: matplotlib only where a figure is drawn (figures_accuracy.pyplot), so that a run
# without a report never loads it.


#: Axis labels of the per-frame flicker metrics.
FLICKER_LABELS = {
    "temporal_relmse": "temporal relMSE (lower is better)",
    "tpsnr": "tPSNR dB (higher is better)",
    "temporal_l1": "temporal_l1, linear (lower is better)",
}


#: Panels per row of the flicker figure (more spp wrap onto further rows, so panels stay readable).
FLICKER_COLUMNS = 3


def flicker_figure(
    series: dict[str, dict[int, dict[str, list[float | None]]]], palette: dict[str, str]
) -> tuple[bytes, str]:
    """Per-frame flicker (frame t against t−1, mean over scenes): one panel per metric and input spp,
    at most :data:`FLICKER_COLUMNS` spp per row (``series``: {metric: {spp: {denoiser: values of
    frames 1, 2, ...}}}); each metric starts a new row, its name on the y axis of the row's first panel."""
    plt = pyplot()
    metrics = list(series)
    spps = sorted({spp for by_spp in series.values() for spp in by_spp})
    columns = min(FLICKER_COLUMNS, len(spps))
    per_metric = -(-len(spps) // columns)
    fig, axes = plt.subplots(
        len(metrics) * per_metric, columns, figsize=(4.6 * columns, 3.0 * len(metrics) * per_metric), squeeze=False
    )
    for ax in axes.flat:
        ax.set_visible(False)
    for m, metric in enumerate(metrics):
        for j, spp in enumerate(spps):
            ax = axes[m * per_metric + j // columns][j % columns]
            ax.set_visible(True)
            lines = series[metric].get(spp, {})
            for label, values in lines.items():
                xs = [i + 1 for i, v in enumerate(values) if v is not None]
                ys = [v for v in values if v is not None]
                ax.plot(
                    xs,
                    ys,
                    "-",
                    marker=marker_of(label, palette),
                    ms=3,
                    color=palette.get(label),
                    lw=2 if label == NOISY else 1,
                    label=label,
                    zorder=10 if label == NOISY else 2,
                )
            pairs = max((len(values) for values in lines.values()), default=1)
            ax.set_xlim(0.5, pairs + 0.5)  # frame pairs 1..n, even when there is one
            ax.set_xticks(range(1, pairs + 1))
            if metric != "tpsnr" and any(v for values in lines.values() for v in values if v):
                ax.set_yscale("log")
            ax.grid(True, alpha=0.25)
            ax.set_title(f"{metric}, {spp} spp", fontsize=9)
            ax.set_xlabel("frame (against the one before)", fontsize=8)
            if j % columns == 0:
                ax.set_ylabel(FLICKER_LABELS.get(metric, metric), fontsize=8)
    handles, labels = [], []
    for ax in axes.flat:
        for h, l in zip(*ax.get_legend_handles_labels()):
            if l not in labels:
                handles.append(h)
                labels.append(l)
    rows = len(metrics) * per_metric
    fig.suptitle("temporal flicker per frame (mean over scenes)", fontsize=10)
    fig.legend(handles, labels, loc="lower center", ncol=min(7, max(1, len(labels))), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, (0.5 + 0.2 * (len(labels) // 7)) / (3.0 * rows), 1, 1 - 0.3 / (3.0 * rows)))
    return save(fig)
