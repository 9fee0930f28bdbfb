"""One run's rows indexed once, and the one place a metric's per-scene value is computed.

Everything that combines scenes (the report's summary table, ``denoisebench leaderboard``, the
effect breakdown, the unresolved-reference rule) asks :class:`RunIndex` for a label's value on a
scene, so they all read the same number the same way.

Notes
-----
* **Per-scene value.** A metric the run stored per frame has the **trimmed mean** over the scene's
  successful frames; a temporal metric the run also stored per consecutive pair (``flicker.<metric>``
  on frame t, frame t against t−1: ``FLICKER_METRICS``) has the trimmed mean over those pairs, with
  their floors, so one flickering frame cannot decide it either (a frame enters two pairs, so twice
  as many pairs are dropped: 2 of 7 at each end for 8 frames, the mean of the middle 3); a temporal
  metric stored per sequence only (``sequence_metrics``: temporal_l1, cvvdp, ...) has the sequence's
  value. Frames: sorted by value, ⌈:data:`FRAME_TRIM` · n⌉
  frames dropped at each end when there are at least 3 (one of 3 to 8 frames: the median of 3, the
  mean of the middle 6 of 8), so that no single frame decides a scene (the trimmed mean of robust
  statistics: Tukey & McLaughlin 1963; Wilcox, "Introduction to Robust Estimation and Hypothesis
  Testing", who recommends 20 %; 12.5 % drops exactly one frame of eight). One frame blown up by any
  factor moves the scene's value by at most (largest kept − smallest kept) / kept count
  (tests/analysis/test_run_index.py). Which table holds it decides, not the metric registry, so a run
  whose plugin metric is no longer installed reads the same. Values that are not finite are left out
  (:mod:`.finite`). :meth:`RunIndex.deciding_frames` names frames far above their scene's median.
* **Floors.** A scene's floor is the mean of its kept frames' floors (all must have one) and its
  reference standard error that of the mean over them, sqrt(Σ se²)/n. A score with a closed-form
  floor also has the floor measured from the reference's halves (frame "metrics" named
  ``floor_measured.<name>``, no metrics themselves); the one that leads is chosen per scene by
  :func:`.aggregate.leading_floor` (:meth:`RunIndex.scene_floors`).
* **Indexed once.** Frames are grouped by (label, spp) and (label, spp, scene), sequence values by
  (label, spp, scene, metric), units by (label, spp), when the index is built: a lookup never
  rescans the run's rows. Lists keep the store's order (label, scene, spp, frame).
"""

from __future__ import annotations

import math

from denoisebench.analysis.aggregate import SceneFloors, leading_floor
from denoisebench.results.finite import finite_mean, finite_values, is_finite
from denoisebench.results.names import FLICKER_PREFIX, MEASURED_FLOOR_PREFIX
from denoisebench.results.records import FrameRow, SequenceRow, UnitRow

#: Share of a scene's frames dropped at each end of the sorted values (at least 3 frames): one of 8.
FRAME_TRIM = 0.125
#: A frame whose value is above this multiple of its scene's median decides that scene's plain mean.
DECIDING_FACTOR = 10.0


def kept_frames(frames: list, metric: str) -> list:
    """The frames a scene's value averages: finite ones, sorted by value, without the ``k`` lowest and
    highest: k = ⌈FRAME_TRIM·n⌉ when there are at least 3 frames; for per-pair values
    (``flicker.<metric>``, n pairs of n + 1 frames) k = 2·⌈FRAME_TRIM·(n + 1)⌉, at most (n − 1) // 2,
    since one frame enters two pairs (module Notes)."""
    rows = sorted((f for f in frames if is_finite(f.metrics.get(metric))), key=lambda f: f.metrics[metric])
    if len(rows) < 3:
        return rows
    if metric.startswith(FLICKER_PREFIX):
        k = min(2 * math.ceil(FRAME_TRIM * (len(rows) + 1)), (len(rows) - 1) // 2)
    else:
        k = math.ceil(FRAME_TRIM * len(rows))
    return rows[k : len(rows) - k]


class RunIndex:
    """A run's units, frames and sequence values, indexed by label, spp and scene."""

    def __init__(self, units: list[UnitRow], frames: list[FrameRow], sequences: list[SequenceRow]):
        self.unit_rows, self.frame_rows, self.sequence_rows = units, frames, sequences
        self.spp = sorted({u.spp for u in units})
        self.scenes = sorted({u.scene for u in units})
        stored = {m for f in frames for m in f.metrics if not m.startswith(MEASURED_FLOOR_PREFIX)}
        self.frame_metric_names = sorted(m for m in stored if not m.startswith("flicker"))
        self.sequence_metric_names = sorted({s.metric for s in sequences})
        #: the per-frame flicker names stored (``flicker.<metric>``, or ``flicker`` of older runs)
        self.flicker_names = {m for m in stored if m.startswith("flicker")}
        self._units: dict[tuple[str, int], list[UnitRow]] = {}
        self._unit_ok: set[tuple[str, int, str]] = set()
        for u in units:
            self._units.setdefault((u.denoiser, u.spp), []).append(u)
            if u.status == "ok":
                self._unit_ok.add((u.denoiser, u.spp, u.scene))
        self._frames_of: dict[str, list[FrameRow]] = {}
        self._ok: dict[tuple, list[FrameRow]] = {}
        for f in frames:
            self._frames_of.setdefault(f.denoiser, []).append(f)
            if f.status == "ok":
                self._ok.setdefault((f.denoiser, f.spp), []).append(f)
                self._ok.setdefault((f.denoiser, f.spp, f.scene), []).append(f)
        self._sequences: dict[tuple[str, int, str, str], list[SequenceRow]] = {}
        for s in sequences:
            self._sequences.setdefault((s.denoiser, s.spp, s.scene, s.metric), []).append(s)

    # ------------------------------------------------------------------ rows

    def units_of(self, label: str, spp: int) -> list[UnitRow]:
        """The units of ``label`` at ``spp`` (one per scene it was run on)."""
        return self._units.get((label, spp), [])

    def frames_of(self, label: str) -> list[FrameRow]:
        """Every frame row of ``label``, failed ones included."""
        return self._frames_of.get(label, [])

    def ok_frames(self, label: str, spp: int, scene: str | None = None) -> list[FrameRow]:
        """The successful frames of ``label`` at ``spp`` (on one scene, or on every scene in order)."""
        return self._ok.get((label, spp) if scene is None else (label, spp, scene), [])

    def unit_ok(self, label: str, spp: int, scene: str) -> bool:
        return (label, spp, scene) in self._unit_ok

    # ------------------------------------------------------------------ per-scene values

    def is_sequence_metric(self, metric: str) -> bool:
        """True when the run holds ``metric`` per sequence only (a temporal metric)."""
        return metric in self.sequence_metric_names and metric not in self.frame_metric_names

    def per_frame_name(self, metric: str) -> str | None:
        """The name under which frame rows hold ``metric`` (itself, or ``flicker.<metric>`` for a temporal
        metric stored per pair), or None when it is held per sequence only."""
        if not self.is_sequence_metric(metric):
            return metric
        return FLICKER_PREFIX + metric if FLICKER_PREFIX + metric in self.flicker_names else None

    def scene_value(self, label: str, spp: int, scene: str, metric: str) -> float | None:
        """The value of ``metric`` for ``label`` on one scene: the trimmed mean of its frames (or pairs),
        or its sequence value (module Notes)."""
        name = self.per_frame_name(metric)
        if name is None:
            values = [s.value for s in self._sequences.get((label, spp, scene, metric), [])]
        else:
            values = [f.metrics.get(name) for f in kept_frames(self.ok_frames(label, spp, scene), name)]
        return finite_mean(values)

    def deciding_frames(self, label: str, spp: int, scene: str, metric: str) -> list[tuple[int, float, float]]:
        """[(frame, value, scene median)] of frames (for a temporal metric: pairs, named by their later
        frame) whose ``metric`` is over :data:`DECIDING_FACTOR` × the scene's median: the frames a plain
        mean would be decided by (the trimmed mean drops them)."""
        metric = self.per_frame_name(metric)
        if metric is None:
            return []
        frames = [f for f in self.ok_frames(label, spp, scene) if is_finite(f.metrics.get(metric))]
        if len(frames) < 3:
            return []
        values = sorted(f.metrics[metric] for f in frames)
        median = values[len(values) // 2] if len(values) % 2 else 0.5 * sum(values[len(values) // 2 - 1 :][:2])
        if not median > 0:
            return []
        return [(f.frame, f.metrics[metric], median) for f in frames if f.metrics[metric] > DECIDING_FACTOR * median]

    def scene_floor(self, label: str, spp: int, scene: str, metric: str) -> tuple[float | None, float | None]:
        """(floor, ref_se) of a metric on one scene: the floor that leads, closed-form or measured
        (:meth:`scene_floors`)."""
        found = self.scene_floors(label, spp, scene, metric=metric)
        return found.floor, found.se

    def scene_floors(self, label: str, spp: int, scene: str, metric: str) -> SceneFloors:
        """Both floors of ``metric`` on one scene (the stored one and the one measured from the reference's
        halves, each the mean over the kept frames with the se of that mean) and the one that leads
        (:func:`.aggregate.leading_floor`)."""
        closed, closed_se = self._stored_floor(label, spp, scene, metric=metric)
        measured = measured_se = None
        name = self.per_frame_name(metric)
        if name is not None:
            frames = kept_frames(self.ok_frames(label, spp, scene), name)
            key = MEASURED_FLOOR_PREFIX + name
            floors = finite_values(f.metrics.get(key) for f in frames)
            ses = finite_values(f.ref_se.get(key) for f in frames)
            if frames and len(floors) == len(frames):
                measured = finite_mean(floors)
                if len(ses) == len(frames):
                    measured_se = float(math.sqrt(sum(x * x for x in ses)) / len(ses))
        return leading_floor(closed, closed_se, measured=measured, measured_se=measured_se)

    def _stored_floor(self, label: str, spp: int, scene: str, metric: str) -> tuple[float | None, float | None]:
        """(floor, ref_se) stored with the metric (closed form, or measured where there is none)."""
        name = self.per_frame_name(metric)
        if name is None:
            rows = self._sequences.get((label, spp, scene, metric), [])
            floors, ses = finite_values(r.floor for r in rows), finite_values(r.ref_se for r in rows)
        else:
            frames = kept_frames(self.ok_frames(label, spp, scene), name)
            floors = finite_values(f.floors.get(name) for f in frames)
            ses = finite_values(f.ref_se.get(name) for f in frames)
            if len(floors) != len(frames):
                floors = []
            ses = ses if len(ses) == len(frames) else []
        floor = finite_mean(floors)
        se = float(math.sqrt(sum(x * x for x in ses)) / len(ses)) if ses else None
        return floor, se

    def per_scene(self, label: str, spp: int, metric: str, scenes=None) -> tuple[dict, dict, dict]:
        """({scene: value}, {scene: floor}, {scene: ref_se}) over ``scenes`` (default: every scene)."""
        values, floors, ses = {}, {}, {}
        for scene in self.scenes if scenes is None else scenes:
            value = self.scene_value(label, spp, scene, metric=metric)
            if value is None:
                continue
            values[scene] = value
            floor, se = self.scene_floor(label, spp, scene, metric=metric)
            if floor is not None:
                floors[scene] = floor
            if se is not None:
                ses[scene] = se
        return values, floors, ses
