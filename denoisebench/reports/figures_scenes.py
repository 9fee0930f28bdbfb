"""Where each denoiser wins: one small panel per scene (small multiples).

Each panel is a grid, one row per denoiser and one column per input spp; a cell is the denoiser's
lead score on that scene at that spp relative to the noisy input's there (its value written in
the cell, colour on a log scale: blue below the input, red above it), and the lowest cell of each
column, the scene's winner at that spp, is framed in black and set in bold.

Rules
-----
* **Relative to the input, per scene.** Scenes differ in brightness and difficulty by orders of
  magnitude; a ratio to the scene's own noisy input at the same spp puts them on one scale, so one
  scene cannot swamp the others' colours. The colour scale is shared by every panel and symmetric
  in log around 1, clipped at :data:`RATIO_CLIP` either way.
* **Only measured cells.** A cell without a value (failed unit, metric not applicable, or no input
  score to divide by) stays blank; a column without any value has no winner; a scene without any
  (the noisy input scores 0 there: a black frame) gets a panel that says so.
* Ties: every cell that equals the column's lowest value is framed.

:func:`scene_grid` computes what is drawn (tests read it); :func:`draw_scenes` draws it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from denoisebench.reports.figures_accuracy import pyplot, save
from denoisebench.results.names import NOISY

#: The colour scale spans ratios from 1/RATIO_CLIP to RATIO_CLIP.
RATIO_CLIP = 100.0
#: Panels per row of the figure.
PANELS_PER_ROW = 3


@dataclass(frozen=True, kw_only=True)
class SceneGrid:
    """One scene's panel: ``ratios[row][col]`` for ``labels`` × ``spp`` (None: no value), and the
    winners per column (the rows of its lowest value)."""

    scene: str
    labels: list[str]
    spp: list[int]
    ratios: list[list[float | None]]
    winners: dict[int, list[str]]


def scene_grid(scene: str, values: dict[str, dict[int, float]], spp: list[int]) -> SceneGrid:
    """The panel of ``scene`` from ``values`` {label: {spp: score}} (the noisy input's among them)."""
    noisy = values.get(NOISY, {})
    labels = [label for label in values if label != NOISY]
    ratios = []
    for label in labels:
        row = []
        for s in spp:
            mine, base = values[label].get(s), noisy.get(s)
            ok = mine is not None and base is not None and math.isfinite(mine) and math.isfinite(base) and base > 0
            row.append(mine / base if ok and mine >= 0 else None)
        ratios.append(row)
    winners = {}
    for j, s in enumerate(spp):
        column = [(r[j], label) for r, label in zip(ratios, labels) if r[j] is not None]
        if column:
            best = min(v for v, _ in column)
            winners[s] = [label for v, label in column if v == best]
    return SceneGrid(scene=scene, labels=labels, spp=list(spp), ratios=ratios, winners=winners)


def _cell_text(ratio: float) -> str:
    return f"{ratio:.2g}" if ratio < 10 else f"{ratio:.0f}"


def draw_scenes(grids: list[SceneGrid], metric: str):
    """The small-multiples figure (one panel per grid); None without a grid."""
    if not grids:
        return None
    import numpy as np
    from matplotlib.colors import LogNorm
    from matplotlib.patches import Rectangle

    plt = pyplot()
    rows_n = max(len(g.labels) for g in grids)
    cols_n = max(len(g.spp) for g in grids)
    per_row = min(PANELS_PER_ROW, len(grids))
    lines = math.ceil(len(grids) / per_row)
    panel_w, panel_h = 0.6 + 0.62 * cols_n, 0.9 + 0.27 * rows_n
    names = 0.075 * max((len(label) for g in grids for label in g.labels), default=8)  # inches of row names
    fig, axes = plt.subplots(
        lines, per_row, figsize=(names + panel_w * per_row + 1.2, panel_h * lines + 0.5), squeeze=False
    )
    fig.subplots_adjust(left=names / fig.get_figwidth(), wspace=0.08, hspace=0.35, top=1 - 0.55 / fig.get_figheight())
    norm = LogNorm(vmin=1 / RATIO_CLIP, vmax=RATIO_CLIP)
    cmap = plt.get_cmap("RdBu_r")
    image = None
    for k, ax in enumerate(axes.flat):
        if k >= len(grids):
            ax.set_visible(False)
            continue
        g = grids[k]
        if all(v is None for row in g.ratios for v in row):
            # nothing to divide by (the input scores 0 or nothing here, e.g. a black frame): say so
            ax.text(
                0.5,
                0.5,
                "no ratio: the noisy input\nscores 0 or nothing here",
                ha="center",
                va="center",
                fontsize=8,
                color="#666666",
                transform=ax.transAxes,
            )
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(g.scene, fontsize=9)
            continue
        data = np.array(
            [[np.nan if v is None else min(max(v, 1 / RATIO_CLIP), RATIO_CLIP) for v in row] for row in g.ratios]
        )
        image = ax.imshow(data, cmap=cmap, norm=norm, aspect="auto")
        for i, label in enumerate(g.labels):
            for j, s in enumerate(g.spp):
                v = g.ratios[i][j]
                if v is None:
                    continue
                win = label in g.winners.get(s, [])
                ax.text(
                    j,
                    i,
                    _cell_text(v),
                    ha="center",
                    va="center",
                    fontsize=7,
                    fontweight="bold" if win else "normal",
                    color="white" if abs(math.log10(max(v, 1e-12))) > 1.2 else "black",
                )
                if win:
                    ax.add_patch(
                        Rectangle(
                            (j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor="black", lw=1.8, gid=f"winner:{label}:{s}"
                        )
                    )
        ax.set_xticks(range(len(g.spp)), [f"{s} spp" for s in g.spp], fontsize=7)
        first = k % per_row == 0 or g.labels != grids[k - 1].labels
        ax.set_yticks(range(len(g.labels)), g.labels if first else [], fontsize=7)
        ax.set_title(g.scene, fontsize=9)
        ax.tick_params(length=0)
    if image is not None:
        bar = fig.colorbar(image, ax=list(axes.flat), shrink=0.6, pad=0.02)
        bar.set_label(f"{metric} / noisy input's (per scene, same spp)", fontsize=8)
    fig.suptitle(
        f"Where each denoiser wins: {metric} relative to the noisy input, per scene (framed: lowest)",
        fontsize=10,
        x=0.45,
    )
    return fig


def scenes_figure(grids: list[SceneGrid], metric: str) -> tuple[bytes, str] | None:
    """(PNG, SVG) of :func:`draw_scenes`, or None without a grid."""
    fig = draw_scenes(grids, metric)
    return None if fig is None else save(fig)
