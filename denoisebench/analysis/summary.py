"""Numbers a report is made of, computed from one run's rows (no drawing, no HTML, no store or file read).

Accuracy against time (the points, the noisy input's curve, the readings) is in :mod:`.accuracy`;
this module has the run's rows (:class:`RunData`) and what is aggregated over scenes from them.

* :func:`summary_table`: per denoiser and input spp, every metric aggregated over scenes by its
  rule (:mod:`.aggregate`: scale-free scores by mean, linear ones relative to the noisy input or by
  geometric mean) with a bootstrap 95 % interval over **scenes** (frames of one scene are not
  independent samples) that includes the reference's uncertainty; MSE-family metrics also carry
  their reference-noise floor and the floor-corrected value; and seconds per frame.
* :func:`indistinguishable_pairs`: pairs of denoisers whose scores differ by less than the
  reference's noise can resolve ("not distinguishable at this reference quality").
* :func:`effect_breakdown`: per denoiser and scene effect, the share of the input's error left.
* :func:`flicker_series`: per denoiser, the per-frame flicker (a scale-free temporal metric of frame
  t against t−1) averaged over scenes, at one spp.

Notes
-----
* Failed units are left out of means and listed separately; a denoiser/spp with no successful
  unit has no point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from denoisebench.analysis import aggregate as agg
from denoisebench.analysis import lead
from denoisebench.analysis.run_index import RunIndex
from denoisebench.results.finite import finite_mean, is_finite
from denoisebench.results.names import (
    FLICKER_METRICS,
    FLICKER_PREFIX,
    NOISY,
)
from denoisebench.results.records import EntryRow, RunRow, RunRows

#: Scenes a per-effect column needs (on one scene a column is that scene's score, not the effect's).
MIN_EFFECT_SCENES = 2


def bootstrap_interval(values, ses=None) -> tuple[float | None, float | None]:
    """Percentile bootstrap 95 % interval of the mean; ``ses`` widen it by the reference's noise."""
    values = list(values)
    keep = [i for i, v in enumerate(values) if is_finite(v)]
    return agg.bootstrap_mean([float(values[i]) for i in keep], None if ses is None else [ses[i] for i in keep])


@dataclass(kw_only=True)
class Cell:
    """A metric aggregated over scenes under its ``rule`` (:mod:`.aggregate`), with a 95 % interval.

    For metrics with a reference-noise floor (the MSE family, with a reference variance) ``value``,
    ``low`` and ``high`` are the **floor-corrected** aggregate (``score − floor`` per scene, raised to
    the reference's se where below it: :func:`.aggregate.corrected_values`), and the interval carries
    the reference's uncertainty; ``raw``/``raw_low``/``raw_high`` are the score as measured against
    the reference, ``floor`` the floor aggregated by the same rule, ``at_resolution`` the scenes whose
    corrected value was at the reference's resolution. Without a floor ``raw`` is ``value``.

    **The number that leads.** For the lead scores (:data:`.lead.LEAD_SCORES`) ``value``/``low``/``high``
    (and ``raw``, ``floor``) are the anchored trimmed geometric mean (``rule`` = :data:`.lead.LEAD_RULE`:
    each scene's score as a share of the noisy input's on that scene at ``anchor_spp``, the run's
    lowest spp; :mod:`.lead`), which no single scene moves by orders of magnitude; ``by_rule`` is the
    aggregate under the metric's own registry rule (``by_rule_name``) that led before. Every cell also
    carries, in the score's units, the ``arithmetic`` mean over scenes of the (corrected) scores with
    its bootstrap interval (``arithmetic_low``/``arithmetic_high``), the ``deciding_scenes`` that carry
    more than half of it ([(scene, share)]), and ``drop_one``, the largest factor by which dropping one
    scene moves the leading value (lead scores only).

    **Floors.** ``floor_closed_form`` and ``floor_measured`` (from the reference's two halves,
    :mod:`denoisebench.metrics.floors.half_reference`) are aggregated like ``floor``; ``measured_floor_leads``
    names the scenes where the two disagreed beyond the measured one's uncertainty, so the measured
    floor corrected the score there (:func:`.aggregate.leading_floor`).
    """

    value: float | None
    low: float | None
    high: float | None
    scenes: int
    rule: str = "mean"
    floor: float | None = None
    raw: float | None = None
    raw_low: float | None = None
    raw_high: float | None = None
    at_resolution: int = 0
    arithmetic: float | None = None
    arithmetic_low: float | None = None
    arithmetic_high: float | None = None
    deciding_scenes: list[tuple[str, float]] = field(default_factory=list)
    by_rule: float | None = None
    by_rule_name: str | None = None
    anchor_spp: int | None = None
    drop_one: float | None = None
    floor_closed_form: float | None = None
    floor_measured: float | None = None
    measured_floor_leads: list[str] = field(default_factory=list)

    @property
    def corrected(self) -> float | None:
        """The floor-corrected aggregate (``value``), None for a metric without a floor."""
        return self.value if self.floor is not None else None


@dataclass(kw_only=True)
class SummaryRow:
    denoiser: str
    spp: int
    metrics: dict[str, Cell]
    denoise_seconds: float | None  # mean per frame
    total_seconds: float | None  # mean per frame
    render_seconds: float | None  # mean per frame
    frames: int
    failed_units: int
    errors: list[str] = field(default_factory=list)


class RunData(RunIndex):
    """One run's rows, indexed once for the analyses (:class:`.run_index.RunIndex`). The caller loads
    them (``RunData(store.run_rows(run_id))``, :func:`denoisebench.reports.run_inputs.run_data`).

    Typed rows: ``run`` (:class:`~.records.RunRow`), ``entries`` (:class:`~.records.EntryRow`, the
    run's labels in the order they were added), and from :class:`.run_index.RunIndex` ``unit_rows``,
    ``frame_rows``, ``sequence_rows``.
    """

    def __init__(self, rows: RunRows):
        self.run: RunRow = rows.run
        self.run_id = rows.run.run_id
        self.entries: list[EntryRow] = rows.entries
        super().__init__(rows.units, rows.frames, rows.sequences)
        self.labels = [d.label for d in self.entries if not d.load_error]
        self._entry = {d.label: d for d in self.entries}

    def entry(self, label: str) -> EntryRow | None:
        """The :class:`~.records.EntryRow` of ``label`` (its sampler and denoiser: the run's sampler
        dimension), or None for a label the run does not have."""
        return self._entry.get(label)


def set_apart(data: RunData, *, records: dict[str, dict], noisy_shares: dict[str, float]) -> list[agg.Unresolved]:
    """The scenes of a run whose scores cannot rank (:func:`.aggregate.unresolved_references`), judged
    from the dataset's scene records (``records``: {scene: record}) and the largest share of each
    scene's reference values too noisy for a floor (``noisy_shares``, read from a few references by
    :func:`denoisebench.reports.run_inputs.reference_noisy_shares`): the one rule the report and
    ``denoisebench leaderboard`` share."""
    states = agg.reference_states({s: records[s] for s in data.scenes})
    for scene, share in noisy_shares.items():
        states.setdefault(scene, {})["noisy_share"] = share
    return agg.unresolved_references(data, states)
    return agg.unresolved_references(data, states)


def summary_table(data: RunData, exclude=()) -> list[SummaryRow]:
    """Per (spp, denoiser): every metric aggregated over its ok scenes, except ``exclude`` (the scenes
    whose reference cannot resolve the headline scores, :func:`.aggregate.unresolved_references`)."""
    exclude = set(exclude)
    rows = []
    for spp in data.spp:
        for label in data.labels:
            units = data.units_of(label, spp)
            if not units:
                continue
            ok_scenes = [u.scene for u in units if u.status == "ok" and u.scene not in exclude]
            cells = {}
            for metric in data.frame_metric_names + data.sequence_metric_names:
                cells[metric] = metric_cell(data, label, spp, metric=metric, scenes=ok_scenes)
            frames = [f for s in ok_scenes for f in data.ok_frames(label, spp, s)]
            rows.append(
                SummaryRow(
                    denoiser=label,
                    spp=spp,
                    metrics=cells,
                    denoise_seconds=finite_mean(f.denoise_seconds for f in frames),
                    total_seconds=finite_mean(f.total_seconds for f in frames),
                    render_seconds=finite_mean(f.render_seconds for f in frames),
                    frames=len(frames),
                    failed_units=sum(u.status != "ok" for u in units),
                    errors=sorted({u.error for u in units if u.error}),
                )
            )
    return rows


def metric_cell(data: RunData, label: str, spp: int, metric: str, scenes: list[str] | None) -> Cell:
    """One metric of one denoiser at one spp, aggregated over ``scenes``.

    With floors on every scene the cell is built from the corrected scores (:class:`Cell`); for
    ``relative_to_input`` both the denoiser's and the input's scores are corrected before the ratio.
    A lead score (:data:`.lead.LEAD_SCORES`) then leads with the anchored trimmed geometric mean
    (:mod:`.lead`); every cell keeps the arithmetic mean and its deciding scenes beside it."""
    rule = agg.rule_of(metric)
    mine, floors, ses = data.per_scene(label, spp, metric, scenes=scenes)
    noisy = noisy_floors = noisy_ses = None
    if rule == "relative_to_input":
        noisy, noisy_floors, noisy_ses = data.per_scene(NOISY, spp, metric, scenes=scenes)
    value, low, high, count = agg.aggregate(rule, mine, noisy, ses=ses)
    floored = bool(floors) and len(floors) == len(mine) and value is not None
    per_scene_floors: dict[str, dict | None] = {}
    if not floored:
        cell = Cell(value=value, low=low, high=high, scenes=count, rule=rule, raw=value, raw_low=low, raw_high=high)
        scores = mine
    else:
        # relative_to_input: the floor relative to the input's own score (noisy is None otherwise)
        floor = agg.aggregate(rule, floors, noisy)[0]
        higher = agg.higher_is_better(metric)
        corrected, raised = agg.corrected_values(mine, floors, ses, higher_is_better=higher)
        noisy_corrected = None
        if noisy is not None:
            noisy_corrected = agg.corrected_values(noisy, noisy_floors or {}, noisy_ses, higher_is_better=higher)[0]
        c_value, c_low, c_high, c_count = agg.aggregate(rule, corrected, noisy_corrected, ses=ses)
        cell = Cell(
            value=c_value,
            low=c_low,
            high=c_high,
            scenes=c_count,
            rule=rule,
            floor=floor,
            raw=value,
            raw_low=low,
            raw_high=high,
            at_resolution=len(raised),
        )
        scores = corrected
        per_scene_floors = _floor_sources(cell, data, (label, spp, metric), scenes=list(mine))
    cell.arithmetic = lead.arithmetic_mean(scores)
    arithmetic = [float(v) for v in scores.values() if is_finite(v)]
    cell.arithmetic_low, cell.arithmetic_high = agg.bootstrap_mean(arithmetic) if arithmetic else (None, None)
    cell.deciding_scenes = lead.deciding_scenes(scores)
    if lead.is_lead_score(metric) and not agg.higher_is_better(metric):
        _lead(cell, data, (label, spp, metric), scores=(mine, scores), floors=per_scene_floors)
    return cell


def _anchors(data: RunData, metric: str, scenes, corrected: bool) -> tuple[int | None, dict]:
    """(anchor spp, {scene: the noisy input's score there}): the run's lowest spp, corrected like the cell."""
    if not data.spp:
        return None, {}
    spp = data.spp[0]
    values, floors, ses = data.per_scene(NOISY, spp, metric, scenes=scenes)
    if corrected and floors and len(floors) == len(values):
        values = agg.corrected_values(values, floors, ses)[0]
    return spp, values


def _lead(cell: Cell, data: RunData, key: tuple[str, int, str], *, scores: tuple[dict, dict], floors: dict) -> None:
    """Make ``cell`` lead with the anchored trimmed geometric mean (:mod:`.lead`) of ``scores`` (raw,
    and as the cell reads them: corrected where floored); ``floors``: {cell field: {scene: floor}}."""
    label, spp, metric = key
    mine, scores = scores
    corrected = cell.floor is not None
    anchor_spp, anchors = _anchors(data, metric, list(scores), corrected=corrected)
    value, low, high, count = lead.lead_aggregate(scores, anchors)
    cell.by_rule, cell.by_rule_name = cell.value, cell.rule
    cell.value, cell.low, cell.high, cell.scenes = value, low, high, count
    cell.rule, cell.anchor_spp = lead.LEAD_RULE, anchor_spp
    cell.drop_one = lead.drop_one_factor(scores, anchors)
    if corrected:
        raw_anchors = _anchors(data, metric, list(scores), corrected=False)[1]
        cell.raw, cell.raw_low, cell.raw_high, _ = lead.lead_aggregate(mine, raw_anchors)
        for name, per_scene in floors.items():
            shared = None if per_scene is None else lead.lead_value(per_scene, raw_anchors)
            if shared is not None or name != "floor":  # a floor ≤ 0 keeps the rule's (the cell stays corrected)
                setattr(cell, name, shared)
    else:
        cell.raw, cell.raw_low, cell.raw_high = value, low, high


def _floor_sources(cell: Cell, data: RunData, key: tuple[str, int, str], *, scenes: list[str]) -> dict:
    """Fill ``cell``'s closed-form and measured floors (aggregated like ``floor``) and the scenes where
    the measured one led (:meth:`.run_index.RunIndex.scene_floors`); return the per-scene floors
    {cell field: {scene: floor} or None where a scene lacks one}."""
    label, spp, metric = key
    found = {s: data.scene_floors(label, spp, s, metric=metric) for s in scenes}
    closed = {s: f.closed for s, f in found.items() if f.closed is not None}
    measured = {s: f.measured for s, f in found.items() if f.measured is not None}
    leading = {s: f.floor for s, f in found.items() if f.floor is not None}
    cell.measured_floor_leads = sorted(s for s, f in found.items() if f.source == "measured" and f.closed is not None)
    rule = cell.rule
    noisy = data.per_scene(NOISY, spp, metric, scenes=scenes)[0] if rule == "relative_to_input" else None
    cell.floor_closed_form = agg.aggregate(rule, closed, noisy)[0] if len(closed) == len(scenes) else None
    cell.floor_measured = agg.aggregate(rule, measured, noisy)[0] if len(measured) == len(scenes) else None
    return {
        "floor": leading,
        "floor_closed_form": closed if len(closed) == len(scenes) else None,
        "floor_measured": measured if len(measured) == len(scenes) else None,
    }


@dataclass(kw_only=True)
class Indistinguishable:
    """Two denoisers whose aggregated scores differ by less than the reference can resolve."""

    spp: int
    metric: str
    a: str
    b: str
    difference: float  # a − b on the rule's scale (score units for mean; log ratio otherwise)
    resolution: float  # 95 % half-width the reference's noise allows


def indistinguishable_pairs(data: RunData, summary: list[SummaryRow]) -> list[Indistinguishable]:
    """Pairs (noisy input included) whose difference lies within the reference's uncertainty.

    For every metric with stored reference se (the MSE family) and every spp; per-scene values over
    the scenes both measured (:func:`.aggregate.reference_resolution`, conservative).
    """
    found = []
    metrics = [
        m
        for m in data.frame_metric_names + data.sequence_metric_names
        if any(c.metrics.get(m) is not None and c.metrics[m].floor is not None for c in summary)
    ]
    for spp in data.spp:
        rows = [r for r in summary if r.spp == spp and r.failed_units == 0]
        for metric in metrics:
            rule = agg.rule_of(metric)
            per = {r.denoiser: data.per_scene(r.denoiser, spp, metric) for r in rows}
            labels = [r.denoiser for r in rows if per[r.denoiser][0]]
            for i, a in enumerate(labels):
                for b in labels[i + 1 :]:
                    (va, _, sa), (vb, _, sb) = per[a], per[b]
                    resolution = agg.reference_resolution(rule, va, sa, mine_b=vb, ses_b=sb)
                    if resolution is None:
                        continue
                    common = [s for s in va if s in vb]
                    if rule == "mean":
                        diff = float(np.mean([va[s] - vb[s] for s in common]))
                    elif all(va[s] > 0 and vb[s] > 0 for s in common):
                        diff = float(np.mean([math.log(va[s] / vb[s]) for s in common]))
                    else:
                        continue
                    if abs(diff) <= resolution:
                        found.append(
                            Indistinguishable(spp=spp, metric=metric, a=a, b=b, difference=diff, resolution=resolution)
                        )
    return found


# --------------------------------------------------------------------------------------------------
# effects and flicker


@dataclass(frozen=True, kw_only=True)
class EffectBreakdown:
    """Per denoiser and effect, the geometric-mean share of the input's error left (:func:`effect_breakdown`).

    ``table``: {denoiser: {``overall`` and each effect: share, None without a value}}; ``too_few``:
    effects left out, with their scene counts; ``notes``: what the report says about them."""

    metric: str
    effects: list[str]
    table: dict[str, dict[str, float | None]]
    too_few: dict[str, int]
    notes: list[str]


def effect_breakdown(data: RunData, scene_effects: dict[str, list[str]], metric: str = "relmse") -> EffectBreakdown:
    """{denoiser: {effect: geometric-mean share of the input's error left}}, plus ``overall``.

    The share is denoiser error / noisy-input error per scene and spp (so scene difficulty cancels),
    averaged geometrically over the scenes that exercise the effect.

    Notes
    -----
    A column needs :data:`MIN_EFFECT_SCENES` scenes: columns with fewer are left out (``too_few``) and
    ``notes`` says so, and which sentences the report cannot write (a "suffers most from" needs two
    columns). Effects that the run's scenes always exercise together (every scene with ``specular`` also has
    ``transmission`` and the other way round) would be columns of the same numbers, computed over the
    same scenes: they are one column, named by their effects joined with ``" + "``
    (``"specular + transmission"``). The run cannot tell such effects apart; more scenes can.
    """
    scene_effects = _merge_inseparable(scene_effects, data.scenes)
    counts: dict[str, int] = {}
    for scene in data.scenes:
        for effect in scene_effects.get(scene, []):
            counts[effect] = counts.get(effect, 0) + 1
    effects = sorted(e for e, n in counts.items() if n >= MIN_EFFECT_SCENES)
    too_few = {e: n for e, n in sorted(counts.items()) if n < MIN_EFFECT_SCENES}
    notes = []
    if too_few:
        notes.append(
            f"Not shown: {', '.join(f'{e} ({n} scene)' for e, n in too_few.items())}. A per-effect column needs "
            f"{MIN_EFFECT_SCENES} scenes of its own: on one scene it is that scene's score, not the effect's."
        )
    if len(effects) < 2:
        notes.append(
            "No \"suffers most from\" sentence: that needs two columns to compare"
            + (f" (this run has {len(effects)})." if effects else " (this run has none).")
        )
    table: dict[str, dict[str, float | None]] = {}
    for label in data.labels:
        if label == NOISY:
            continue
        shares: dict[str, list[float]] = {}
        for scene in data.scenes:
            for spp in data.spp:
                mine, noisy = (
                    data.scene_value(label, spp, scene, metric=metric),
                    data.scene_value(NOISY, spp, scene, metric=metric),
                )
                if mine is None or not noisy or mine <= 0 or not data.unit_ok(label, spp, scene):
                    continue
                for key in ["overall", *scene_effects.get(scene, [])]:
                    shares.setdefault(key, []).append(mine / noisy)
        table[label] = {
            key: (float(np.exp(np.mean(np.log(shares[key])))) if shares.get(key) else None)
            for key in ["overall", *effects]
        }
    return EffectBreakdown(metric=metric, effects=effects, table=table, too_few=too_few, notes=notes)


def _merge_inseparable(scene_effects: dict[str, list[str]], scenes) -> dict[str, list[str]]:
    """``scene_effects`` with effects exercised by exactly the same of ``scenes`` merged into one name."""
    present = [s for s in scenes if s in scene_effects]
    holders: dict[str, frozenset] = {}
    for effect in sorted({e for s in present for e in scene_effects[s]}):
        holders[effect] = frozenset(s for s in present if effect in scene_effects[s])
    groups: dict[frozenset, list[str]] = {}
    for effect, where in holders.items():
        groups.setdefault(where, []).append(effect)
    name_of = {effect: " + ".join(group) for group in groups.values() for effect in group}
    return {scene: list(dict.fromkeys(name_of.get(e, e) for e in effects)) for scene, effects in scene_effects.items()}


def flicker_metrics(data: RunData) -> list[str]:
    """The per-frame flicker metrics a run stored: FLICKER_METRICS, or ``temporal_l1`` of old runs."""
    stored = data.flicker_names
    names = [m for m in FLICKER_METRICS if FLICKER_PREFIX + m in stored]
    if not names and "flicker" in stored:
        names = ["temporal_l1"]  # older runs: "flicker" was temporal_l1 (linear: not averaged in a figure)
    return names


def flicker_series(data: RunData, spp: int, metric: str = FLICKER_METRICS[0]) -> dict[str, list[float | None]]:
    """{denoiser: [mean ``metric`` flicker of frame 1, 2, ...] over scenes} at ``spp`` (frame 0 has none).

    The mean over scenes is arithmetic: only for scale-free metrics (the flicker ones are).
    """
    key = "flicker" if metric == "temporal_l1" else FLICKER_PREFIX + metric
    series = {}
    for label in data.labels:
        by_frame: dict[int, list[float]] = {}
        for f in data.ok_frames(label, spp):
            value = f.metrics.get(key)
            if is_finite(value):
                by_frame.setdefault(f.frame, []).append(value)
        if by_frame:
            last = max(by_frame)
            series[label] = [float(np.mean(by_frame[i])) if i in by_frame else None for i in range(1, last + 1)]
    return series
