"""What the report's first screen and its per-scene figure are made of, gathered from one run.

:func:`screen_parts` reads the run's per-scene values of the lead metric (the values the aggregate
reads: :meth:`denoisebench.analysis.run_index.RunIndex.scene_value`), finds identical denoisers
(:mod:`.identical`, their kept images compared pixel by pixel from the store), and builds the first
screen (:mod:`.summary_screen`) and the small multiples (:mod:`.figures_scenes`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from denoisebench.reports import figures_scenes, identical, summary_screen


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
                    set(store.image_frames(run_id, a, scene, spp=spp))
                    & set(store.image_frames(run_id, b, scene, spp=spp))
                ):
                    left = store.image(run_id, a, scene, spp=spp, frame=frame)
                    right = store.image(run_id, b, scene, spp=spp, frame=frame)
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


def screen_parts(store, data, panels: list, *, metric: str | None) -> ScreenParts:
    """The parts for lead ``metric`` (None or no panel of it: no first screen and no figure)."""
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
    screen = summary_screen.first_screen(panel, values, groups)
    grids = []
    for scene in data.scenes:
        by_label = {
            label: {spp: v[scene] for spp, v in by_spp.items() if scene in v} for label, by_spp in values.items()
        }
        grids.append(figures_scenes.scene_grid(scene, {k: v for k, v in by_label.items() if v}, data.spp))
    figure = figures_scenes.scenes_figure([g for g in grids if g.labels], metric)
    return ScreenParts(first_screen=screen, identical=groups, scenes_figure=figure)
