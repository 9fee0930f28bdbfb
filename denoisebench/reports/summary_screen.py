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
* **Equal quality.** At its best spp the denoiser's error ``e``; rendering alone needs ``spp_e``
  (:func:`denoisebench.analysis.equal_tables.spp_for`) and its seconds; the **equal-quality time**
  is the denoiser's seconds over those (below 1: it saves time).
* **Never extrapolated: bounds.** The noisy curve falls with spp, so where ``spp_t`` lies beyond
  the top rung rendering alone reaches *at most* the top rung's error there, and the ratio is a
  lower bound (``≥``, how ``at_least``); below the lowest rung an upper bound (``≤``, ``at_most``).
  Likewise for equal quality: an error below the top rung's needs more than the top rung's seconds
  (the time ratio is ``≤`` that against it), one above the lowest rung's needs no more than the
  lowest rung's (``≥``). A line through the rungs extended by decades says more about its last
  segment than about rendering (on a partial demo run, the 8→16-spp segment put 80-spp rendering
  at 5e-6).
* **Best spp.** The spp of the lowest equal-time error among those read between measured rungs;
  only when none is, the lowest bound.
* **Deciding scenes.** A scene whose value carries more than half of the arithmetic mean of the
  denoiser's per-scene values at its best spp (:func:`deciding_scenes`): that one scene alone would
  move the mean. The per-scene values come from the caller (the same values the aggregate reads).
* Identical denoisers (:mod:`.identical`) share one row, named together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from denoisebench.analysis.equal_tables import error_at, spp_for
from denoisebench.analysis.lead import is_lead_score
from denoisebench.results.finite import num
from denoisebench.results.names import NOISY

#: A scene deciding a mean carries more than this share of the sum of the per-scene values.
DECIDING_SHARE = 0.5
#: How a figure read between measured rungs is marked (anything else is a bound).
EXACT = ("measured", "interpolated")


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
    """``measured``/``interpolated`` (between rungs), or a bound: ``at_least`` (the ratio is at least
    this: rendering alone's error is at most the one given) or ``at_most``."""
    equal_quality_seconds: float | None
    """Rendering alone's seconds to reach the denoiser's error (a rung's seconds for a bound)."""
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
    scenes: tuple[str, ...] = ()
    """The scenes the screen's values come from (sorted). One alone decides every figure: the screen says so."""


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


def _rungs(at) -> list[int]:
    return sorted(s for s, e in at.noisy_curve.items() if e is not None and e > 0 and math.isfinite(e))


def _equal_time(at, point):
    """(rendering alone's error in the point's seconds, how: exact or a bound on the ratio) or (None, None)."""
    spp = _render_spp_at(at.fit, point.seconds)
    rungs = _rungs(at)
    if spp is None or not rungs:
        return None, None
    if spp > rungs[-1] and not math.isclose(spp, rungs[-1]):
        return at.noisy_curve[rungs[-1]], "at_least"  # rendering reaches at most this: the ratio is at least
    if spp < rungs[0] and not math.isclose(spp, rungs[0]):
        return at.noisy_curve[rungs[0]], "at_most"
    found = error_at(at.noisy_curve, spp)
    if found is None or not (found.value > 0 and math.isfinite(found.value)):
        return None, None
    return found.value, found.how


def _equal_quality(at, point):
    """(rendering alone's seconds to the point's error, how: exact or a bound on the ratio) or (None, None)."""
    rungs = _rungs(at)
    if at.fit is None or not rungs:
        return None, None
    need = spp_for(at.noisy_curve, point.error)
    if need is None or need.how == "extrapolated":  # below the top rung's error: it needs more than the top
        spp, how = rungs[-1], "at_most"
    elif need.how == "at_most":  # met at the lowest rung already: rendering needs no more than it
        spp, how = rungs[0], "at_least"
    else:
        spp, how = need.value, need.how
    seconds = at.fit.seconds_at(spp)
    if not (seconds and seconds > 0 and math.isfinite(seconds)):
        return None, None
    return seconds, how


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
    between = [s for s in usable if s[3] in EXACT]
    p, render_error, ratio, how = min(between or usable, key=lambda s: s[2])
    eq_seconds, eq_how = _equal_quality(at, p)
    eq_ratio = p.seconds / eq_seconds if eq_seconds else None
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
        note=None if eq_ratio is not None else "no render time for the noisy curve",
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
        scenes=tuple(
            sorted({scene for by_spp in scene_values.values() for values in by_spp.values() for scene in values})
        ),
    )


# --------------------------------------------------------------------------------------------------
# text both renderers share


#: How a bound reads: the ratio's sign, and the sign of rendering alone's figure it rests on.
BOUND_SIGNS = {"at_least": ("≥ ", "≤ "), "at_most": ("≤ ", "≥ ")}


def _times(ratio: float, how: str | None = None) -> str:
    return BOUND_SIGNS.get(how, ("", ""))[0] + f"{ratio:.3g}×"


def _theirs(how: str | None) -> str:
    return BOUND_SIGNS.get(how, ("", ""))[1]


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
                f"{_times(r.equal_time_ratio, r.equal_time_how)} ({num(r.error)} vs "
                f"{_theirs(r.equal_time_how)}{num(r.equal_time_error)})"
            )
        else:
            eq_time = "—"
        if r.equal_quality_ratio is not None:
            eq_quality = (
                f"{_times(r.equal_quality_ratio, r.equal_quality_how)} ({num(r.seconds)} s vs "
                f"{_theirs(r.equal_quality_how)}{num(r.equal_quality_seconds)} s)"
            )
        else:
            eq_quality = "—"
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
        "≤ and ≥: bounds, where rendering alone would have to be read beyond its measured rungs (never "
        "extrapolated). A deciding scene carries more than half of the mean of the denoiser's per-scene scores at "
        "that spp."
    ]
    best = next((r for r in screen.rows if r.equal_time_ratio is not None and r.equal_time_how in EXACT), None)
    if best is not None and best.equal_time_ratio < 1:
        lines.insert(
            0,
            f"Best at equal time: {best.denoiser} at {best.best_spp} spp, {_times(best.equal_time_ratio)} rendering "
            f"alone's {screen.metric} in the same {num(best.seconds)} s per frame.",
        )
    elif best is not None:
        lines.insert(
            0,
            f"At equal time no denoiser beats rendering alone in {screen.metric}; closest: {best.denoiser} at "
            f"{best.best_spp} spp, {_times(best.equal_time_ratio)} rendering alone's error in the same "
            f"{num(best.seconds)} s per frame.",
        )
    if is_lead_score(screen.metric):
        lines.append(
            f"{screen.metric} leads as a share of the noisy input's at its lowest spp (each scene's score over the "
            "input's there; geometric mean over scenes, from 3 scenes on without the highest and lowest ⌈12.5 %⌉): one "
            "scene cannot move it "
            "by orders of magnitude; the arithmetic mean and its deciding scenes are in results.json."
        )
    if len(screen.scenes) == 1:
        lines.insert(
            0,
            f"This run scores one scene ({screen.scenes[0]}): every figure here is that scene's, so no deciding "
            "scene can be named; score more scenes (run-benchmark --split all, or a larger dataset) before ranking.",
        )
    for spp, scenes in screen.noisy_deciding.items():
        lines.append(f"The noisy input's own mean at {spp} spp is decided by {', '.join(scenes)}.")
    return lines + list(screen.identical)
