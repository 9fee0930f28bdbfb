"""The accuracy-against-time figure, drawn to be read: one large panel per lead metric.

:func:`draw_accuracy` returns the matplotlib figure (tests read its axes back);
:func:`accuracy_time_figure` returns it as (PNG bytes, SVG text) like every report figure.

Rules
-----
* **Axes span the measured points.** Both log axes cover the drawn measured points (every denoiser
  and the noisy input at every rung) with :data:`MARGIN` of the span on each side (at least
  :data:`MIN_DECADES_PAD` decade). Nothing else moves them: the reference's render time, when it
  lies outside, is written at the right edge with its value instead of a line at its place; the
  noisy input's extrapolation is a short dashed stub (at most :data:`STUB_FACTOR` × the top rung's
  spp, cut at the axis' edge) marked "extrapolated".
* **The noisy input is drawn on top** of every denoiser (highest z-order, a white halo), since it
  is the line every point is read against.
* **Colours and markers.** :func:`colors` hands out :data:`DISTINCT_COLORS` (14 colours chosen far
  apart in CIELAB, none of them grey, the noisy input's colour) in the run's label order, then
  repeats them; :func:`marker_of` gives every label a marker shape as well, so that two labels
  differ in shape where colours repeat or a reader cannot tell two apart.
* **Direct labels that do not collide.** Each denoiser is named at the right of the panel, level
  with its rightmost point and joined to it by a thin line; names are pushed apart vertically
  (:func:`spread`) so that no two overlap. Points along one curve are its rungs from left to right
  (more spp takes longer); the noisy input's rungs carry their spp.

Pitfalls
--------
* A point with zero or negative error or time cannot sit on a log axis: the analysis leaves it out
  and lists it (``AccuracyTime.hidden``).
* matplotlib is imported inside the functions with the Agg backend, so that importing this module
  stays cheap and no display is needed.
"""

from __future__ import annotations

import io
import math

from denoisebench.analysis.lead import is_lead_score
from denoisebench.results.names import NOISY

NOISY_COLOR = "#444444"

#: Qualitative colours for up to 14 labels, pairwise far apart in CIELAB (tests/reports hold the
#: distance), none grey or pale on white.
DISTINCT_COLORS = (
    "#1f77b4",  # blue
    "#ff7f0e",  # orange
    "#2ca02c",  # green
    "#d62728",  # red
    "#9467bd",  # purple
    "#8c564b",  # brown
    "#e377c2",  # pink
    "#17becf",  # cyan
    "#bcbd22",  # olive yellow
    "#000075",  # navy
    "#00a087",  # teal green
    "#f032e6",  # magenta
    "#800000",  # maroon
    "#ffc000",  # amber
)

#: Marker shapes, handed out with the colours (offset so that repeated colours get new shapes).
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "p", "h", "*", "d", "8")

#: Share of each axis' log span added on both sides of the measured points.
MARGIN = 0.08
#: Least padding on each side, in decades.
MIN_DECADES_PAD = 0.08
#: The noisy input's extrapolated stub reaches at most this multiple of the top rung's spp.
STUB_FACTOR = 4.0
#: Width and height (inches) of one panel; at the PNG's 110 dpi a panel is about 1000 px wide.
PANEL_SIZE = (9.4, 5.6)


def pyplot():
    """matplotlib.pyplot on the Agg backend (imported here, on first use)."""

    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def colors(labels: list[str]) -> dict[str, str]:
    """Label → colour: :data:`DISTINCT_COLORS` in label order (the noisy input dark grey)."""
    palette = {
        label: DISTINCT_COLORS[i % len(DISTINCT_COLORS)] for i, label in enumerate(l for l in labels if l != NOISY)
    }
    palette[NOISY] = NOISY_COLOR
    return palette


def marker_of(label: str, palette: dict[str, str]) -> str:
    """A label's marker: its position among the palette's labels, offset each round of colours."""
    names = [l for l in palette if l != NOISY]
    if label == NOISY or label not in names:
        return "o"
    i = names.index(label)
    return MARKERS[(i + i // len(DISTINCT_COLORS)) % len(MARKERS)]


def log_limits(values: list[float]) -> tuple[float, float] | None:
    """(low, high) around positive ``values`` on a log axis: their span plus :data:`MARGIN` of it on
    each side, at least :data:`MIN_DECADES_PAD` decade; None without a positive finite value."""
    logs = [math.log10(v) for v in values if v is not None and math.isfinite(v) and v > 0]
    if not logs:
        return None
    low, high = min(logs), max(logs)
    pad = max(MARGIN * (high - low), MIN_DECADES_PAD)
    return 10 ** (low - pad), 10 ** (high + pad)


def spread(positions: list[float], gap: float, low: float = 0.0, high: float = 1.0) -> list[float]:
    """``positions`` (axis fractions) moved as little as needed so that neighbours are ``gap`` apart,
    kept within [low, high] where they fit; the order of the inputs is kept."""
    if not positions:
        return []
    order = sorted(range(len(positions)), key=lambda i: positions[i])
    placed = [positions[i] for i in order]
    for _ in range(len(placed) + 2):
        for k in range(1, len(placed)):  # push up
            placed[k] = max(placed[k], placed[k - 1] + gap)
        if placed[-1] > high:  # then down from the top
            placed[-1] = high
            for k in range(len(placed) - 2, -1, -1):
                placed[k] = min(placed[k], placed[k + 1] - gap)
        if placed[0] >= low - 1e-12:
            break
        placed[0] = low
    out = [0.0] * len(positions)
    for k, i in enumerate(order):
        out[i] = placed[k]
    return out


def _halo():
    from matplotlib import patheffects

    return [patheffects.withStroke(linewidth=4, foreground="white")]


def _noisy(ax, at, noisy) -> None:
    ax.plot(
        [p.seconds for p in noisy],
        [p.error for p in noisy],
        "-o",
        color=NOISY_COLOR,
        lw=2.4,
        ms=6,
        label="noisy input (render more samples)",
        zorder=20,
        path_effects=_halo(),
    )
    for p in noisy:
        ax.annotate(
            f"{p.spp} spp",
            (p.seconds, p.error),
            textcoords="offset points",
            xytext=(-6, -12),
            ha="right",
            fontsize=8,
            color=NOISY_COLOR,
            zorder=21,
        )


def _stub(ax, at, noisy, xlim) -> None:
    """The noisy fit beyond its top rung: at most STUB_FACTOR × its spp and never past the x axis."""
    if at.fit is None or not noisy:
        return
    top = noisy[-1]
    steps = [top.spp * STUB_FACTOR ** (k / 12) for k in range(13)]
    xs, ys = [], []
    for spp in steps:
        x, y = at.fit.seconds_at(spp), at.fit.error_at(spp)
        if not (math.isfinite(x) and math.isfinite(y) and x > 0 and y > 0) or x > xlim[1]:
            break
        xs.append(x)
        ys.append(y)
    if len(xs) < 2:
        return
    ax.plot(xs, ys, "--", color=NOISY_COLOR, lw=1.4, zorder=19, label="noisy, extrapolated (stub)")
    middle = len(xs) // 2
    ax.annotate(
        "extrapolated",
        (xs[middle], ys[middle]),
        textcoords="offset points",
        xytext=(0, 7),
        ha="center",
        fontsize=7,
        color=NOISY_COLOR,
        style="italic",
        zorder=21,
    )


def _reference(ax, at, xlim) -> None:
    if not at.reference_seconds:
        return
    words = f"reference, {at.reference_spp} spp" if at.reference_spp else "reference"
    if xlim[0] <= at.reference_seconds <= xlim[1]:
        ax.axvline(at.reference_seconds, color="#888888", ls=":", lw=1.2, zorder=1)
        ax.text(
            at.reference_seconds,
            0.98,
            f" {words}",
            transform=ax.get_xaxis_transform(),
            va="top",
            fontsize=7,
            color="#666666",
        )
        return
    side = "right" if at.reference_seconds > xlim[1] else "left"
    arrow = "\u2192" if side == "right" else "\u2190"
    text = f"{words}: {at.reference_seconds:.3g} s, off this axis {arrow}"
    ax.text(
        0.99 if side == "right" else 0.01,
        0.98,
        text,
        transform=ax.transAxes,
        ha=side,
        va="top",
        fontsize=7,
        color="#666666",
    )


def _labels(ax, ends: dict[str, tuple[float, float]], palette: dict[str, str]) -> None:
    """Each denoiser's name right of the axes, level with its last point, pushed apart so none overlap."""
    if not ends:
        return
    fig = ax.figure
    height_pt = ax.get_position().height * fig.get_figheight() * 72
    fontsize = 8 if len(ends) <= 10 else 7
    gap = 1.25 * fontsize / height_pt
    names = list(ends)
    to_axes = ax.transAxes.inverted()
    raw = [float(to_axes.transform(ax.transData.transform(ends[n]))[1]) for n in names]
    placed = spread(raw, gap, low=0.0, high=1.0)
    for name, y0, y in zip(names, raw, placed):
        ax.annotate(
            name,
            xy=(1.0, y0),
            xycoords="axes fraction",
            xytext=(1.03, y),
            textcoords="axes fraction",
            va="center",
            fontsize=fontsize,
            color=palette.get(name),
            arrowprops={"arrowstyle": "-", "color": palette.get(name), "lw": 0.6, "alpha": 0.7},
            annotation_clip=False,
        )


def _tick_text(value: float, every: bool) -> str:
    """``value`` as a plain number; on minor ticks only mantissas 2, 3 and 5 unless ``every``."""
    if value <= 0 or not math.isfinite(value):
        return ""
    mantissa = round(value / 10 ** math.floor(math.log10(value) + 1e-9))
    return f"{value:g}" if every or mantissa in (1, 2, 3, 5) else ""


def _plain_ticks(ax) -> None:
    """Tick labels as plain numbers (``3``, ``0.01``), not ``3×10^0``; minor ticks labelled where an
    axis spans under two decades (else it would show one or two numbers)."""
    from matplotlib.ticker import FuncFormatter

    for axis, (low, high) in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        narrow = math.log10(high / low) < 2
        short = math.log10(high / low) < 0.7
        axis.set_major_formatter(FuncFormatter(lambda v, _: _tick_text(v, True)))
        axis.set_minor_formatter(FuncFormatter(lambda v, _, n=narrow, s=short: _tick_text(v, s) if n else ""))
        axis.set_tick_params(which="minor", labelsize=7)


def _panel(ax, at, palette: dict[str, str]) -> None:
    noisy = sorted((p for p in at.points if p.denoiser == NOISY), key=lambda p: p.spp)
    xlim = log_limits([p.seconds for p in at.points])
    ylim = log_limits([p.error for p in at.points])
    ax.set_xscale("log")
    ax.set_yscale("log")
    if xlim is None or ylim is None:
        return
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    labels = list(dict.fromkeys(p.denoiser for p in at.points if p.denoiser != NOISY))
    ends = {}
    for label in labels:
        mine = sorted((p for p in at.points if p.denoiser == label), key=lambda p: p.spp)
        ax.plot(
            [p.seconds for p in mine],
            [p.error for p in mine],
            "-",
            marker=marker_of(label, palette),
            color=palette.get(label),
            ms=6,
            lw=1.1,
            alpha=0.9,
            zorder=5,
        )
        last = max(mine, key=lambda p: p.seconds)
        ends[label] = (last.seconds, last.error)
    front = sorted((p for p in at.points if p.pareto), key=lambda p: p.seconds)
    if front:
        ax.scatter(
            [p.seconds for p in front],
            [p.error for p in front],
            s=150,
            facecolors="none",
            edgecolors="#d62728",
            lw=1.0,
            alpha=0.7,
            label="Pareto front",
            zorder=6,
        )
    if noisy:
        _noisy(ax, at, noisy)
        _stub(ax, at, noisy, xlim=xlim)
    _reference(ax, at, xlim)
    ax.set_xlim(*xlim)  # plotting never widens what the measured points set
    ax.set_ylim(*ylim)
    words = at.time_label if "render" in at.time_label else f"{at.time_label}: render at input spp + denoise"
    ax.set_xlabel(words)
    _plain_ticks(ax)
    ax.set_ylabel(
        f"{at.metric}: share of the noisy input's at its lowest spp (lower is better)"
        if is_lead_score(at.metric)
        else f"{at.metric} (lower is better)"
    )
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(loc="lower left", fontsize=8, frameon=True, framealpha=0.85)
    _labels(ax, ends, palette)


def draw_accuracy(panels: list, palette: dict[str, str]):
    """The figure: one :data:`PANEL_SIZE` panel per metric of ``panels`` (AccuracyTime), stacked."""
    plt = pyplot()
    width, height = PANEL_SIZE
    fig, axes = plt.subplots(len(panels), 1, figsize=(width, height * len(panels)), squeeze=False)
    # the layout first: the names' spacing is computed from the panels' final height
    fig.subplots_adjust(
        left=0.09, right=0.8, top=1 - 0.45 / fig.get_figheight(), bottom=0.6 / fig.get_figheight(), hspace=0.28
    )
    for ax, at in zip(axes[:, 0], panels):
        _panel(ax, at, palette)
        ax.set_title(f"{at.metric} against time (points along a curve: its spp rungs, left to right)", fontsize=10)
    return fig


def save(fig) -> tuple[bytes, str]:
    """(PNG at 110 dpi, SVG) of ``fig``, then closed."""
    png, svg = io.BytesIO(), io.StringIO()
    fig.savefig(png, format="png", dpi=110, bbox_inches="tight")
    fig.savefig(svg, format="svg", bbox_inches="tight")
    pyplot().close(fig)
    return png.getvalue(), svg.getvalue()


def accuracy_time_figure(panels: list, palette: dict[str, str]) -> tuple[bytes, str]:
    """Error against total time, one large log-log panel per metric (module docstring)."""
    return save(draw_accuracy(panels, palette))
