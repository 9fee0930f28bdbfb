"""One unit measured: one denoiser (or the noisy input) on one scene's sequence at one spp.

:func:`measure_unit` runs the denoiser through :func:`denoisebench.denoisers.runner.run_sequence`
(``reset()`` first, then the frames in order, every call timed, every output checked, failures
contained), computes every per-frame metric (with its floor: closed-form, or measured from the
reference's two halves; a closed-form floor also gets the measured one beside it, as the frame value
``floor_measured.<name>``, per pair for the flicker scores) and the temporal ones over the sequence
and its consecutive pairs, and
returns the :class:`~denoisebench.results.records.UnitRecord` the store keeps. The runner
(:mod:`.runner`) and the live sampler pairs (:mod:`.sampler_units`) both measure through it.

Notes
-----
* **Time.** ``total_seconds`` of a frame = the generator's render time at that spp + the measured
  ``denoise()`` time (:func:`denoisebench.metrics.cost.total_seconds`); the noisy input's denoise
  time is 0 and its image is the color buffer after the harness's NaN/Inf sanitising.
* **A metric that does not apply** (``MetricNotApplicable``, e.g. SSIM under 11×11 px) is recorded
  with its reason; a metric that refuses an output (``ValueError``) fails the frame.
* **Argument order.** The reference's per-pixel variance comes before the robust scores' trim
  everywhere (``ref_var``/``ref_vars``, then ``trim``); both are passed by keyword.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from denoisebench.denoisers.runner import run_sequence, sanitize_array
from denoisebench.metrics import compute_metrics
from denoisebench.metrics.cost import total_seconds
from denoisebench.metrics.floors.half_reference import half_reference_floor, other_half
from denoisebench.metrics.registry import get_metric
from denoisebench.metrics.validation import MetricNotApplicable
from denoisebench.results.crops import cut
from denoisebench.results.finite import is_finite
from denoisebench.results.names import DECIDING_SCORES, FLICKER_METRICS, FLICKER_PREFIX, MEASURED_FLOOR_PREFIX
from denoisebench.results.records import FrameRecord, UnitRecord


def _split_results(results) -> tuple[dict[str, float], dict[str, float], dict[str, float]]:
    """(values, floors, ref_se) of compute_metrics results; floors only where the metric has one."""
    values = {name: r.value for name, r in results.items()}
    floors = {name: r.floor for name, r in results.items() if r.floor is not None}
    ses = {name: r.ref_se for name, r in results.items() if r.ref_se is not None}
    return values, floors, ses


def _applicable(compute: Callable[[list[str]], dict], names: list[str]) -> tuple[dict, dict[str, str]]:
    """``compute(names)``, and when a metric's precondition fails (MetricNotApplicable, e.g. SSIM on
    frames under 11×11 px), each metric on its own: (results of those that apply, {name: reason})."""
    try:
        return compute(names), {}
    except MetricNotApplicable:
        pass
    results: dict = {}
    skipped: dict[str, str] = {}
    for name in names:
        try:
            results.update(compute([name]))
        except MetricNotApplicable as exc:
            skipped[name] = str(exc)
    return results, skipped


def _frame_metrics(pred: np.ndarray, ref: np.ndarray, names: list[str], *, ref_var=None, trim=None, halves=None):
    """(values, floors, ref_se, not applicable {name: reason}) of the per-frame metrics.

    ``halves`` (:func:`_reference_halves`): the reference's two halves and their spp; the metrics
    without a closed-form floor then get the floor measured from them (:mod:`denoisebench.metrics.floors.half_reference`)."""
    results, skipped = _applicable(lambda chosen: compute_metrics(pred, ref, chosen, ref_var=ref_var, trim=trim), names)
    values, floors, ses = _split_results(results)
    if halves is not None:
        (half_a, half_b), full_spp, half_spp = halves
        scored = [n for n in values if math.isfinite(values[n])]
        if scored:
            against = (
                compute_metrics(pred, half_a, scored, trim=trim),
                compute_metrics(pred, half_b, scored, trim=trim),
            )
            _measured_floors((values, floors, ses), against, (full_spp, half_spp))
    return values, floors, ses, skipped


def _measured_floors(scores: tuple[dict, dict, dict], against: tuple[dict, dict], spp: tuple) -> None:
    """Each finite score's floor measured from the reference's halves (:mod:`denoisebench.metrics.floors.half_reference`).

    ``scores``: (values, floors, ses) as stored, filled in place; ``against``: the results against half a
    and half b; ``spp``: (full spp, (spp a, spp b)). A score with a closed-form floor keeps the measured
    one beside it (``floor_measured.<name>`` among the values, its se among the ses: the analyses choose
    which leads); one without has it as its floor."""
    values, floors, ses = scores
    against_a, against_b = against
    full_spp, half_spp = spp
    for name in [n for n in values if n in against_a and n in against_b and math.isfinite(values[n])]:
        measured = half_reference_floor(
            values[name], (against_a[name].value, against_b[name].value), full_spp, half_spp=half_spp
        )
        if not (math.isfinite(measured.floor) and math.isfinite(measured.se)):
            continue
        if name in floors:
            values[MEASURED_FLOOR_PREFIX + name], ses[MEASURED_FLOOR_PREFIX + name] = measured.floor, measured.se
        else:
            floors[name], ses[name] = measured.floor, measured.se


def _reference_halves(frame):
    """((half a, half b), full spp, (spp a, spp b)) of the frame's reference, or None without halves."""
    meta = frame.meta if isinstance(frame.meta, dict) else {}
    half = meta.get("reference_buffers", {}).get("color_half")
    half_spp, full_spp = meta.get("reference_half_spp"), meta.get("reference_spp")
    if half is None or not half_spp or not full_spp or frame.reference is None:
        return None
    if np.shape(half) != np.shape(frame.reference) or sum(half_spp) != int(full_spp):
        return None
    other = other_half(frame.reference, half, int(full_spp), half_spp=tuple(half_spp))
    return (np.asarray(half, np.float32), other.astype(np.float32)), int(full_spp), tuple(int(s) for s in half_spp)


def _sequence_metrics(outputs, refs, motion, *, names: list[str], ref_vars=None, trim=None):
    """(values, floors, ref_se, not applicable {name: reason}) of the temporal metrics ``names`` over
    the whole sequence (those needing motion only when it is given)."""
    usable = [n for n in names if "motion" not in get_metric(n).requires or motion is not None]
    if len(outputs) < 2 or not usable:
        return {}, {}, {}, {}
    ref_var = None if ref_vars is None else np.stack(ref_vars)
    pred, ref = np.stack(outputs), np.stack(refs)
    results, skipped = _applicable(
        lambda chosen: compute_metrics(pred, ref, chosen, motion=motion, ref_var=ref_var, trim=trim), usable
    )
    return (*_split_results(results), skipped)


def _flicker(outputs, refs, motion=None, *, ref_vars=None, trim=None, halves=None) -> list[tuple[dict, dict, dict]]:
    """FLICKER_METRICS of each consecutive pair: (values, floors, ref_se) of frame t against frame t−1,
    named ``flicker.<metric>``. The scene's temporal score is their trimmed mean over pairs
    (:mod:`denoisebench.analysis.run_index`), so one pair cannot decide it; the floors correct it.
    ``halves``: each frame's :func:`_reference_halves` (or None); with both frames' halves a pair's
    floored scores also get their floor measured (:func:`_pair_halves`, :func:`_measured_floors`)."""
    out = []
    for t in range(1, len(outputs)):
        pair_motion = None if motion is None else motion[t - 1 : t + 1]
        pair_var = None if ref_vars is None else np.stack(ref_vars[t - 1 : t + 1])
        pred = np.stack(outputs[t - 1 : t + 1])

        def score(ref, var=None, pred=pred, pair_motion=pair_motion):
            return compute_metrics(pred, ref, list(FLICKER_METRICS), motion=pair_motion, ref_var=var, trim=trim)

        values, floors, ses = _split_results(score(np.stack(refs[t - 1 : t + 1]), pair_var))
        pair = None if halves is None else _pair_halves(halves, t)
        if pair is not None:
            (half_a, half_b), full_spp, half_spp = pair
            closed = {n: v for n, v in values.items() if n in floors}  # only floored scores: tpsnr has none
            _measured_floors((closed, floors, ses), (score(half_a), score(half_b)), (full_spp, half_spp))
            values.update(closed)
        out.append(tuple({_flicker_name(k): v for k, v in part.items()} for part in (values, floors, ses)))
    return out


def _flicker_name(name: str) -> str:
    """``flicker.<metric>``, and ``floor_measured.flicker.<metric>`` for a measured floor."""
    if name.startswith(MEASURED_FLOOR_PREFIX):
        return MEASURED_FLOOR_PREFIX + FLICKER_PREFIX + name[len(MEASURED_FLOOR_PREFIX) :]
    return FLICKER_PREFIX + name


def _pair_halves(halves: list, t: int):
    """((half a of frames t−1 and t, half b of them), full spp, (spp a, spp b)) of a pair, or None.

    A pair's score carries both frames' reference noise; an adaptive reference's frames have different
    spp, so the pair's are the harmonic means of the two frames' (a mean's noise variance falls as
    1/spp, and the pair's as the mean of the two frames' 1/spp)."""
    before, now = halves[t - 1], halves[t]
    if before is None or now is None:
        return None
    (a0, b0), n0, (na0, nb0) = before
    (a1, b1), n1, (na1, nb1) = now

    def harmonic(x, y):
        return 2.0 / (1.0 / x + 1.0 / y)

    return (np.stack([a0, a1]), np.stack([b0, b1])), harmonic(n0, n1), (harmonic(na0, na1), harmonic(nb0, nb1))


def _reference_variance(frame) -> np.ndarray | None:
    """The reference's per-pixel variance of the mean (``color_var`` of the reference file), or None."""
    var = frame.meta.get("reference_buffers", {}).get("color_var") if isinstance(frame.meta, dict) else None
    if var is None or frame.reference is None or np.shape(var)[:2] != frame.reference.shape[:2]:
        return None
    return np.asarray(var, dtype=np.float32)


def kept_images(records: list[FrameRecord], outputs: list[np.ndarray]) -> dict[int, np.ndarray]:
    """The outputs a unit keeps for reports ({frame: image}): its last frame, and for each of
    :data:`DECIDING_SCORES` (the first alternative measured) the frame it scores worst, the one that
    would decide a plain mean. ``records`` and ``outputs`` are the unit's frames, all successful, in order."""
    kept = {records[-1].frame: outputs[-1]}
    for alternatives in DECIDING_SCORES:
        name = next((n for n in alternatives if all(is_finite(r.metrics.get(n)) for r in records)), None)
        if name is None:
            continue
        worse = min if get_metric(name).higher_is_better else max
        k = worse(range(len(records)), key=lambda i: records[i].metrics[name])
        kept.setdefault(records[k].frame, outputs[k])
    return kept


def measure_unit(
    label: str, denoiser: object | None, sequence, *, spatial: list[str], temporal: list[str], trim: float | None = None
) -> UnitRecord:
    """Run one denoiser (None: the noisy input) on ``sequence`` and measure every frame.

    ``trim``: the robust scores' dropped fraction (None: their default, :mod:`denoisebench.metrics.ours.robust`)."""
    frames = list(sequence)
    if denoiser is None:
        results = [(True, None, 0.0, sanitize_array(f.color)[0].astype(np.float32), 0) for f in frames]
    else:
        results = [
            (r.ok, r.error, r.seconds, r.output, r.sanitized_total)
            for r in run_sequence(denoiser, frames, name=label, keep_output=True)
        ]
    records: list[FrameRecord] = []
    outputs: list[np.ndarray] = []
    for frame, (ok, error, seconds, output, sanitized) in zip(frames, results):
        render = frame.meta.get("seconds")
        total = None
        if render is not None and seconds is not None:
            total = total_seconds(float(render) / frame.spp, frame.spp, float(seconds))
        record = FrameRecord(
            frame=frame.index,
            status="ok" if ok else "failed",
            error=error,
            render_seconds=render,
            denoise_seconds=seconds,
            total_seconds=total,
            sanitized=sanitized,
        )
        if ok:
            try:
                record.metrics, record.floors, record.ref_se, record.not_applicable = _frame_metrics(
                    output,
                    frame.reference,
                    spatial,
                    ref_var=_reference_variance(frame),
                    trim=trim,
                    halves=_reference_halves(frame),
                )
            except ValueError as exc:  # a metric refusing this output is the denoiser's failure
                record.status, record.error, ok = "failed", f"metrics: {exc}", False
        if ok:
            outputs.append(output)
        records.append(record)
    all_ok = all(r.status == "ok" for r in records)
    unit = UnitRecord(
        denoiser=label,
        scene=sequence.scene,
        spp=sequence.spp,
        status="ok" if all_ok else "failed",
        error=None,
        frames=records,
    )
    if not all_ok:
        unit.error = next(r.error for r in records if r.status != "ok")
        return unit
    refs = [f.reference for f in frames]
    motion = np.stack([f.buffers["motion"] for f in frames]) if all(f.has("motion") for f in frames) else None
    ref_vars = [_reference_variance(f) for f in frames]
    ref_vars = None if any(v is None for v in ref_vars) else ref_vars
    unit.sequence_metrics, unit.sequence_floors, unit.sequence_ref_se, unit.sequence_not_applicable = _sequence_metrics(
        outputs, refs, motion, names=temporal, ref_vars=ref_vars, trim=trim
    )
    unit.images = kept_images(records, outputs)
    if len(outputs) > 1:
        halves = [_reference_halves(f) for f in frames]
        for record, (values, floors, ses) in zip(
            records[1:], _flicker(outputs, refs, motion, ref_vars=ref_vars, trim=trim, halves=halves)
        ):
            record.metrics.update(values)
            record.floors.update(floors)
            record.ref_se.update(ses)

        first, unit.strip_window, unit.strip = cut(outputs, [f.color for f in frames], refs, motion=motion)
        unit.strip_first = frames[first].index
    return unit
