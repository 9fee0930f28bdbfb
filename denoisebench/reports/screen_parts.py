"""What the report's first screen and its per-scene figure are made of, gathered from one run.

:func:`screen_parts` reads the run's per-scene values of the lead metric (the values the aggregate
reads: :meth:`denoisebench.analysis.run_index.RunIndex.scene_value`), finds identical denoisers
(:mod:`.identical`, their kept images compared pixel by pixel from the store), and builds the first
screen (:mod:`.summary_screen`) and the small multiples (:mod:`.figures_scenes`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from denoisebench.reports import figures_scenes, identical, summary_screen
from denoisebench.results.names import NOISY


@dataclass(frozen=True, kw_only=True)
class ScreenParts:
    """The first screen, the identical groups and the small-multiples figure (None without values)."""

    first_screen: summary_screen.FirstScreen | None
    identical: list[identical.IdenticalGroup]
    scenes_figure: tuple[bytes, str] | None


def pixel_check(store, run_id: str, *, scenes: list[str], spps: list[int]):
    """``same_pixels(a, b)`` for :func:`.identical.identical_groups`: (images compared, all equal) over
    the frames both labels kept, at every scene and spp."""

    def same_pixels(a: str, b: str) -> tuple[int, bool]:
        count = 0
        for scene in scenes:
            for spp in spps:
                for frame in sorted(
                    set(store.image_frames(run_id, a, spp=spp, scene=scene))
                    & set(store.image_frames(run_id, b, spp=spp, scene=scene))
                ):
                    left = store.image(run_id, a, spp=spp, scene=scene, frame=frame)
                    right = store.image(run_id, b, spp=spp, scene=scene, frame=frame)
                    if left is None or right is None:
                        continue
                    if not np.array_equal(left[1], right[1], equal_nan=True):
                        return count + 1, False
                    count += 1
        return count, True

    return same_pixels


def scene_values(data, metric: str) -> dict[str, dict[int, dict[str, float]]]:
    """{label: {spp: {scene: value}}} of ``metric`` over the units that finished."""
    out: dict[str, dict[int, dict[str, float]]] = {}
    for label in data.labels:
        for spp in data.spp:
            for scene in data.scenes:
                if not data.unit_ok(label, spp, scene):
                    continue
                value = data.scene_value(label, spp, scene, metric=metric)
                if value is not None:
                    out.setdefault(label, {}).setdefault(spp, {})[scene] = value
    return out


def _cell_deciding(summary, label: str, spp: int | None, metric: str) -> list[str] | None:
    """The deciding scenes the aggregate named for (label, spp, metric) (a summary cell's
    ``deciding_scenes``: (scene, share) pairs), or None when the cell has none to give."""
    for row in summary or ():
        if row.denoiser == label and row.spp == spp:
            found = getattr(row.metrics.get(metric), "deciding_scenes", None)
            return None if found is None else [scene for scene, _ in found]
    return None


def _named_by_cells(screen, summary, metric: str):
    """``screen`` with each row's and the noisy input's deciding scenes as the aggregate's cells name
    them, where they do (one rule with results.json's ``deciding_scenes``)."""
    rows = []
    for row in screen.rows:
        found = _cell_deciding(summary, row.denoiser.split(" = ")[0], row.best_spp, metric=metric)
        rows.append(row if found is None else replace(row, deciding_scenes=found))
    noisy = dict(screen.noisy_deciding)
    for spp in {r.spp for r in summary or () if r.denoiser == NOISY}:
        found = _cell_deciding(summary, NOISY, spp, metric=metric)
        if found is not None:
            noisy[spp] = found
    return replace(screen, rows=rows, noisy_deciding={s: n for s, n in sorted(noisy.items()) if n})


def screen_parts(store, data, panels: list, *, metric: str | None, summary=None) -> ScreenParts:
    """The parts for lead ``metric`` (None or no panel of it: no first screen and no figure);
    ``summary``: the report's summary rows, whose cells name the deciding scenes where they do
    (else the first screen finds them from the per-scene values, by the same rule)."""
    groups = identical.identical_groups(
        data.frame_rows,
        data.sequence_rows,
        data.entries,
        same_pixels=pixel_check(store, data.run_id, scenes=data.scenes, spps=data.spp),
    )
    panel = next((p for p in panels if p.metric == metric), None)
    if metric is None or panel is None:
        return ScreenParts(first_screen=None, identical=groups, scenes_figure=None)
    values = scene_values(data, metric)
    screen = _named_by_cells(summary_screen.first_screen(panel, values, groups), summary, metric)
    grids = []
    for scene in data.scenes:
        by_label = {
            label: {spp: v[scene] for spp, v in by_spp.items() if scene in v} for label, by_spp in values.items()
        }
        grids.append(figures_scenes.scene_grid(scene, {k: v for k, v in by_label.items() if v}, data.spp))
    figure = figures_scenes.scenes_figure([g for g in grids if g.labels], metric)
    return ScreenParts(first_screen=screen, identical=groups, scenes_figure=figure)
