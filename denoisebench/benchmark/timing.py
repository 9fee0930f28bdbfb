"""Timing a run's denoisers and its renderer at a second, larger size (what the time model projects from).

After the run each denoiser is called again on its frame tiled up to ``--time-size``
(:func:`upscaled_frame`, :func:`time_call`) at the ladder's lowest spp, and once more at its highest
spp when the run's own seconds per frame there differ by more than the spread (the record's
``highest``): a per-sample filter grows with spp, and a filter that estimates the variance a 1-spp
frame lacks does more per pixel at 1 spp (cross_bilateral on the demo's cluttered_915: 236 ms at 512×512
and 1 spp, 90 ms at 16 spp). The dataset's first stage is rendered at the
dataset's size and at ``--time-size`` (:func:`probe_render`); the records go to the store
(:mod:`denoisebench.results.timings`) and :mod:`denoisebench.analysis.time_model` reads them.

Notes
-----
* **Time budget.** A denoiser whose proportional estimate at the timing size exceeds ``budget``
  seconds is timed at the largest size that fits (at least :data:`MIN_SIZE_FACTOR` × the frame), or
  not at all; the record says which size was used. The timing call is made after ``reset()`` and
  followed by one, so that a temporal denoiser neither sees a frame of another size as its history
  nor keeps it.
* **Times on a busy machine.** Other processes only ever add time, so each cost is the least of
  repeated measurements, and its spread (median over least, at least
  :data:`~denoisebench.results.timings.MIN_SPREAD`) is recorded beside it: the render probe renders
  the stage at both sizes in turn (:data:`PROBE_REPEATS` rounds, interleaved, so that both sizes see
  the same load), and each denoiser's timing call is repeated (:data:`TIMING_REPEATS`).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
from tqdm import tqdm

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.runner import run_frame
from denoisebench.results.timings import (
    MIN_SPREAD,
    PROBE_REPEATS,
    TIMING_REPEATS,
    machine,
    read_timings,
    write_timing,
)

# Lazy imports: frame_jobs' render_job looked up when a render is timed (tests replace it on its module).

#: The second size each denoiser (and the render probe) is timed at unless ``--time-size`` says otherwise.
DEFAULT_TIME_SIZE = (1024, 1024)
#: Seconds one denoiser's timing call may be expected to take before its size is reduced.
DEFAULT_TIME_BUDGET = 60.0
#: Spp of the render probe (two, so that its offset and per-sample cost separate).
PROBE_SPP = (1, 4)
#: The smallest timing size, as a multiple of the dataset's pixels, that still separates the costs.
MIN_SIZE_FACTOR = 4


def upscaled_frame(frame, width: int, height: int):
    """A synthetic ``width``×``height`` frame: ``frame``'s buffers (and per-sample data) tiled, then cropped.

    Only for timing: the content repeats, which no denoiser's cost depends on in a way that matters
    here (the cost of a call grows with pixels and samples, not with what they show)."""

    def tile(array: np.ndarray, axes: tuple[int, int]) -> np.ndarray:
        reps = [1] * array.ndim
        reps[axes[0]] = math.ceil(height / array.shape[axes[0]])
        reps[axes[1]] = math.ceil(width / array.shape[axes[1]])
        out = np.tile(array, reps)
        index = [slice(None)] * array.ndim
        index[axes[0]], index[axes[1]] = slice(0, height), slice(0, width)
        return np.ascontiguousarray(out[tuple(index)])

    buffers = {name: tile(array, (0, 1)) for name, array in frame.buffers.items()}
    samples = None if frame.samples is None else {name: tile(a, (1, 2)) for name, a in frame.samples.items()}
    return Frame(
        buffers, frame.spp, frame.scene, index=frame.index, reference=None, samples=samples, meta=dict(frame.meta)
    )


def timing_size(small_seconds: float, pixels0: int, requested: tuple[int, int], budget: float):
    """(width, height, note) to time a denoiser at: ``requested``, or smaller to fit ``budget``, or None."""
    width, height = requested
    estimate = small_seconds * width * height / pixels0  # proportional: an upper bound when fixed ≥ 0
    if estimate <= budget:
        return width, height, ""
    scale = math.sqrt(budget / estimate)
    width, height = max(int(width * scale), 1), max(int(height * scale), 1)
    if width * height < MIN_SIZE_FACTOR * pixels0:
        return None
    return width, height, f"timed at {width}×{height}, not {requested[0]}×{requested[1]}, to stay within {budget:g} s"


def _changes_with_spp(lowest: list[float], highest: list[float]) -> bool:
    """True when a denoiser's median seconds per frame at the ladder's highest spp differ from those at its lowest
    by more than :data:`MIN_SPREAD` either way: its cost depends on the input (per-sample filters grow with spp;
    a filter that estimates variance itself where a 1-spp frame has none shrinks after 1 spp)."""
    low, high = float(np.median(lowest)), float(np.median(highest))
    return low > 0 and high > 0 and max(low / high, high / low) > MIN_SPREAD


def time_call(denoiser, frame, label: str, repeats: int = TIMING_REPEATS) -> tuple[float | None, str, float]:
    """(least seconds of up to ``repeats`` calls on ``frame``, why not, spread = median / least).

    One call only when it takes over 2 s (the spread is then :data:`MIN_SPREAD`); (None, why, nan) when
    a call fails."""
    times = []
    for _ in range(repeats):
        reset = getattr(denoiser, "reset", None)
        if callable(reset):
            reset()
        result = run_frame(denoiser, frame, name=label, keep_output=False)
        if callable(reset):
            reset()
        if result.status != "ok":
            return None, f"timing call failed: {result.error}", math.nan
        times.append(result.seconds)
        if result.seconds > 2.0:
            break
    best = min(times)
    spread = float(np.median(times) / best) if best > 0 and len(times) > 1 else MIN_SPREAD
    return best, "", max(spread, MIN_SPREAD)


def probe_render(dataset, scene: str, size: tuple[int, int], spp=PROBE_SPP, repeats: int = PROBE_REPEATS) -> dict:
    """Renders of ``scene``'s frame 0 at the dataset's size and at ``size``, up to each of ``spp``.

    Returns {"points": [[spp, seconds]] at ``size``, "small_points": the same at the dataset's size,
    "spread": median / least over every point, "repeats"}. Seconds exclude kernel compilation, like
    the dataset's own (the generator's timer). The first render at each size is a warm-up and is not
    timed: at a size no dataset frame had, it traces and records the frozen passes (measured on the
    demo's cluttered_915 at 512×512: 1.30 s to reach 1 spp against 0.43-0.44 s warm), which the
    dataset's own frames pay once per sequence, not per frame. Then ``repeats`` rounds, each one render
    at each size in turn (interleaved: both sizes see the same load), and each point keeps the least
    of its renders (other processes on a shared machine only ever add time; module Notes)."""
    from denoisebench.generator.frame_jobs import FrameJob, render_job

    info = dataset.scene(scene)
    record = info.record
    plan = record.get("plan") or {}
    options = {"per_sample": bool(plan.get("per_sample", False)), "rr_depth": int(plan.get("rr_depth", 5))}
    if plan.get("max_depth_source") == "user":
        options["max_depth"] = int(plan.get("max_depth", -1))
    usd = dataset.path(record["usd"], "stage file")
    small = (int(record["width"]), int(record["height"]))

    def job(width: int, height: int):
        return FrameJob(
            scene,
            0,
            str(record.get("stage_sha256", scene)),
            usd_path=str(usd),
            spp=tuple(int(s) for s in spp),
            ref_spp=None,
            width=width,
            height=height,
            render_seed=int(record.get("render_seed", 0)),
            options=options,
        )

    jobs = {"small": job(*small), "large": job(int(size[0]), int(size[1]))}
    for j in jobs.values():
        render_job(j)  # warm-up: trace and record the passes at this size
    timed: dict[str, list] = {"small": [], "large": []}
    for _ in range(max(int(repeats), 1)):
        for key, j in jobs.items():
            timed[key].append([rung.seconds for rung in render_job(j).noisy])
    spreads = []

    def points(key: str) -> list[list[float]]:
        out = []
        for k, s in enumerate(spp):
            seconds = [run[k] for run in timed[key]]
            least = min(seconds)
            if least > 0:
                spreads.append(float(np.median(seconds)) / least)
            out.append([int(s), least])
        return out

    return {
        "scene": scene,
        "width": int(size[0]),
        "height": int(size[1]),
        "points": points("large"),
        "small_points": points("small"),
        "small_pixels": small[0] * small[1],
        "repeats": max(int(repeats), 1),
        "spread": max(max(spreads, default=MIN_SPREAD), MIN_SPREAD),
        "seconds": timed,
    }


def measure_run_timings(
    store,
    dataset,
    plan,
    instances: dict,
    size: tuple[int, int] | None = DEFAULT_TIME_SIZE,
    *,
    budget: float = DEFAULT_TIME_BUDGET,
    render_probe: bool = True,
    progress: bool = True,
) -> dict[str, dict]:
    """Time every loaded denoiser (and one render) at ``size`` once per run; return the run's timings.

    ``size`` None: nothing is timed (the report's times stay at the dataset's resolution)."""
    done = read_timings(store, plan.run_id)
    if "machine" not in done:
        write_timing(store, plan.run_id, "machine", value=machine())
    if size is None or not plan.scenes or not plan.spp:
        return read_timings(store, plan.run_id)
    scene, spp, highest = plan.scenes[0], min(plan.spp), max(plan.spp)
    info = dataset.scene(scene)
    pixels0 = int(info.record["width"]) * int(info.record["height"])
    frames = store.frames(plan.run_id)
    todo = [label for label in instances if f"denoiser:{label}" not in done]
    wants_probe = render_probe and "render_probe" not in done
    bar = tqdm(
        total=len(todo) + wants_probe, desc="benchmark: timing at a larger size", file=sys.stderr, disable=not progress
    )
    needs_samples = any("samples" in getattr(d, "needs", ()) for d in plan.denoisers if d.label in todo)
    small_frames = {}  # spp -> the scene's frame 0 at that spp, read once

    def run_seconds(label: str, at: int) -> list[float]:
        return [
            f.denoise_seconds for f in frames if f.denoiser == label and f.spp == at and f.denoise_seconds is not None
        ]

    def timed(label: str, at: int, measured: list[float]) -> dict:
        """One timing at the larger size on frame 0 at ``at`` spp, as the record's fields."""
        chosen = timing_size(float(np.mean(measured)), pixels0, size, budget=budget)
        if chosen is None:
            return {"seconds": None, "note": f"not timed at a larger size: over {budget:g} s even at 4× the frame"}
        if at not in small_frames:
            small_frames[at] = dataset.frame(scene, at, 0, samples=needs_samples)
        width, height, note = chosen
        started = time.perf_counter()
        seconds, error, spread = time_call(instances[label], upscaled_frame(small_frames[at], width, height), label)
        fields = {"width": width, "height": height, "seconds": seconds, "note": error or note}
        if math.isfinite(spread):
            fields["spread"] = spread
        fields["wall_seconds"] = time.perf_counter() - started
        return fields

    for label in todo:
        measured = run_seconds(label, spp)
        record = {"spp": spp, "scene": scene}
        if not measured:  # every unit failed (or none ran): a timing call would only fail or hang again
            record.update(seconds=None, note="not timed at a larger size: no successful frame in the run")
        else:
            record.update(timed(label, spp, measured))
            at_highest = run_seconds(label, highest)
            if record["seconds"] is not None and at_highest and _changes_with_spp(measured, at_highest):
                record["highest"] = {"spp": highest, **timed(label, highest, at_highest)}
        write_timing(store, plan.run_id, f"denoiser:{label}", value=record)
        bar.update(1)
    if wants_probe:
        try:
            record = probe_render(dataset, scene, size)
        except Exception as error:  # noqa: BLE001 - no renderer here, or a stage it cannot load: say so
            record = {"error": f"render probe failed: {type(error).__name__}: {error}".splitlines()[0][:300]}
        write_timing(store, plan.run_id, "render_probe", value=record)
        bar.update(1)
    bar.close()
    return read_timings(store, plan.run_id)
