"""Timing a run's denoisers and its renderer at a second, larger size (what the time model projects from).

After the run each denoiser is called again on its frame tiled up to the timing size
(:func:`upscaled_frame`, :func:`time_call`) at the ladder's lowest spp, and once more at its highest
spp when the run's own seconds per frame there differ by more than the spread (the record's
``highest``): a per-sample filter grows with spp, and a filter that estimates the variance a 1-spp
frame lacks does more per pixel at 1 spp (cross_bilateral on the demo's cluttered_915: 236 ms at 512×512
and 1 spp, 90 ms at 16 spp). The dataset's first stage is rendered at the dataset's size and at the
timing size once for every **buffer set** the run pays for (:func:`probe_render`): colour alone (what
rendering more samples without a denoiser renders) and the buffers each denoiser reads
(:func:`render_buffers`). The records go to the store (:mod:`denoisebench.results.timings`) and
:mod:`denoisebench.analysis.time_model` reads them.

Notes
-----
* **Timing size.** ``--time-size auto`` (the default, :func:`auto_time_size`) is
  :data:`AUTO_SIDE_FACTOR` times the dataset frame's width and height (64 times its pixels), at most
  :data:`DEFAULT_TIME_SIZE`: enough pixels that the per-pixel part of a cost is most of it, and no more
  (a 32-px dataset is timed at 256×256 instead of 1 MP; its timing stage took about 20 s at 1 MP,
  almost all of it the render probe). The size used is recorded (key ``timing``) and the report states it.
* **Buffer sets.** A render gives colour with its diffuse/specular split and their variances
  (:data:`~denoisebench.results.timings.COLOUR_ONLY`) whatever else it makes; a denoiser is charged a
  render of those plus the features it reads (``needs``, and ``uses`` for a built-in that reads some
  buffers only when present: OIDN's albedo and normal, cross_bilateral's features), in the dataset's
  plan order, and with every feature and the per-sample data when it reads ``samples``. Each set is
  rendered with the dataset's plan restricted to its features (:func:`plan_for`), so it costs what a
  dataset of those buffers would. An isolated plugin is charged for what it declares in ``needs``.
* **Time budget.** A denoiser whose proportional estimate at the timing size exceeds ``budget``
  seconds is timed at the largest size that fits (at least :data:`MIN_SIZE_FACTOR` × the frame), or
  not at all; the record says which size was used. The timing call is made after ``reset()`` and
  followed by one, so that a temporal denoiser neither sees a frame of another size as its history
  nor keeps it.
* **Times on a busy machine.** Other processes only ever add time, so each cost is the least of
  repeated measurements, and its spread (median over least, at least
  :data:`~denoisebench.results.timings.MIN_SPREAD`) is recorded beside it: the render probe renders
  every buffer set at both sizes in turn (:data:`PROBE_REPEATS` rounds, interleaved, so that every
  set and size sees the same load), and each denoiser's timing call is repeated
  (:data:`TIMING_REPEATS`).
* **Resuming.** Records are kept per run: a resumed run times only the denoisers without a record,
  and renders only the buffer sets its probe record lacks.
"""

from __future__ import annotations

import math
import sys
import time
from collections import OrderedDict
from dataclasses import replace

import numpy as np
from tqdm import tqdm

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.runner import run_frame
from denoisebench.results.timings import (
    COLOUR_ONLY,
    MIN_SPREAD,
    PROBE_REPEATS,
    SAMPLES,
    TIMING_REPEATS,
    machine,
    read_timings,
    write_timing,
)

# Lazy imports: the generator (stage loading, render plan, renderer) only when a render is timed.

#: The largest size ``--time-size auto`` times at, and the size a denoiser is timed at when none is given.
DEFAULT_TIME_SIZE = (1024, 1024)
#: ``--time-size auto``: each side of the timing size as a multiple of the dataset frame's (64 × its pixels).
AUTO_SIDE_FACTOR = 8
#: The ``--time-size`` value that picks the size from the dataset's (:func:`auto_time_size`).
AUTO = "auto"
#: Seconds one denoiser's timing call may be expected to take before its size is reduced.
DEFAULT_TIME_BUDGET = 60.0
#: Spp of the render probe: two far enough apart that the per-sample cost is not lost in the 1-spp render's
#: own scatter. With 1 and 4 on the demo's cluttered_915 at 512×512 (quiet cores) the 1-spp point read
#: 0.040-0.108 s from run to run against 0.135 s at 4 spp, so the per-spp slope came out 0.023-0.074 s per
#: megapixel per spp; a 16-spp render (0.508 s) pins it at 0.118.
PROBE_SPP = (1, 16)
#: The smallest timing size, as a multiple of the dataset's pixels, that still separates the costs.
MIN_SIZE_FACTOR = 4


def auto_time_size(width: int, height: int, cap: tuple[int, int] = DEFAULT_TIME_SIZE) -> tuple[int, int]:
    """The timing size ``--time-size auto`` picks for ``width``×``height`` frames: :data:`AUTO_SIDE_FACTOR` × each
    side, scaled down (aspect kept) to at most ``cap``'s pixels, and at least :data:`MIN_SIZE_FACTOR` × the frame's
    pixels (a frame already larger than ``cap`` is timed at twice its sides)."""
    w, h = int(width) * AUTO_SIDE_FACTOR, int(height) * AUTO_SIDE_FACTOR
    limit = max(cap[0] * cap[1], MIN_SIZE_FACTOR * int(width) * int(height))
    if w * h > limit:
        scale = math.sqrt(limit / (w * h))
        w, h = max(int(w * scale), 1), max(int(h * scale), 1)
    return w, h


def render_buffers(reads, features, per_sample: bool) -> tuple[str, ...]:
    """The buffer set a denoiser that reads ``reads`` (buffer names; ``_var`` names count as their buffer) is
    charged a render of, on a dataset whose plan makes ``features`` (and per-sample data with ``per_sample``).

    :data:`COLOUR_ONLY` (every render makes it), then the features it reads in the plan's order; a reader of
    ``samples`` on a dataset that has them gets every feature and :data:`SAMPLES` (per-sample data holds the
    features per sample). Rendering alone is charged :data:`COLOUR_ONLY`."""
    names = {str(name).removesuffix("_var") for name in reads}
    features = tuple(str(f) for f in features)
    if SAMPLES in names and per_sample:
        return (*COLOUR_ONLY, *features, SAMPLES)
    return (*COLOUR_ONLY, *(f for f in features if f in names))


def denoiser_reads(needs, instance) -> frozenset[str]:
    """The buffers a denoiser reads: its ``needs``, and its ``uses`` when it declares one (a built-in that reads
    some buffers only when the frame has them, e.g. OIDN's albedo and normal). A malformed ``uses`` counts as
    none (it is not part of the protocol a plugin is checked against)."""
    uses = getattr(instance, "uses", None) or ()
    if isinstance(uses, str) or not all(isinstance(u, str) for u in uses):
        uses = ()
    return frozenset(str(n) for n in needs) | frozenset(uses)


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


def plan_for(plan, buffers):
    """The dataset's render ``plan`` restricted to the buffer set ``buffers`` (:func:`render_buffers`): its
    features that the set names, per-sample data only when the set holds :data:`SAMPLES`."""
    features = tuple(f for f in plan.features if f in buffers)
    return replace(plan, features=features, per_sample=bool(plan.per_sample) and SAMPLES in buffers)


def render_rungs(scene, camera, plan, *, width: int, height: int, spp, seed: int) -> tuple[list[float], list[str]]:
    """(seconds to reach each rung of ``spp``, names of the buffers made) of one progressive render of frame 0.

    Seconds exclude kernel compilation, like the dataset's own (the generator's clock). The one place the
    probe renders: a test plants a cost law here."""
    from denoisebench.generator.render.frame import render_ladder
    from denoisebench.generator.render.progressive import RenderClock

    clock = RenderClock()
    rungs = render_ladder(scene, camera, 0, plan=plan, width=width, height=height, rungs=spp, seed=seed, clock=clock)
    made = sorted(set(rungs[-1].buffers)) + ([SAMPLES] if rungs[-1].samples else [])
    return [rung.seconds for rung in rungs], made


def probe_render(
    dataset, scene: str, size: tuple[int, int], *, buffer_sets, spp=PROBE_SPP, repeats: int = PROBE_REPEATS
) -> dict:
    """Renders of ``scene``'s frame 0 at the dataset's size and at ``size``, one at each of ``spp``, for each
    buffer set of ``buffer_sets`` (:func:`render_buffers`; the dataset's plan restricted to it, :func:`plan_for`).

    Returns {"scene", "width", "height", "small_pixels", "repeats", "lines": one per set, {"buffers": the set,
    "made": the buffer names the render made, "points": [[spp, seconds]] at ``size``, "small_points": the
    same at the dataset's size, "spread": median / least over its points, "seconds": every timed render}}.

    Each spp is a render of its own, not a rung of one ladder: a rung's seconds is the time to reach it, and
    the ladder traces the next rung's samples while the host assembles this one's buffers, so its rungs at 1
    and 4 spp were within 4 % of each other (cornell at 256×256: 0.584 and 0.586 s; cluttered_915 at 512×512:
    1.44 and 1.49 s, where separate renders took 0.36 and 0.91-1.25 s). The first render of each set at each
    size is a warm-up and is not timed: it compiles (cold kernel cache), traces and records the frozen passes
    at that size (measured on the demo's cluttered_915 at 512×512: 1.30 s to reach 1 spp against 0.43-0.44 s
    warm), which the dataset's own frames pay once per sequence, not per frame. Then ``repeats`` rounds, each
    one render of every set at each size and spp in turn (interleaved: every set and size sees the same
    load), and each point keeps the least of its renders (other processes on a shared machine only ever add
    time; module Notes)."""
    from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
    from denoisebench.generator.dataset_scenes import load_scene_file
    from denoisebench.generator.render.scene import build_mitsuba_scene

    record = dataset.scene(scene).record
    stored = record.get("plan") or {}
    options = RenderOptions(
        max_depth=int(stored.get("max_depth", -1)) if stored.get("max_depth_source") == "user" else None,
        per_sample=bool(stored.get("per_sample", False)),
        rr_depth=int(stored.get("rr_depth", 5)),
        aperture_scale=float(stored.get("aperture_scale", 1.0)),
        shutter_scale=float(stored.get("shutter_scale", 1.0)),
    )
    translated, loaded = load_scene_file(dataset.path(record["usd"], "stage file"))
    plan = make_render_plan(translated.effects, options, stage_max_depth=translated.max_depth)
    stage = loaded if loaded is not None else build_mitsuba_scene(translated)
    seed = int(record.get("render_seed", 0))
    sizes = {"small": (int(record["width"]), int(record["height"])), "large": (int(size[0]), int(size[1]))}
    variants = {tuple(buffers): plan_for(plan, buffers) for buffers in buffer_sets}
    rounds = max(int(repeats), 1)

    def render(key: tuple, which: str, at: int) -> tuple[float, list[str]]:
        width, height = sizes[which]
        restricted, camera = variants[key], translated.camera
        seconds, made = render_rungs(stage, camera, restricted, width=width, height=height, spp=(at,), seed=seed)
        return seconds[-1], made

    made = {}
    for key in variants:
        for which in sizes:
            made[key] = render(key, which, spp[0])[1]  # warm-up: compile, trace and record the passes at this size
    timed = {key: {which: {int(s): [] for s in spp} for which in sizes} for key in variants}
    for _ in range(rounds):
        for key in variants:
            for which in sizes:
                for at in spp:
                    timed[key][which][int(at)].append(render(key, which, at)[0])

    def line(key: tuple) -> dict:
        spreads, points = [], {}
        for which in sizes:
            points[which] = []
            for at, seconds in timed[key][which].items():
                least = min(seconds)
                if least > 0:
                    spreads.append(float(np.median(seconds)) / least)
                points[which].append([at, least])
        return {
            "buffers": list(key),
            "made": made[key],
            "points": points["large"],
            "small_points": points["small"],
            "spread": max(max(spreads, default=MIN_SPREAD), MIN_SPREAD),
            "seconds": {which: {str(at): v for at, v in by_spp.items()} for which, by_spp in timed[key].items()},
        }

    return {
        "scene": scene,
        "width": sizes["large"][0],
        "height": sizes["large"][1],
        "small_pixels": sizes["small"][0] * sizes["small"][1],
        "repeats": rounds,
        "lines": [line(key) for key in variants],
    }


def _probe_todo(done: dict, needed: list[tuple], size: tuple[int, int]) -> list[tuple]:
    """The buffer sets of ``needed`` that the run's probe record (``done``'s) lacks at ``size``; none after a
    failed probe (it would only fail again)."""
    record = done.get("render_probe")
    if record is None:
        return list(needed)
    if "error" in record or "lines" not in record:  # failed, or made before render lines: kept as it is
        return []
    if (int(record["width"]), int(record["height"])) != tuple(size):
        return []
    have = {tuple(line["buffers"]) for line in record["lines"]}
    return [key for key in needed if key not in have]


def measure_run_timings(
    store,
    dataset,
    plan,
    instances: dict,
    size: tuple[int, int] | str | None = AUTO,
    *,
    budget: float = DEFAULT_TIME_BUDGET,
    render_probe: bool = True,
    progress: bool = True,
) -> dict[str, dict]:
    """Time every loaded denoiser (and one render of each buffer set the run pays for) at ``size`` once per run;
    return the run's timings.

    ``size`` :data:`AUTO`: :func:`auto_time_size` of the dataset's frames; None: nothing is timed (the report's
    times stay at the dataset's resolution)."""
    done = read_timings(store, plan.run_id)
    if "machine" not in done:
        write_timing(store, plan.run_id, "machine", value=machine())
    if size is None or not plan.scenes or not plan.spp:
        return read_timings(store, plan.run_id)
    scene, spp, highest = plan.scenes[0], min(plan.spp), max(plan.spp)
    info = dataset.scene(scene)
    width0, height0 = int(info.record["width"]), int(info.record["height"])
    pixels0 = width0 * height0
    auto = size == AUTO
    size = auto_time_size(width0, height0) if auto else (int(size[0]), int(size[1]))
    if (done.get("timing") or {}).get("width"):  # a resumed run keeps the size it was timed at
        size = (int(done["timing"]["width"]), int(done["timing"]["height"]))
    stored_plan = info.record.get("plan") or {}
    features, per_sample = tuple(stored_plan.get("features") or ()), bool(stored_plan.get("per_sample", False))
    if "timing" not in done:
        full = (*COLOUR_ONLY, *features, *((SAMPLES,) if per_sample else ()))
        fields = {"width": size[0], "height": size[1], "auto": auto, "dataset_buffers": list(full)}
        write_timing(store, plan.run_id, "timing", value=fields)
    frames = store.frames(plan.run_id)
    todo = [label for label in instances if f"denoiser:{label}" not in done]
    needs = {d.label: d.needs for d in plan.denoisers}
    charged = {
        label: render_buffers(denoiser_reads(needs.get(label, ()), instances[label]), features, per_sample)
        for label in instances
    }
    sets = [COLOUR_ONLY]
    for label in instances:
        kept = (done.get(f"denoiser:{label}") or {}).get("buffers")
        key = tuple(kept) if kept else charged[label]
        if key not in sets:
            sets.append(key)
    probe_sets = _probe_todo(done, sets, size) if render_probe else []
    bar = tqdm(
        total=len(todo) + bool(probe_sets),
        desc=f"benchmark: timing at {size[0]}×{size[1]}",
        file=sys.stderr,
        disable=not progress,
    )
    frames_read: dict[tuple[int, bool], object] = {}  # (spp, samples) -> the scene's frame 0, read once
    tiled: OrderedDict = OrderedDict()  # (spp, samples, width, height) -> its upscaled copy; the last two kept

    def run_seconds(label: str, at: int) -> list[float]:
        return [
            f.denoise_seconds for f in frames if f.denoiser == label and f.spp == at and f.denoise_seconds is not None
        ]

    def upscaled(at: int, samples: bool, *, width: int, height: int):
        """Frame 0 at ``at`` spp tiled to ``width``×``height``, per-sample data only for a reader of them (tiled
        to 1 MP at 16 spp they are hundreds of MB that a colour filter never receives)."""
        key = (at, samples, width, height)
        if key not in tiled:
            if (at, samples) not in frames_read:
                frames_read[(at, samples)] = dataset.frame(scene, at, 0, samples=samples)
            tiled[key] = upscaled_frame(frames_read[(at, samples)], width, height)
            while len(tiled) > 2:
                tiled.popitem(last=False)
        return tiled[key]

    def timed(label: str, at: int, measured: list[float]) -> dict:
        """One timing at the larger size on frame 0 at ``at`` spp, as the record's fields."""
        chosen = timing_size(float(np.mean(measured)), pixels0, size, budget=budget)
        if chosen is None:
            return {"seconds": None, "note": f"not timed at a larger size: over {budget:g} s even at 4× the frame"}
        width, height, note = chosen
        started = time.perf_counter()
        frame = upscaled(at, SAMPLES in needs.get(label, ()), width=width, height=height)
        seconds, error, spread = time_call(instances[label], frame, label)
        fields = {"width": width, "height": height, "seconds": seconds, "note": error or note}
        if math.isfinite(spread):
            fields["spread"] = spread
        fields["wall_seconds"] = time.perf_counter() - started
        return fields

    for label in todo:
        measured = run_seconds(label, spp)
        record = {"spp": spp, "scene": scene, "buffers": list(charged[label])}
        if not measured:  # every unit failed (or none ran): a timing call would only fail or hang again
            record.update(seconds=None, note="not timed at a larger size: no successful frame in the run")
        else:
            record.update(timed(label, spp, measured))
            at_highest = run_seconds(label, highest)
            if record["seconds"] is not None and at_highest and _changes_with_spp(measured, at_highest):
                record["highest"] = {"spp": highest, **timed(label, highest, at_highest)}
        write_timing(store, plan.run_id, f"denoiser:{label}", value=record)
        bar.update(1)
    if probe_sets:
        kept = (done.get("render_probe") or {}).get("lines") or []
        try:
            record = probe_render(dataset, scene, size, buffer_sets=probe_sets)
            record["lines"] = kept + record["lines"]
        except Exception as error:  # noqa: BLE001 - no renderer here, or a stage it cannot load: say so
            record = {"error": f"render probe failed: {type(error).__name__}: {error}".splitlines()[0][:300]}
            if kept:
                record = {**done["render_probe"], "note": record["error"]}
        write_timing(store, plan.run_id, "render_probe", value=record)
        bar.update(1)
    bar.close()
    return read_timings(store, plan.run_id)
