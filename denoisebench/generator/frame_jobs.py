"""Render a scene's frames at every spp and the reference, and hand them to the dataset writer.

The unit of work is a :class:`FrameJob`: one frame of one scene, with the noisy sample counts and
the reference that are still missing. :func:`render_job` does it wherever it runs (this process,
or a Ray worker: jobs and results are plain picklable data); :func:`write_rendered` then records
the result with the :class:`~denoisebench.dataset.writer.DatasetWriter` in the driving process.

Frame ``i`` is rendered at the camera's ``i``-th time sample. Noisy renders and the reference use
the renderer's separate random streams (``reference=True``), so they never share random numbers;
the seed of every render is the scene's ``render_seed``.

Rungs (the noisy spp of a frame) are nested by default: one progressive render
(:func:`~denoisebench.generator.render.frame.render_ladder`) whose rung ``k`` is the mean of each
pixel's first ``k`` samples, so a ladder costs what its top rung costs and a rung is the same bytes
as a plain render at that spp; a rung's seconds is the time the render took to reach it. A frame
whose rungs are partly written renders again up to its highest missing rung and writes the missing
ones (the same bytes whichever rungs are asked for). With ``independent_rungs``
(``--independent-rungs``) every rung is a render of its own, seeded by :func:`independent_rung_seed`,
for users who need uncorrelated inputs. The same job gives bit-identical buffers
in any process, which is what makes resuming and the Ray executor byte-identical to a plain run.

References: with ``ref_error`` (``--ref-error``) a frame's reference is adaptive
(:mod:`~denoisebench.generator.render.reference`): rounds with fresh, deterministic seeds until its
estimated noise floor is at most ``ref_error``, with ``ref_spp`` as the cap; the manifest records
the spp used, the seconds and the floor (``reference_adaptive``). Without it, one render at
``ref_spp``. Either way the plan comes from the job's options and the stage's own ``maxDepth``.

Notes:
    Render seconds go into the manifest as the time axis of later comparisons, so they must not
    include Dr.Jit's kernel compilation, which happens the first time a process meets a kernel
    (a new scene, sample count, image size or frame kind) and can take seconds where rendering
    takes milliseconds. Dr.Jit's own kernel history (``JitFlag.KernelHistory``) reports the LLVM
    compile time of every launch; :func:`_timed_render` and :func:`_timed_ladder` subtract it
    (:class:`~denoisebench.generator.render.progressive.RenderClock`, read at every rung), and
    record it apart as ``jit_compile_seconds`` (for a ladder: the whole render's, on every rung).
    What remains is tracing plus execution, what a warm renderer costs.
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import struct
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from denoisebench.dataset import layout
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.contract.scene_parts import MeshShape
from denoisebench.generator.dataset_scenes import load_scene_file
from denoisebench.generator.render.frame import render_frame, render_ladder
from denoisebench.generator.render.progressive import RenderClock
from denoisebench.generator.render.reference import render_adaptive, round_seed
from denoisebench.generator.render.scene import build_mitsuba_scene

#: Reference layers besides color and color_var (the renderer's reference output).
REFERENCE_EXTRA = ("diffuse", "diffuse_var", "specular", "specular_var", "color_half")


@dataclass(frozen=True)
class FrameJob:
    """Render frame ``frame`` of ``scene`` at each of ``spp`` (noisy) and at ``ref_spp`` (reference).

    ``stage_key`` is the scene's stage digest (workers cache the loaded scene under it);
    ``usd_path`` is where the stage is on the driver's disk (used when the stage files are not
    shipped with the job); ``options`` are :class:`~denoisebench.generator.contract.render_plan.RenderOptions`
    fields.
    """

    scene: str
    frame: int
    stage_key: str
    usd_path: str
    spp: tuple[int, ...]
    ref_spp: int | None
    width: int
    height: int
    render_seed: int
    options: dict = field(default_factory=dict)
    ref_error: float | None = None  # adaptive reference target (None: one render at ref_spp)
    independent_rungs: bool = False  # False: the spp are rungs of one progressive render


@dataclass
class Render:
    spp: int
    buffers: dict[str, np.ndarray]
    samples: dict[str, np.ndarray] | None
    seconds: float  # rendering, without kernel compilation
    compile_seconds: float = 0.0
    adaptive: dict | None = None  # the adaptive reference's record (reference_render.render_adaptive)


@dataclass
class RenderedJob:
    """What :func:`render_job` returns: the noisy renders, the reference (or None), the camera pose."""

    scene: str
    frame: int
    noisy: list[Render]
    reference: Render | None
    pose: list
    nested: bool = True  # the noisy renders are rungs of one progressive render

    def render_seconds(self) -> float:
        """Seconds this job rendered: nested rungs count once (the top rung's time), plus the reference."""
        times = [r.seconds for r in self.noisy]
        noisy = max(times, default=0.0) if self.nested else sum(times)
        return noisy + (self.reference.seconds if self.reference else 0.0)

    def samples_per_pixel(self) -> int:
        """Samples per pixel this job traced (nested rungs: the top rung's)."""
        spps = [r.spp for r in self.noisy]
        noisy = max(spps, default=0) if self.nested else sum(spps)
        return noisy + (self.reference.spp if self.reference else 0)


class _LoadedScene:
    """A translated stage, its render plan and its Mitsuba scene, ready to render."""

    def __init__(self, usd_path: Path, options: dict):
        self.translated, loaded = load_scene_file(usd_path)  # scene.usda (USD) or scene.xml (Mitsuba XML)
        self.plan = make_render_plan(
            self.translated.effects, RenderOptions(**options), stage_max_depth=self.translated.max_depth
        )
        self.scene = loaded if loaded is not None else build_mitsuba_scene(self.translated)
        self._frame_scene: tuple = (0, self.scene)
        self.per_frame = loaded is None and scene_varies_by_frame(self.translated)

    def scene_at(self, frame: int):
        """The Mitsuba scene of ``frame``: the one scene, or where the scene varies by frame that frame's (the last kept)."""
        if not self.per_frame:
            return self.scene

        if self._frame_scene[0] != frame:
            self._frame_scene = (frame, build_mitsuba_scene(self.translated, frame=frame))
        return self._frame_scene[1]


def scene_varies_by_frame(translated) -> bool:
    """Whether ``build_mitsuba_scene(translated, frame=i)`` differs between frames ``i``.

    Notes
    -----
    Only meshes that move between frames and stay in the main scene take per-frame vertices (and their
    previous frame's, for motion vectors); static meshes carry their own positions as the previous
    ones at every frame. With object motion blur (``shutter_moving``) every shape that moves within the
    shutter lives apart in its object space, posed at each ray's time from keys covering all frames,
    so unless some other shape moves between frames only (an emitter, which never moves within the
    shutter), one scene serves every frame: the same bytes as a scene built per frame, without
    rebuilding it, and the passes recorded with ``dr.freeze`` for it (:mod:`~denoisebench.generator.render.frame`)
    replay for later frames instead of being recorded and compiled anew."""
    if not translated.moving:
        return False
    if not translated.shutter_moving:
        return True
    return any(
        isinstance(s, MeshShape) and s.frame_positions is not None and s.shutter_motion is None
        for s in translated.shapes
    )


# One scene per process: jobs arrive grouped by scene, and a Mitsuba scene can be large.
_CACHE: dict[tuple, _LoadedScene] = {}
_STAGE_DIRS: dict[str, Path] = {}


_STAGE_PREFIX = "denoisebench-stage-"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def sweep_stale_stage_dirs(root: Path | None = None) -> int:
    """Remove stage folders whose worker process is gone; return how many.

    A Ray worker is killed at shutdown without running ``atexit``, so the folder it materialised
    would stay in the temporary directory for good; its name carries the worker's pid
    (``denoisebench-stage-<key>-<pid>-<random>``), and the next worker to materialise a stage sweeps
    the folders of dead pids. Folders of live processes (this one included) are left alone."""
    removed = 0
    for folder in Path(root or tempfile.gettempdir()).glob(f"{_STAGE_PREFIX}*-*-*"):
        parts = folder.name[len(_STAGE_PREFIX) :].split("-")
        if len(parts) != 3 or not parts[1].isdigit() or not folder.is_dir() or _pid_alive(int(parts[1])):
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed += not folder.exists()
    return removed


def _materialize(stage_key: str, files: dict[str, bytes]) -> Path:
    """Write shipped stage files into a private temporary folder (once per stage); return scene.usda."""
    folder = _STAGE_DIRS.get(stage_key)
    if folder is None:
        sweep_stale_stage_dirs()
        folder = Path(tempfile.mkdtemp(prefix=f"{_STAGE_PREFIX}{stage_key[:12]}-{os.getpid()}-"))
        atexit.register(shutil.rmtree, folder, True)  # a worker's copies go when the worker does
        for relative, data in files.items():
            target = folder / relative
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        _STAGE_DIRS[stage_key] = folder
    return folder / ("scene.xml" if "scene.xml" in files else layout.SCENE_USD)


def _loaded(job: FrameJob, stage_files: dict[str, bytes] | None) -> _LoadedScene:
    key = (job.stage_key, tuple(sorted(job.options.items())))
    if key not in _CACHE:
        _CACHE.clear()
        for stale in [k for k in _STAGE_DIRS if k != job.stage_key]:  # one stage's files on disk at a time
            shutil.rmtree(_STAGE_DIRS.pop(stale), ignore_errors=True)
        usd = _materialize(job.stage_key, stage_files) if stage_files is not None else Path(job.usd_path)
        _CACHE[key] = _LoadedScene(usd, job.options)
    return _CACHE[key]


#: Stream tag of independent rungs' seeds (hashed with the render seed and the rung's spp).
INDEPENDENT_RUNG_STREAM = 3


def independent_rung_seed(render_seed: int, spp: int) -> int:
    """Render seed of rung ``spp`` with ``--independent-rungs``: a hash of the render seed, spp and a stream tag."""
    data = struct.pack("<qqq", int(render_seed), int(spp), INDEPENDENT_RUNG_STREAM)
    return int.from_bytes(hashlib.blake2b(data, digest_size=4).digest(), "little")


def _timed_render(loaded: _LoadedScene, job: FrameJob, spp: int, reference: bool, seed: int | None = None) -> Render:
    """Render, and split the renderer's seconds into rendering and kernel compilation.

    ``seed``: the sampler seed (default: the job's ``render_seed``; adaptive reference rounds pass their own)."""

    clock = RenderClock()
    out = render_frame(
        loaded.scene_at(job.frame),
        loaded.translated.camera,
        job.frame,
        loaded.plan,
        width=job.width,
        height=job.height,
        spp=spp,
        seed=job.render_seed if seed is None else seed,
        reference=reference,
        clock=clock,
    )
    return Render(spp, out.buffers, None if reference else out.samples, out.seconds, clock.compile_seconds)


def _timed_ladder(loaded: _LoadedScene, job: FrameJob) -> list[Render]:
    """The job's noisy rungs from one progressive render; each rung's seconds is the time to reach it."""

    clock = RenderClock()
    renders = []
    rungs = render_ladder(
        loaded.scene_at(job.frame),
        loaded.translated.camera,
        job.frame,
        loaded.plan,
        width=job.width,
        height=job.height,
        rungs=job.spp,
        seed=job.render_seed,
        clock=clock,
    )
    compiled = clock.compile_seconds  # compilation happens in the first passes; report it with every rung
    for rung in rungs:
        renders.append(Render(rung.spp, rung.buffers, rung.samples, rung.seconds, compiled))
    return renders


def render_job(job: FrameJob, stage_files: dict[str, bytes] | None = None) -> RenderedJob:
    """Render one :class:`FrameJob` (``stage_files``: the stage's bytes when not on this disk)."""
    loaded = _loaded(job, stage_files)
    camera = loaded.translated.camera
    if not 0 <= job.frame < camera.frames:
        raise ValueError(f"scene {job.scene!r} has {camera.frames} frame(s), not frame {job.frame}")
    if not job.spp:
        noisy = []
    elif job.independent_rungs:
        noisy = [
            _timed_render(loaded, job, spp, reference=False, seed=independent_rung_seed(job.render_seed, spp))
            for spp in job.spp
        ]
    else:
        noisy = _timed_ladder(loaded, job)
    reference = _render_reference(loaded, job) if job.ref_spp else None
    pose = np.asarray(camera.poses[job.frame]).tolist()
    return RenderedJob(job.scene, job.frame, noisy, reference, pose, nested=not job.independent_rungs)


def _render_reference(loaded: _LoadedScene, job: FrameJob) -> Render:
    """The frame's reference: one render at ``ref_spp``, or adaptive rounds when ``ref_error`` is set."""
    if job.ref_error is None:
        return _timed_render(loaded, job, job.ref_spp, reference=True)

    def render_round(index: int, round_spp: int):
        render = _timed_render(
            loaded, job, round_spp, reference=True, seed=round_seed(job.render_seed, job.frame, index)
        )
        return render.buffers, render.seconds, render.compile_seconds

    outcome = render_adaptive(render_round, job.ref_spp, job.ref_error)
    return Render(outcome.spp, outcome.buffers, None, outcome.seconds, outcome.compile_seconds, outcome.record)


def write_rendered(writer, result: RenderedJob) -> int:
    """Record every render of ``result`` with ``writer``; return the number of files' worth written."""

    def extra(render: Render) -> dict:
        return {"camera_pose": result.pose, "jit_compile_seconds": render.compile_seconds}

    for render in result.noisy:
        writer.write_frame(
            result.scene,
            result.frame,
            render.spp,
            render.buffers,
            render.samples,
            seconds=render.seconds,
            extra=extra(render),
        )
    if result.reference is not None:
        ref = result.reference
        more = extra(ref)
        if ref.adaptive is not None:
            more["reference_adaptive"] = ref.adaptive
        writer.write_reference(
            result.scene,
            result.frame,
            ref.buffers["color"],
            ref.buffers["color_var"],
            ref.seconds,
            spp=ref.spp,
            buffers={k: ref.buffers[k] for k in REFERENCE_EXTRA if k in ref.buffers},
            extra=more,
        )
    return len(result.noisy) + (result.reference is not None)


def missing_jobs(
    writer,
    scene: str,
    stage_key: str,
    usd_path: str,
    render_seed: int,
    options: dict,
    ref_error: float | None = None,
    independent_rungs: bool = False,
) -> list[FrameJob]:
    """The jobs still needed for ``scene`` (frames whose every file is intact are skipped).

    A job lists the frame's missing rungs only; nested rungs render up to the highest of them."""
    record = writer.manifest["scenes"][scene]
    jobs = []
    for frame in range(record["frames"]):
        spp = tuple(s for s in record["spp"] if not writer.is_done(scene, frame, s))
        ref_spp = record.get("ref_spp")
        if ref_spp and writer.is_done(scene, frame, layout.REFERENCE):
            ref_spp = None
        if spp or ref_spp:
            jobs.append(
                FrameJob(
                    scene,
                    frame,
                    stage_key,
                    usd_path,
                    spp,
                    ref_spp,
                    record["width"],
                    record["height"],
                    render_seed,
                    dict(options),
                    ref_error,
                    independent_rungs,
                )
            )
    return jobs
