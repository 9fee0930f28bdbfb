"""The report's first screen: per denoiser its best spp, its error at equal time, its time at equal
quality, and the scenes that decide its mean, in one table a reader takes in at a glance.

Everything is read off the lead metric's accuracy-against-time panel
(:class:`denoisebench.analysis.accuracy.AccuracyTime`: the same points, seconds and noisy-input
curve as the figure and the readings), so the first screen never disagrees with them.

Rules
-----
* **Equal time.** For a denoiser at spp ``s`` taking ``t`` seconds per frame, rendering alone in
  ``t`` seconds reaches ``spp_t`` (the render line, inverted) and the error of the noisy curve there
  (log-log between measured rungs: :func:`denoisebench.analysis.equal_tables.error_at`). The
  denoiser's **equal-time error** is its error over that one (below 1: it wins).
* **Best spp.** The spp of the lowest equal-time error among those read between measured rungs;
  only when none is, the lowest of the extrapolated ones (marked).
* **Equal quality.** At its best spp the denoiser's error ``e``; rendering alone needs ``spp_e``
  (:func:`denoisebench.analysis.equal_tables.spp_for`) and its seconds; the **equal-quality time**
  is the denoiser's seconds over those (below 1: it saves time). An ``e`` below the top rung's error
  needs an extrapolated ``spp_e`` (marked, at most the analysis' extrapolation limit; beyond it:
  "not reached" on the measured curve).
* **Deciding scenes.** A scene whose value carries more than half of the arithmetic mean of the
  denoiser's per-scene values at its best spp (:func:`deciding_scenes`): that one scene alone would
  move the mean. The per-scene values come from the caller (the same values the aggregate reads).
* Identical denoisers (:mod:`.identical`) share one row, named together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from denoisebench.analysis.equal_tables import error_at, spp_for
from denoisebench.results.finite import num
from denoisebench.results.names import NOISY

#: A scene deciding a mean carries more than this share of the sum of the per-scene values.
DECIDING_SHARE = 0.5


@dataclass(frozen=True, kw_only=True)
class ScreenRow:
    """One denoiser (or a group of identical ones) on the first screen; None: no answer (see ``note``)."""

    denoiser: str
    best_spp: int | None
    seconds: float | None
    error: float | None
    equal_time_error: float | None
    """Rendering alone's error in the same seconds."""
    equal_time_ratio: float | None
    equal_time_how: str | None
    """``measured``/``interpolated`` (between rungs) or ``extrapolated``."""
    equal_quality_seconds: float | None
    """Rendering alone's seconds to reach the denoiser's error."""
    equal_quality_ratio: float | None
    equal_quality_how: str | None
    deciding_scenes: list[str]
    note: str | None = None


@dataclass(frozen=True, kw_only=True)
class FirstScreen:
    """The first screen: the lead metric, the time axis, one row per denoiser (best first)."""

    metric: str
    time_label: str
    rows: list[ScreenRow]
    noisy_deciding: dict[int, list[str]]
    """Per spp, the scenes deciding the noisy input's own mean."""
    identical: list[str]
    """One sentence per group of identical denoisers (:meth:`.identical.IdenticalGroup.sentence`)."""


def deciding_scenes(values: dict[str, float]) -> list[str]:
    """Scenes whose value is more than :data:`DECIDING_SHARE` of the sum of ``values`` (finite, ≥ 0)."""
    finite = {s: v for s, v in values.items() if v is not None and math.isfinite(v) and v >= 0}
    total = sum(finite.values())
    if len(finite) < 2 or total <= 0:
        return []
    return [s for s, v in finite.items() if v > DECIDING_SHARE * total]


def _render_spp_at(fit, seconds: float) -> float | None:
    """The spp rendering alone reaches in ``seconds`` on the fit's render line (None: not positive)."""
    if fit is None or not fit.seconds_per_spp or fit.seconds_per_spp <= 0:
        return None
    spp = (seconds - fit.time_offset) / fit.seconds_per_spp
    return spp if math.isfinite(spp) and spp > 0 else None


def _equal_time(at, point):
    """(rendering's error at the point's seconds, how) or (None, None)."""
    spp = _render_spp_at(at.fit, point.seconds)
    if spp is None:
        return None, None
    found = error_at(at.noisy_curve, spp)
    if found is None or not (found.value > 0 and math.isfinite(found.value)):
        return None, None
    return found.value, found.how


def _row(at, label: str, per_scene: dict[int, dict[str, float]], *, group: list[str]) -> ScreenRow:
    mine = [p for p in at.points if p.denoiser == label]
    name = " = ".join(group)
    empty = ScreenRow(
        denoiser=name,
        best_spp=None,
        seconds=None,
        error=None,
        equal_time_error=None,
        equal_time_ratio=None,
        equal_time_how=None,
        equal_quality_seconds=None,
        equal_quality_ratio=None,
        equal_quality_how=None,
        deciding_scenes=[],
        note="no point on the accuracy-against-time panel (no score or no time)",
    )
    if not mine:
        return empty
    scored = []
    for p in mine:
        render_error, how = _equal_time(at, p)
        ratio = p.error / render_error if render_error else None
        scored.append((p, render_error, ratio, how))
    usable = [s for s in scored if s[2] is not None]
    if not usable:
        best = min(mine, key=lambda p: p.error)
        return replace(
            empty,
            best_spp=best.spp,
            seconds=best.seconds,
            error=best.error,
            deciding_scenes=deciding_scenes(per_scene.get(best.spp, {})),
            note="no noisy-input curve to compare with (its error does not fall with spp, or no render times)",
        )
    between = [s for s in usable if s[3] != "extrapolated"]
    p, render_error, ratio, how = min(between or usable, key=lambda s: s[2])
    eq_seconds = eq_ratio = eq_how = None
    need = spp_for(at.noisy_curve, p.error) if at.noisy_curve else None
    if need is not None and at.fit is not None:
        eq_seconds = at.fit.seconds_at(need.value)
        if eq_seconds and eq_seconds > 0 and math.isfinite(eq_seconds):
            eq_ratio, eq_how = p.seconds / eq_seconds, need.how
        else:
            eq_seconds = None
    return ScreenRow(
        denoiser=name,
        best_spp=p.spp,
        seconds=p.seconds,
        error=p.error,
        equal_time_error=render_error,
        equal_time_ratio=ratio,
        equal_time_how=how,
        equal_quality_seconds=eq_seconds,
        equal_quality_ratio=eq_ratio,
        equal_quality_how=eq_how,
        deciding_scenes=deciding_scenes(per_scene.get(p.spp, {})),
        note=None if eq_ratio is not None else "its error is beyond what the measured noisy curve reaches",
    )


def first_screen(at, scene_values: dict[str, dict[int, dict[str, float]]], identical=()) -> FirstScreen:
    """The first screen from the lead metric's panel ``at`` and ``scene_values`` {label: {spp: {scene:
    value}}} of that metric; ``identical``: :class:`.identical.IdenticalGroup` s (one row each)."""
    groups = {g.labels[0]: list(g.labels) for g in identical}
    hidden = {label for g in identical for label in g.labels[1:]}
    labels = [l for l in dict.fromkeys(p.denoiser for p in at.points) if l != NOISY and l not in hidden]
    rows = [_row(at, label, scene_values.get(label, {}), group=groups.get(label, [label])) for label in labels]
    rows.sort(key=lambda r: (r.equal_time_ratio is None, r.equal_time_ratio if r.equal_time_ratio is not None else 0.0))
    noisy = {spp: deciding_scenes(values) for spp, values in scene_values.get(NOISY, {}).items()}
    return FirstScreen(
        metric=at.metric,
        time_label=at.time_label,
        rows=rows,
        noisy_deciding={spp: scenes for spp, scenes in sorted(noisy.items()) if scenes},
        identical=[g.sentence() for g in identical],
    )


# --------------------------------------------------------------------------------------------------
# text both renderers share


def _mark(how: str | None) -> str:
    return " (extrapolated)" if how == "extrapolated" else ""


def _times(ratio: float) -> str:
    return f"{ratio:.2g}×"


def screen_rows(screen: FirstScreen) -> tuple[list[str], list[list[str]]]:
    """(header, rows) of the first-screen table."""
    metric = screen.metric
    header = [
        "denoiser",
        "best spp",
        f"its {metric}",
        "its s/frame",
        "error at equal time (vs rendering alone)",
        "time at equal quality (vs rendering alone)",
        "deciding scenes",
    ]
    rows = []
    for r in screen.rows:
        if r.best_spp is None:
            rows.append([r.denoiser, "—", "—", "—", "—", "—", r.note or ""])
            continue
        if r.equal_time_ratio is not None:
            eq_time = (
                f"{_times(r.equal_time_ratio)} ({num(r.error)} vs {num(r.equal_time_error)}){_mark(r.equal_time_how)}"
            )
        else:
            eq_time = "—"
        if r.equal_quality_ratio is not None:
            eq_quality = (
                f"{_times(r.equal_quality_ratio)} ({num(r.seconds)} s vs {num(r.equal_quality_seconds)} s)"
                f"{_mark(r.equal_quality_how)}"
            )
        else:
            eq_quality = "not reached on the measured curve"
        rows.append(
            [
                r.denoiser,
                str(r.best_spp),
                num(r.error),
                num(r.seconds),
                eq_time,
                eq_quality,
                ", ".join(r.deciding_scenes) or "none",
            ]
        )
    return header, rows


def screen_lines(screen: FirstScreen) -> list[str]:
    """Sentences under the table: how to read it, the input's deciding scenes, identical denoisers."""
    lines = [
        f"Lead score: {screen.metric}; times are {screen.time_label}. Ratios below 1× favour the denoiser: "
        "its error over rendering alone's in the same time, its time over rendering alone's to the same error. "
        "A deciding scene carries more than half of the mean of the denoiser's per-scene scores at that spp."
    ]
    best = next((r for r in screen.rows if r.equal_time_ratio is not None and r.equal_time_how != "extrapolated"), None)
    if best is not None:
        lines.insert(
            0,
            f"Best at equal time: {best.denoiser} at {best.best_spp} spp, {_times(best.equal_time_ratio)} rendering "
            f"alone's {screen.metric} in the same {num(best.seconds)} s per frame.",
        )
    for spp, scenes in screen.noisy_deciding.items():
        lines.append(f"The noisy input's own mean at {spp} spp is decided by {', '.join(scenes)}.")
    return lines + list(screen.identical)
