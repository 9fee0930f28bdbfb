"""Report figures with matplotlib (Agg backend): accuracy against time, flicker per frame.

Each figure is returned as (PNG bytes, SVG text): the HTML embeds the PNG as a data URI (so the
page works offline and loads fast), the SVG goes to ``figures/`` for papers.

Notes
-----
* matplotlib is imported inside the functions and the Agg backend forced, so that no display is
  needed and importing this module stays cheap.
* Log axes: points with zero error cannot be placed; the analysis leaves them out and lists them.
* Colours come from one qualitative map keyed by the denoiser's position in the run, so a denoiser
  keeps its colour across the report's figures.
"""

from __future__ import annotations

import io

import numpy as np

from denoisebench.analysis.accuracy import AccuracyTime
from denoisebench.results.names import NOISY

# Lazy imports: matplotlib only where a figure is drawn, so that a run without a report never loads it.

NOISY_COLOR = "#444444"


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def colors(labels: list[str]) -> dict[str, str]:
    plt = _plt()
    cmap = plt.get_cmap("tab10" if len(labels) <= 10 else "tab20")
    palette = {}
    for i, label in enumerate(l for l in labels if l != NOISY):
        r, g, b, _ = cmap(i % cmap.N)
        palette[label] = "#%02x%02x%02x" % (int(r * 255), int(g * 255), int(b * 255))
    palette[NOISY] = NOISY_COLOR
    return palette


def _save(fig) -> tuple[bytes, str]:
    png, svg = io.BytesIO(), io.StringIO()
    fig.savefig(png, format="png", dpi=110, bbox_inches="tight")
    fig.savefig(svg, format="svg", bbox_inches="tight")
    _plt().close(fig)
    return png.getvalue(), svg.getvalue()


def _accuracy_axis(ax, at: AccuracyTime, palette: dict[str, str]) -> None:

    noisy = sorted((p for p in at.points if p.denoiser == NOISY), key=lambda p: p.spp)
    if noisy:
        ax.plot(
            [p.seconds for p in noisy],
            [p.error for p in noisy],
            "-o",
            color=NOISY_COLOR,
            lw=2,
            ms=5,
            label="noisy input (render more samples)",
            zorder=3,
        )
        for p in noisy:
            ax.annotate(
                f"{p.spp}",
                (p.seconds, p.error),
                textcoords="offset points",
                xytext=(4, 4),
                fontsize=7,
                color=NOISY_COLOR,
            )
    if at.fit is not None and noisy:
        # from the largest measured spp to the reference's (or 16× further), along the fitted time line
        spps = np.geomspace(noisy[-1].spp, max(at.reference_spp or noisy[-1].spp * 16, noisy[-1].spp * 1.01), 20)
        xs = [at.fit.seconds_at(s) for s in spps]
        ys = [at.fit.error_at(s) for s in spps]
        ax.plot(xs, ys, "--", color=NOISY_COLOR, lw=1, label="noisy, extrapolated", zorder=2)
    labels = list(dict.fromkeys(p.denoiser for p in at.points if p.denoiser != NOISY))
    for label in labels:
        mine = sorted((p for p in at.points if p.denoiser == label), key=lambda p: p.spp)
        ax.plot(
            [p.seconds for p in mine],
            [p.error for p in mine],
            "-o",
            color=palette.get(label),
            ms=5,
            lw=1,
            label=label,
            zorder=4,
        )
        for p in mine:
            ax.annotate(
                f"{p.spp}",
                (p.seconds, p.error),
                textcoords="offset points",
                xytext=(4, -9),
                fontsize=6,
                color=palette.get(label),
            )
    front = sorted((p for p in at.points if p.pareto), key=lambda p: p.seconds)
    if front:
        ax.step(
            [p.seconds for p in front],
            [p.error for p in front],
            where="post",
            color="#d62728",
            lw=0.8,
            alpha=0.6,
            zorder=1,
        )
        ax.scatter(
            [p.seconds for p in front],
            [p.error for p in front],
            s=110,
            facecolors="none",
            edgecolors="#d62728",
            lw=1.2,
            label="Pareto front",
            zorder=5,
        )
    if at.reference_seconds:
        ax.axvline(at.reference_seconds, color="#888888", ls=":", lw=1.2)
        ax.text(
            at.reference_seconds,
            0.98,
            f" reference\n {at.reference_spp} spp" + ("\n (extrapolated)" if "projected" in at.time_label else ""),
            transform=ax.get_xaxis_transform(),
            va="top",
            ha="left",
            fontsize=7,
            color="#666666",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"{at.time_label}: render at input spp + denoise")
    ax.set_ylabel(f"{at.metric} (lower is better)")
    ax.grid(True, which="both", alpha=0.25)


def accuracy_time_figure(panels: list[AccuracyTime], palette: dict[str, str]) -> tuple[bytes, str]:
    """Error against total time, one panel per metric, log–log."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 4.6), squeeze=False)
    for ax, at in zip(axes[0], panels):
        _accuracy_axis(ax, at, palette)
        ax.set_title(f"{at.metric} against time")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(
        handles,
        labels,
        loc="lower center",
        ncol=min(5, len(labels)),
        fontsize=8,
        frameon=False,
        bbox_to_anchor=(0.5, -0.02 - 0.035 * (len(labels) // 5)),
    )
    fig.tight_layout(rect=(0, 0.08 + 0.035 * (len(labels) // 5), 1, 1))
    return _save(fig)


#: Axis labels of the per-frame flicker metrics.
FLICKER_LABELS = {
    "temporal_relmse": "temporal relMSE (lower is better)",
    "tpsnr": "tPSNR dB (higher is better)",
    "temporal_l1": "temporal_l1, linear (lower is better)",
}


def flicker_figure(
    series: dict[str, dict[int, dict[str, list[float | None]]]], palette: dict[str, str]
) -> tuple[bytes, str]:
    """Per-frame flicker (frame t against t−1, mean over scenes): one column per input spp, one row
    per metric (``series``: {metric: {spp: {denoiser: values of frames 1, 2, ...}}})."""
    plt = _plt()
    metrics = list(series)
    spps = sorted({spp for by_spp in series.values() for spp in by_spp})
    fig, axes = plt.subplots(len(metrics), len(spps), figsize=(4.6 * len(spps), 3.0 * len(metrics)), squeeze=False)
    for row, metric in enumerate(metrics):
        for col, spp in enumerate(spps):
            ax = axes[row][col]
            lines = series[metric].get(spp, {})
            for label, values in lines.items():
                xs = [i + 1 for i, v in enumerate(values) if v is not None]
                ys = [v for v in values if v is not None]
                ax.plot(xs, ys, "-o", ms=3, color=palette.get(label), lw=2 if label == NOISY else 1, label=label)
            ax.xaxis.get_major_locator().set_params(integer=True)
            if metric != "tpsnr" and any(v for values in lines.values() for v in values if v):
                ax.set_yscale("log")
            ax.grid(True, alpha=0.25)
            if row == 0:
                ax.set_title(f"{spp} spp")
            if row == len(metrics) - 1:
                ax.set_xlabel("frame (against the one before)")
            if col == 0:
                ax.set_ylabel(FLICKER_LABELS.get(metric, metric), fontsize=8)
    handles, labels = [], []
    for ax in axes.flat:
        for h, l in zip(*ax.get_legend_handles_labels()):
            if l not in labels:
                handles.append(h)
                labels.append(l)
    fig.suptitle("temporal flicker per frame (mean over scenes)", fontsize=10)
    fig.legend(handles, labels, loc="lower center", ncol=min(6, max(1, len(labels))), fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0.06 + 0.03 * (len(labels) // 6), 1, 0.97))
    return _save(fig)
