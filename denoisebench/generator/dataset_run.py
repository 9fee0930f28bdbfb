"""Generate (or resume) a dataset: prepare the scenes, render the missing frames, write, finalize.

:func:`generate_dataset` is what ``denoisebench generate`` and the demo run. The dataset config
(:func:`dataset_config`) is everything that decides the bytes: families, scene count, frames,
size, spp and whether its rungs are nested (``rungs``), reference spp (the cap with ``ref_error``),
the reference's target floor ``ref_error``,
the user's transport restriction ``max_depth``, per-sample data, seed and the user's USD files
(path and sha256). The
executor is *not* part of it: local and Ray runs give the same bytes, so a run started locally may
be finished on a cluster. Running again with the same config resumes; another config is refused
unless ``force`` (:class:`~denoisebench.dataset.writer.DatasetWriter`). A non-empty OUT that is
no dataset is refused, and with ``force`` filled beside the files there (:func:`check_out_folder`).

The options applied to user scenes (``--camera``, ``--auto-camera``, ``--default-light``; for
``--usd`` stages and ``--mitsuba`` files alike) sit under the config key ``stage_options``.
Datasets written before that name was chosen carry them as ``usd_options``, and the config hash
covers the key: :func:`resumable_config` gives such a dataset its own spelling back when the
options are the same, so it resumes under its original hash instead of being refused or rebuilt.

Notes:
    User stages are checked (opened, translated, dependencies inside their folder) before
    anything is written: one bad ``--usd`` file refuses the whole command with a one-line error
    (exit 2) rather than leaving a dataset that silently lacks a scene.
    A job that fails while rendering (an internal error) is reported and the others carry on; the
    dataset is then finalized as incomplete (``complete: false``) and a rerun renders what is
    missing.
"""

from __future__ import annotations

import hashlib
import sys
import time
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

from tqdm import tqdm

from denoisebench.dataset import bounds, layout
from denoisebench.dataset.atomic import is_temporary
from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.manifest import assign_splits, config_hash, load_header, pin_held_out
from denoisebench.dataset.writer import DatasetWriter
from denoisebench.errors import UserInputError
from denoisebench.generator import dataset_scenes as scenes_mod
from denoisebench.generator.contract.render_plan import RenderOptions, check_max_depth, make_render_plan
from denoisebench.generator.dataset_scenes import SceneSpec
from denoisebench.generator.frame_jobs import missing_jobs, write_rendered
from denoisebench.generator.render.reference import GROWTH_WARNING
from denoisebench.mitsuba_runtime import load_mitsuba
from denoisebench.scenes import get_family

CONFIG_KIND = "denoisebench.generate"
#: The reference should have this many times the noisy inputs' largest spp (rel_se falls as 1/sqrt(spp),
#: and the manifest flags a reference that is not 4× less noisy than its inputs).
REFERENCE_SPP_FACTOR = 16
#: Default target of the adaptive reference's noise floor (relMSE of a perfect denoiser against it).
DEFAULT_REF_ERROR = 1e-3
#: Default cap of reference samples per pixel when the reference is adaptive.
DEFAULT_REF_SPP = 4096
#: Config key of the options applied to user scenes (--camera, --auto-camera, --default-light).
STAGE_OPTIONS_KEY = "stage_options"
#: The same key in datasets written before it was renamed (it also covered --mitsuba files).
LEGACY_STAGE_OPTIONS_KEY = "usd_options"


@dataclass(frozen=True)
class GenerateRequest:
    """What to generate (the command line's options)."""

    out: Path
    families: tuple[str, ...]
    scenes: int = 1
    frames: int = 8
    width: int = 128
    height: int = 128
    spp: tuple[int, ...] = (1, 4, 16)
    ref_spp: int = DEFAULT_REF_SPP  # the cap when ref_error is set
    samples: bool = False
    seed: int = 0
    usd: tuple[str, ...] = ()
    xml: tuple[str, ...] = ()  # --mitsuba (--xml): Mitsuba XML scenes (generator/mitsuba_xml.py), static camera
    force: bool = False
    ref_error: float | None = DEFAULT_REF_ERROR  # None: one reference render at ref_spp
    max_depth: int | None = None  # the user's transport restriction (None: full transport / stage's own)
    camera: str | None = None  # --camera PATH for the --usd stages
    auto_camera: bool = False  # --auto-camera: frame --usd stages with an orbiting camera (usd/additions.py)
    default_light: bool = False  # --default-light: light --usd stages that have no light
    independent_rungs: bool = False  # --independent-rungs: every spp its own render (default: nested rungs)
    defines: tuple[tuple[str, str], ...] = ()  # --define NAME=VALUE: parameters of the --mitsuba scenes
    # --mitsuba-path DIR: more folders to find the --mitsuba scenes' files in. Not in the config: the copies
    # hold every file they need, and a machine's folders must not change the config hash.
    search_paths: tuple[str, ...] = ()
    # --time-range START:END and an explicit --frames: which of a --usd stage's own time codes to render
    time_range: tuple[float, float] | None = None
    stage_frames: int | None = None

    def define_dict(self) -> dict[str, str]:
        """The --define parameters as a dict (later ones win, as on Mitsuba's command line)."""
        return dict(self.defines)

    def stage_options(self) -> dict:
        """What is written into every copied --usd stage (dataset_scenes.stage_options)."""
        return scenes_mod.stage_options(
            self.camera,
            self.auto_camera,
            self.default_light,
            self.frames,
            time_range=self.time_range,
            stage_frames=self.stage_frames,
        )


@dataclass
class GenerateSummary:
    out: Path
    scenes: int = 0
    frames: int = 0  # scene-frames rendered in this run
    files: int = 0  # EXR files written in this run (noisy spp + references)
    skipped: int = 0  # scene-frames already complete (resume)
    render_seconds: float = 0.0
    samples: int = 0  # pixel samples rendered in this run
    wall_seconds: float = 0.0
    too_noisy: int = 0  # frames whose reference is flagged
    at_cap: list = field(default_factory=list)  # "scene/frame" whose adaptive reference stopped at the cap
    rising: list = field(default_factory=list)  # "scene/frame" whose floor estimate was still rising (a lower bound)
    failures: list = field(default_factory=list)
    complete: bool = False

    @property
    def samples_per_second(self) -> float:
        return self.samples / self.render_seconds if self.render_seconds > 0 else 0.0


def check_request(request: GenerateRequest) -> None:
    """UserInputError for values no dataset can have."""
    for name in ("scenes", "frames", "width", "height", "ref_spp"):
        if getattr(request, name) < 1:
            raise UserInputError(f"--{name.replace('_', '-')} must be >= 1 (got {getattr(request, name)})")
    if max(request.width, request.height) > 16384:
        raise UserInputError(f"--width/--height at most 16384 (got {request.width}x{request.height})")
    if not request.spp or min(request.spp) < 1:
        raise UserInputError(f"--spp needs positive sample counts (got {list(request.spp)})")
    if not request.families and not request.usd and not request.xml:
        raise UserInputError("nothing to generate: give --families, --usd and/or --mitsuba")

    bounds.check_generate(
        width=request.width,
        height=request.height,
        scenes=request.scenes,
        frames=request.frames,
        spp=request.spp,
        ref_spp=request.ref_spp,
        samples=request.samples,
    )
    if request.ref_error is not None and not (0 < request.ref_error < float("inf")):
        raise UserInputError(f"--ref-error must be a positive number (got {request.ref_error})")
    if request.max_depth is not None:
        try:
            check_max_depth(request.max_depth, "--max-depth")
        except ValueError as error:
            raise UserInputError(str(error)) from None
    if request.time_range is not None and not request.usd:
        raise UserInputError("--time-range chooses among a --usd stage's time codes; give --usd")


def validate_request(request: GenerateRequest) -> None:
    """Every check that needs no output folder: values, family names, the user's stages."""
    check_request(request)
    if request.families:
        for family in request.families:
            get_family(family)  # UnknownFamilyError is a UserInputError
    for path in request.usd:
        scenes_mod.check_user_stage(path, request.stage_options())
    for path in request.xml:
        scenes_mod.check_xml_scene(
            path,
            request.frames,
            auto_camera=request.auto_camera,
            defines=request.define_dict(),
            search_paths=request.search_paths,
        )


def dataset_names(request: GenerateRequest) -> list[str]:
    """Every name the dataset writes directly under OUT: the manifest, its frame index, the scene folders."""
    family_names = [
        name for _, _, name in scenes_mod.family_scene_names(list(request.families), request.scenes, request.seed)
    ]
    user_names = scenes_mod.user_scene_names(list(request.usd), set(family_names))
    return [layout.MANIFEST_NAME, layout.INDEX_NAME, *family_names, *user_names, *xml_scene_names(request)]


def check_out_folder(request: GenerateRequest) -> None:
    """UserInputError where OUT is a non-empty folder that is not a dataset (no ``dataset.json``).

    Such a folder is someone's: without ``force`` it is refused; with ``force`` the dataset goes in
    beside the files there, and is refused only where one of its own names (:func:`dataset_names`)
    is taken, since writing it would replace that file or folder. A dataset's own folder (resume,
    or another config with ``force``) is the writer's to judge; a run's hidden temporaries do not
    make a folder foreign.
    """
    out = Path(request.out)
    if not out.is_dir() or (out / layout.MANIFEST_NAME).exists():
        return
    entries = sorted(p.name for p in out.iterdir() if not is_temporary(p))
    if not entries:
        return
    shown = ", ".join(entries[:3]) + (f" and {len(entries) - 3} more" if len(entries) > 3 else "")
    if not request.force:
        raise UserInputError(
            f"--out {out} holds {len(entries)} entries that are not a denoisebench dataset ({shown}): give an empty "
            "or new folder, or --force to write the dataset beside them"
        )
    taken = [name for name in dataset_names(request) if (out / name).exists() or (out / name).is_symlink()]
    if taken:
        raise UserInputError(
            f"--out {out}: the dataset would replace your {', '.join(taken[:3])}"
            f"{' and more' if len(taken) > 3 else ''}; give another folder"
        )


def _file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def xml_scene_names(request: GenerateRequest) -> list[str]:
    """The dataset names of the --mitsuba scenes (``xml_<stem>``), as :func:`_prepare_scenes` gives them."""
    taken = {name for _, _, name in scenes_mod.family_scene_names(list(request.families), request.scenes, request.seed)}
    taken |= set(scenes_mod.user_scene_names(list(request.usd), taken))
    return scenes_mod.user_scene_names(list(request.xml), taken, prefix="xml_")


def dataset_config(request: GenerateRequest) -> dict:
    """The config whose hash identifies the dataset (see the module docstring).

    A --mitsuba scene is recorded by where it is copied (``xml_<stem>/scene.xml``) and the sha256 of
    the user's file, never by its path on this machine: the same files give the same hash anywhere.
    """
    return {
        "generator": CONFIG_KIND,
        "families": list(request.families),
        "scenes": request.scenes,
        "frames": request.frames,
        "width": request.width,
        "height": request.height,
        "spp": sorted(set(int(s) for s in request.spp)),
        "ref_spp": request.ref_spp,
        "ref_error": request.ref_error,
        "max_depth": request.max_depth,
        "samples": bool(request.samples),
        "seed": request.seed,
        "rungs": "independent" if request.independent_rungs else "nested",
        "usd": [{"path": str(Path(p).resolve()), "sha256": _file_sha256(Path(p))} for p in request.usd],
        **(
            {
                "xml": [
                    {"path": f"{name}/{scenes_mod.XML_NAME}", "sha256": _file_sha256(Path(p))}
                    for p, name in zip(request.xml, xml_scene_names(request))
                ]
            }
            if request.xml
            else {}
        ),
        **({"defines": dict(sorted(request.define_dict().items()))} if request.defines else {}),
        # which of the --usd stages' own time codes are rendered (keys only when asked for: older hashes hold)
        **({"time_range": list(request.time_range)} if request.usd and request.time_range else {}),
        **({"stage_frames": request.stage_frames} if request.usd and request.stage_frames is not None else {}),
        **(
            {
                STAGE_OPTIONS_KEY: {
                    "camera": request.camera,
                    "auto_camera": request.auto_camera,
                    "default_light": request.default_light,
                }
            }
            if request.camera or request.auto_camera or request.default_light
            else {}
        ),
    }


def legacy_config(config: dict) -> dict | None:
    """``config`` as datasets before the rename spelled it (``usd_options``), or None when it has no stage options."""
    if STAGE_OPTIONS_KEY not in config:
        return None
    return {(LEGACY_STAGE_OPTIONS_KEY if k == STAGE_OPTIONS_KEY else k): v for k, v in config.items()}


def absolute_xml_config(request: GenerateRequest, config: dict) -> dict | None:
    """``config`` as older datasets spelled their --mitsuba files (the absolute path on the
    machine that made them), or None without --mitsuba files or with --define (which did not exist)."""
    if not request.xml or request.defines:
        return None
    xml = [{"path": str(Path(p).resolve()), "sha256": _file_sha256(Path(p))} for p in request.xml]
    return {**config, "xml": xml}


def resumable_config(out: str | Path, config: dict, *older: dict | None) -> dict:
    """The config to open ``out`` with: ``config``, or an older spelling when ``out`` was written with it.

    Only an existing manifest whose hash is that of :func:`legacy_config` (the same options, the old
    key) or of one of ``older`` (e.g. :func:`absolute_xml_config`) gets that spelling; anything else
    (no dataset, an unreadable manifest, another config) gets ``config`` and the writer's usual rules
    (resume, refuse, or ``--force``).
    """
    older = tuple(c for c in older if c is not None)
    spellings = (legacy_config(config), *older, *(legacy_config(c) for c in older))
    candidates = [c for c in spellings if c is not None and c != config]
    if not candidates:
        return config
    try:
        header = load_header(Path(out) / layout.MANIFEST_NAME)
    except DatasetError:
        return config
    return next((c for c in candidates if header.get("config_hash") == config_hash(c)), config)


def render_versions() -> dict[str, str]:
    """Versions that decide the renders: Mitsuba (and its variant), Dr.Jit, USD."""
    versions = {"mitsuba_variant": load_mitsuba().variant()}
    for package in ("mitsuba", "drjit", "usd-core"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "missing"
    return versions


def transport_note(translated, plan) -> str:
    """`` (<which integrator>)`` when a Mitsuba XML scene's own integrator restricts transport, else ""."""
    origin = translated.transport_origin
    return f" ({origin})" if origin and plan.max_depth_source == "stage" else ""


def _scene_record(spec: SceneSpec, translated, request: GenerateRequest, plan) -> dict:
    camera = translated.camera
    prefix = str(Path(spec.stage_dir)) + "/"
    return {
        "family": spec.family,
        "seed": spec.seed,
        "source": spec.source,
        "frames": camera.frames,
        "width": request.width,
        "height": request.height,
        "spp": sorted(set(int(s) for s in request.spp)),
        "ref_spp": request.ref_spp,
        "ref_error": request.ref_error,
        "transport": plan.transport_line() + transport_note(translated, plan),
        "usd": f"{spec.name}/{spec.stage_files[0]}",  # scene.usda, or scene.xml for --xml
        "stage_files": list(spec.stage_files),
        "stage_sha256": scenes_mod.stage_digest(spec.stage_dir, spec.stage_files),
        "render_seed": spec.render_seed,
        "effects": {"declared": list(translated.effects_declared), "inferred": list(translated.effects_inferred)},
        **({"variants": dict(translated.variants)} if translated.variants else {}),  # held-out pools
        "plan": plan.to_dict(),
        "translated": translated.summary(),  # shapes, instances, how each material was translated
        "camera": {
            "prim_path": camera.prim_path,
            "fov_x_deg": float(camera.fov_x_deg),
            "aperture_radius": float(camera.aperture_radius),
            "focus_distance": float(camera.focus_distance),
            "shutter_open": float(camera.shutter_open),
            "shutter_close": float(camera.shutter_close),
            "animated": bool(camera.is_animated),
            **({"projection": camera.projection} if camera.projection != "perspective" else {}),
        },
        # Paths inside OUT are made relative so that the manifest does not depend on where OUT is.
        "warnings": [w.replace(prefix, f"{spec.name}/") for w in translated.warnings],
        **({"frame_selection": selection} if (selection := _selection(spec)) else {}),
    }


def _selection(spec: SceneSpec) -> dict | None:
    """The time codes a user stage's copy renders of its own (--frames, --time-range), or None."""
    if spec.family != "usd":
        return None
    return scenes_mod.frame_selection(spec.usd_path)


def _prepare_scenes(request: GenerateRequest, writer: DatasetWriter, user_names: list[str]) -> list[SceneSpec]:
    """Author / copy every scene into OUT and record it with the writer."""
    entries = []
    for family, seed, name in scenes_mod.family_scene_names(list(request.families), request.scenes, request.seed):
        folder = writer.scene_dir(name)
        files = scenes_mod.author_family_scene(
            get_family(family), folder, seed, request.frames, request.width, request.height
        )
        entries.append(
            SceneSpec(
                name, family, seed, family, str(folder.resolve()), files, scenes_mod.render_seed(request.seed, name)
            )
        )
    for path, name in zip(request.usd, user_names):
        folder = writer.scene_dir(name)
        files = scenes_mod.copy_user_stage(path, folder, request.stage_options())
        entries.append(
            SceneSpec(
                name, "usd", 0, str(path), str(folder.resolve()), files, scenes_mod.render_seed(request.seed, name)
            )
        )
    taken = {spec.name for spec in entries}
    for path, name in zip(request.xml, scenes_mod.user_scene_names(list(request.xml), taken, prefix="xml_")):
        folder = writer.scene_dir(name)
        files = scenes_mod.copy_xml_scene(
            path,
            folder,
            request.frames,
            auto_camera=request.auto_camera,
            defines=request.define_dict(),
            search_paths=request.search_paths,
        )
        entries.append(
            SceneSpec(
                name, "xml", 0, str(path), str(folder.resolve()), files, scenes_mod.render_seed(request.seed, name)
            )
        )
    options = RenderOptions(**render_options(request))
    records = {}
    for spec in entries:
        translated = scenes_mod.translate_scene_file(spec.usd_path)
        plan = make_render_plan(translated.effects, options, stage_max_depth=translated.max_depth)
        records[spec.name] = _scene_record(spec, translated, request, plan)
    writer.add_scenes(records)  # one header write for all scenes (not one per scene)
    return entries


def render_options(request: GenerateRequest) -> dict:
    """The :class:`~denoisebench.generator.contract.render_plan.RenderOptions` fields a request sets (picklable)."""
    return {"per_sample": bool(request.samples), "max_depth": request.max_depth}


def generate_dataset(request: GenerateRequest, executor, progress: bool = True, log=None) -> GenerateSummary:
    """Generate or resume the dataset ``request`` asks for with ``executor``; return a summary."""
    log = log or (lambda line: print(line, file=sys.stderr))
    started = time.perf_counter()
    validate_request(request)
    family_names = {
        name for _, _, name in scenes_mod.family_scene_names(list(request.families), request.scenes, request.seed)
    }
    user_names = scenes_mod.user_scene_names(list(request.usd), family_names)

    check_out_folder(request)
    config = dataset_config(request)
    config = resumable_config(request.out, config, absolute_xml_config(request, config))
    writer = DatasetWriter(request.out, config, render_versions(), force=request.force)
    specs = _prepare_scenes(request, writer, user_names)
    by_name = {spec.name: spec for spec in specs}
    options = render_options(request)
    jobs = []
    for spec in specs:
        stage_key = writer.manifest["scenes"][spec.name]["stage_sha256"]
        jobs.extend(
            missing_jobs(
                writer,
                spec.name,
                stage_key,
                str(spec.usd_path),
                spec.render_seed,
                options,
                request.ref_error,
                request.independent_rungs,
            )
        )
    for spec in specs:
        record = writer.manifest["scenes"][spec.name]
        if spec.family == "usd" and "frame_selection" not in record and record["frames"] > scenes_mod.LONG_STAGE_FRAMES:
            log(
                f"note: {spec.name} renders all {record['frames']} time codes of its stage; --frames N takes N of "
                "them evenly, --time-range START:END a window"
            )
    summary = GenerateSummary(out=Path(request.out), scenes=len(specs))
    total_frames = sum(writer.manifest["scenes"][s.name]["frames"] for s in specs)
    summary.skipped = total_frames - len(jobs)
    if writer.resumed and summary.skipped:
        log(f"resuming {request.out}: {summary.skipped} of {total_frames} frame(s) already done")

    scene_order = {spec.name: k + 1 for k, spec in enumerate(specs)}
    bar = tqdm(
        total=total_frames,
        initial=summary.skipped,
        unit="frame",
        desc="generate",
        file=sys.stderr,
        disable=not progress,
        dynamic_ncols=True,
    )
    try:
        for outcome in executor.run(jobs, by_name):
            bar.set_postfix_str(f"scene {scene_order[outcome.scene]}/{len(specs)} {outcome.scene}")
            if not hasattr(outcome, "noisy"):
                summary.failures.append(outcome)
                tqdm.write(f"error: scene {outcome.scene} frame {outcome.frame}: {outcome.message}", file=sys.stderr)
                bar.update(1)
                continue
            summary.files += write_rendered(writer, outcome)
            summary.frames += 1
            summary.render_seconds += outcome.render_seconds()  # nested rungs count once
            summary.samples += outcome.samples_per_pixel() * request.width * request.height
            bar.update(1)
    finally:
        bar.close()
    # stratified by family: every family of >= 3 scenes lands in train, val and test
    families = {name: spec.family for name, spec in by_name.items()}
    held_out = [n for n, s in writer.manifest["scenes"].items() if s.get("variants", {}).get("pool") == "held_out"]
    splits = pin_held_out(assign_splits(list(by_name), request.seed, families=families), held_out)
    writer.finalize(splits, allow_incomplete=bool(summary.failures))
    summary.complete = bool(writer.manifest["complete"])
    for name, scene in writer.manifest["scenes"].items():
        for frame, record in sorted(scene["renders"].get(layout.REFERENCE, {}).items()):
            adaptive = record.get("reference_adaptive") or {}
            summary.too_noisy += bool(record.get("reference_too_noisy"))
            if adaptive.get("stopped_at_cap"):
                summary.at_cap.append(f"{name}/{frame}")
            if (adaptive.get("floor_growth") or 0.0) > GROWTH_WARNING:
                summary.rising.append(f"{name}/{frame}")
    summary.wall_seconds = time.perf_counter() - started
    return summary
