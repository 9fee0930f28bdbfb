"""The benchmark runner: every denoiser over every sequence of a split at every input spp.

A **unit** is one denoiser on one scene's sequence at one spp. The runner loads a sequence once,
runs the noisy input itself (the "just render more samples" point, label :data:`NOISY`) and every
denoiser on it through :func:`denoisebench.denoisers.runner.run_sequence` (``reset()`` first, then
the frames in order, every call timed, every output checked, failures contained), computes every
metric per frame and the temporal ones per sequence, and writes the unit to the
:class:`~denoisebench.results.store.ResultsStore` in one transaction.

Notes
-----
* **Resuming.** A run is identified by the hash of the dataset and the benchmark config
  (:func:`run_identity`). Rerunning the same command finds the run and computes only the units that
  have no row; a unit is atomic in the store, so a kill loses at most the unit in flight.
* **Time.** ``render_seconds`` of a frame is the generator's measured render time at that spp
  (manifest); ``total_seconds`` = render + denoise (:func:`denoisebench.metrics.cost.total_seconds`).
  Denoise time is measured around ``denoise()`` only. Two runs on a busy machine measure different
  times: a ranking shows the run each number comes from.
* **The noisy input** is the color buffer after the harness's NaN/Inf sanitising (what denoisers
  see); its denoise time is 0.
* A denoiser the user named that cannot be loaded (broken plugin, missing optional dependency) is
  bad input, raised before the run is written; one that ``all`` brought in is recorded with its
  error in ``run_denoisers`` and gets no units, and so is one whose needs the dataset cannot meet
  (:func:`skip_unrunnable`: rpf without per-sample data), with the flag that would enable it. An
  unknown name or option (``--option identity:nosuchopt=1``, an option for a spec that is not run)
  is bad input.
* **Plugin code.** The config (the run's identity) holds a hash of each plugin's code
  (``code``: :func:`denoisebench.denoisers.registry.denoiser_code_identity`; built-ins have none, a
  run of built-ins keeps its id): an edited plugin makes a new run, and :func:`replaced_runs` names
  the earlier runs of the same command it replaces.
* **Untrusted plugins** run in worker processes of their own under a time and a memory limit
  (:mod:`denoisebench.denoisers.isolation`; ``BenchmarkConfig.isolation``, ``time_limit``,
  ``memory_limit_mb``); a plugin that exits, crashes, hangs or bloats fails its units with the
  reason and the run goes on.
* **Untrusted data.** Before the first unit, every file the run reads is checked against the
  manifest's sha256 (:func:`denoisebench.dataset.verify.verify_files`, with a progress bar);
  ``verify=False`` (``--no-verify``) skips it and is recorded in the run's config. Manifest paths
  are confined to the dataset root by the reader either way.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import platform
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from denoisebench.benchmark.measure import measure_unit
from denoisebench.benchmark.sampler_units import measure_pairs, plan_pairs, register_pairs
from denoisebench.dataset import Dataset, DatasetError, layout
from denoisebench.dataset.bounds import check_scene_record
from denoisebench.dataset.exr_io import canonical_json
from denoisebench.dataset.verify import run_files, verify_files
from denoisebench.denoisers import isolation as isolation_mod
from denoisebench.denoisers.isolation import IsolatedDenoiser
from denoisebench.denoisers.protocol import describe
from denoisebench.denoisers.registry import DenoiserLoadError, available_denoisers, denoiser_code_identity
from denoisebench.errors import UserInputError
from denoisebench.metrics.registry import default_metric_names, expand_metric_names, get_metric
from denoisebench.plugins import DEFAULT_MEMORY_LIMIT_MB, DEFAULT_TIME_LIMIT, Limits
from denoisebench.plugins.sandbox import version as sandbox_version
from denoisebench.results.names import (
    NOISY,
    REQUIRED_METRICS,
)
from denoisebench.results.records import UnitRecord
from denoisebench.results.store import ResultsStore

#: A unit's key: (label, scene, spp).
UnitKey = tuple[str, str, int]
#: Distributions whose versions a run records (those installed).
VERSIONED = (
    "denoisebench",
    "numpy",
    "scipy",
    "scikit-image",
    "colour-science",
    "flip-evaluator",
    "OpenEXR",
    "torch",
    "pyoidn",
    "mitsuba",
    "usd-core",
    "ray",
)


@dataclass(kw_only=True)
class BenchmarkConfig:
    """What a run measures; its canonical JSON (with the dataset hash) identifies the run."""

    denoisers: list[str]
    spp: list[int]
    split: str = "test"
    metrics: list[str] = field(default_factory=list)
    options: dict[str, dict] = field(default_factory=dict)
    nonce: str | None = None  # set to force a new run instead of resuming
    isolation: str = "plugins"  # who runs in a worker process (denoisebench.denoisers.isolation.POLICIES)
    time_limit: float | None = None  # per-call seconds of an isolated denoiser (None: the default)
    memory_limit_mb: int | None = None  # worker resident-memory limit (None: the default)
    verify: bool = True  # check every file's sha256 before the first unit
    trim: float | None = None  # robust scores' dropped fraction (None: metrics.robust.DEFAULT_TRIM, 0.1 %)
    samplers: list[str] = field(default_factory=list)  # live sampler × denoiser pairs (benchmark.sampler_units)
    code: dict[str, str] = field(default_factory=dict)  # plugin spec -> hash of its code (registry identity)

    def as_dict(self) -> dict:
        data = {
            "denoisers": list(self.denoisers),
            "spp": sorted(int(s) for s in self.spp),
            "split": self.split,
            "metrics": list(self.metrics),
            "options": self.options,
        }
        if self.nonce:
            data["nonce"] = self.nonce
        # recorded (and part of the run's identity) only when not the default, so that runs made
        # before these settings existed keep their ids and resume
        if self.isolation != "plugins":
            data["isolation"] = self.isolation
        if self.time_limit is not None:
            data["time_limit"] = float(self.time_limit)
        if self.memory_limit_mb is not None:
            data["memory_limit_mb"] = int(self.memory_limit_mb)
        if not self.verify:
            data["verify"] = False
        if self.trim is not None:
            data["trim"] = float(self.trim)
        if self.samplers:
            data["samplers"] = list(self.samplers)
        if self.code:  # plugins only: a run of built-ins keeps the id it always had
            data["code"] = dict(sorted(self.code.items()))
        return data

    def limits(self):

        return Limits(
            DEFAULT_TIME_LIMIT if self.time_limit is None else float(self.time_limit),
            DEFAULT_MEMORY_LIMIT_MB if self.memory_limit_mb is None else int(self.memory_limit_mb),
        )


@dataclass(kw_only=True)
class LoadedDenoiser:
    label: str
    spec: str
    instance: object | None
    needs: frozenset[str]
    temporal: bool
    load_error: str | None = None
    trained_scenes: frozenset[str] = frozenset()  # what the denoiser declared (learned models: their checkpoint's)

    @property
    def loaded(self) -> bool:
        """It loaded (and is measured): judged by the error, so that a plan sent without its
        instances (:func:`.ray_executor.light_plan`) has the same labels."""
        return self.load_error is None


# --------------------------------------------------------------------------------------------------
# identity of a run


def dataset_hash(dataset: Dataset) -> str:
    """sha256 of the manifest without timings: the dataset's content (files' sha256 included)."""
    return dataset.content_hash()  # streamed one scene at a time (the same text for schema versions 1 and 2)


def run_identity(data_hash: str, config: BenchmarkConfig) -> str:
    text = canonical_json({"dataset": data_hash, "config": config.as_dict()})
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def software_versions() -> dict[str, str]:
    versions = {"python": platform.python_version()}
    for dist in VERSIONED:
        try:
            versions[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            continue

    if sandbox_version():  # the plugin sandbox (reports say whether the run used it)
        versions["bubblewrap"] = sandbox_version().split()[-1]
    return versions


# --------------------------------------------------------------------------------------------------
# inputs


def resolve_denoiser_specs(specs: Iterable[str]) -> list[str]:
    """Expand ``all`` to every available name (built-ins, then entry points); keep order, no repeats."""
    out: list[str] = []
    for spec in specs:
        names = list(available_denoisers()) if spec.strip() == "all" else [spec.strip()]
        out.extend(n for n in names if n and n not in out)
    if not out:
        raise UserInputError("no denoisers given")
    return out


def load_denoisers(
    specs: list[str], options: dict[str, dict], *, isolation: str = "plugins", limits=None, required=()
) -> list[LoadedDenoiser]:
    """Construct each denoiser (isolated by ``isolation``). An unknown name or option is bad input,
    and so is a load failure of a spec in ``required`` (those the user named: exit 2 with the
    message ``check-plugin`` gives); any other load failure (``all``'s) is recorded, not raised."""
    unknown = [spec for spec in options if spec not in specs]
    if unknown:
        raise UserInputError(
            f"--option for {', '.join(map(repr, unknown))}, which is not among the denoisers run ({', '.join(specs)})"
        )
    loaded: list[LoadedDenoiser] = []
    taken = {NOISY}
    for spec in specs:
        try:
            instance = isolation_mod.load(spec, options.get(spec, {}), policy=isolation, limits=limits)
            info = describe(instance, fallback_name=spec)
            label, needs, temporal, error, trained = info.name, info.needs, info.temporal, None, info.trained_scenes
        except DenoiserLoadError as exc:
            if spec in required:
                close_isolated(d.instance for d in loaded)
                raise
            instance, label, needs, temporal, error, trained = None, spec, frozenset(), False, str(exc), frozenset()
        base, n = label, 2
        while label in taken:  # two specs with one name (or a plugin called "noisy") stay apart
            label, n = f"{base}#{n}", n + 1
        taken.add(label)
        loaded.append(
            LoadedDenoiser(
                label=label,
                spec=spec,
                instance=instance,
                needs=needs,
                temporal=temporal,
                load_error=error,
                trained_scenes=trained,
            )
        )
    return loaded


def close_isolated(instances: Iterable[object]) -> None:
    """Stop the worker processes of the isolated ones among ``instances``."""
    for instance in instances:
        if isinstance(instance, IsolatedDenoiser):
            instance.close()


#: What a dataset may lack that a denoiser needs -> the generate-dataset flag that provides it.
ENABLED_BY = {"samples": "per-sample data (generate-dataset --samples)"}


def unmet_needs(dataset: Dataset, scenes: list[str], spp: list[int]) -> set[str]:
    """The needs of :data:`ENABLED_BY` that the run's frames cannot meet: per-sample data where a
    scene's first frame at the lowest spp has no samples file."""
    first = min(spp)
    lacking = set()
    for scene in scenes:
        record = dataset.record(scene, first, 0) or {}
        if not record.get("samples"):
            lacking.add("samples")
    return lacking


def skip_unrunnable(denoisers: list[LoadedDenoiser], named: set[str], lacking: set[str]) -> None:
    """Mark the denoisers ``all`` brought in (not in ``named``) whose needs the dataset lacks as not
    run, with the flag that would enable them; they then have no units (none counts as failed).
    A denoiser the user named keeps its units: their failures say what is missing."""
    for d in denoisers:
        missing = sorted(need for need in d.needs & lacking if need in ENABLED_BY)
        if d.loaded and d.spec not in named and missing:
            close_isolated([d.instance])
            d.load_error = "cannot run on this dataset: needs " + ", ".join(ENABLED_BY[m] for m in missing)
            d.instance = None


def check_dataset(dataset: Dataset, scenes: list[str], spp: list[int]) -> None:
    """Every frame the run needs has a manifest record and a file, and a reference: else one line."""
    for scene in scenes:
        info = dataset.scene(scene)
        check_scene_record(scene, info.record)  # a forged size or frame count is refused before any loop
        renders = info.record.get("renders", {})
        missing_spp = [s for s in spp if s not in info.spp]
        if missing_spp:
            raise DatasetError(f"scene {scene!r} was rendered at spp {info.spp}, not {missing_spp}")
        for index in range(info.frame_count):
            key = layout.frame_key(index)
            ref = renders.get(layout.REFERENCE, {}).get(key)
            ref_path = dataset.path(ref.get("file") if ref else layout.reference_path(scene, index), "reference file")
            if not info.has_reference or ref is None or not ref_path.is_file():
                raise DatasetError(
                    f"scene {scene!r} frame {index} has no reference ({ref_path} is "
                    f"{'not in the manifest' if ref is None else 'missing'}): the benchmark needs one for every frame"
                )
            for s in spp:
                record = renders.get(layout.spp_key(s), {}).get(key)
                path = dataset.path(record.get("file") if record else layout.noisy_path(scene, s, index), "frame file")
                if record is None or not path.is_file():
                    raise DatasetError(f"scene {scene!r} frame {index} at {s} spp: {path} is missing")


# --------------------------------------------------------------------------------------------------
# the run


def split_metrics(names: list[str]) -> tuple[list[str], list[str]]:
    """(per-frame metric names, temporal metric names) of a metrics option: metric or set names
    (``noisebase``); [] = every registered metric outside the opt-in sets."""
    try:
        chosen = expand_metric_names(names) if names else default_metric_names()
    except ValueError as exc:
        raise UserInputError(str(exc)) from None
    for name in REQUIRED_METRICS:
        if name not in chosen:
            chosen.append(name)
    spatial = [n for n in dict.fromkeys(chosen) if not get_metric(n).temporal]
    temporal = [n for n in dict.fromkeys(chosen) if get_metric(n).temporal]
    return spatial, temporal


@dataclass(kw_only=True)
class RunPlan:
    run_id: str
    scenes: list[str]
    spp: list[int]
    denoisers: list[LoadedDenoiser]
    spatial: list[str]
    temporal: list[str]
    resumed: bool
    trim: float | None = None  # the config's (None: the robust scores' default)
    samplers: list = field(default_factory=list)  # sampler_units.SamplerPair: measured live, after the denoisers
    replaced: list = field(default_factory=list)  # ReplacedRun: earlier runs of this command with other plugin code

    @property
    def labels(self) -> list[str]:
        return [NOISY] + [d.label for d in self.denoisers if d.loaded] + [p.label for p in self.samplers]

    def unit_keys(self) -> list[UnitKey]:
        """Every unit of the run, (label, scene, spp), scene by scene and spp by spp, labels in order."""
        return [(label, scene, spp) for scene in self.scenes for spp in self.spp for label in self.labels]

    @property
    def total_units(self) -> int:
        return len(self.unit_keys())

    def missing(self, done: set[UnitKey]) -> list[UnitKey]:
        """The units of the run without a row in ``done`` (:meth:`.store.ResultsStore.done_units`)."""
        return [key for key in self.unit_keys() if key not in done]

    def trained_on(self) -> dict[str, list[str]]:
        """Denoisers (label) that were trained on some of this run's scenes, and those scenes."""
        seen = {d.label: sorted(set(self.scenes) & d.trained_scenes) for d in self.denoisers if d.loaded}
        return {label: scenes for label, scenes in seen.items() if scenes}


@dataclass(frozen=True, kw_only=True)
class ReplacedRun:
    """An earlier run of the same command whose plugins' code differs (``specs``): not resumed."""

    run_id: str
    specs: tuple[str, ...]
    units: int


def replaced_runs(store: ResultsStore, run_id: str, *, data_hash: str, config: dict) -> list[ReplacedRun]:
    """The runs on ``data_hash`` whose config is ``config`` but for the code of some plugin."""
    mine = {k: v for k, v in config.items() if k != "code"}
    code = config.get("code", {})
    found = []
    for run in store.runs(data_hash):
        theirs = run.config if isinstance(run.config, dict) else {}
        if run.run_id == run_id or {k: v for k, v in theirs.items() if k != "code"} != mine:
            continue
        old = theirs.get("code", {})
        changed = tuple(spec for spec in sorted(set(code) | set(old)) if code.get(spec) != old.get(spec))
        if changed:
            found.append(ReplacedRun(run_id=run.run_id, specs=changed, units=len(store.units(run.run_id))))
    return found


def prepare_run(dataset: Dataset, config: BenchmarkConfig, store: ResultsStore, *, progress: bool = False) -> RunPlan:
    """Check the inputs, load the denoisers, create (or find) the run in the store."""
    # "all": every scene, for a dataset made only to be benchmarked (the demo's); a learned model's
    # own training scenes would then be among them, so the report says which split it scored.
    scenes = dataset.scenes if config.split == "all" else dataset.split(config.split)
    if not scenes:
        raise UserInputError(f"{dataset.root}: split {config.split!r} has no scenes")
    spp = (
        sorted({int(s) for s in config.spp})
        if config.spp
        else sorted(set.intersection(*(set(dataset.scene(s, renders=False).spp) for s in scenes)))
    )
    if not spp:
        raise UserInputError(f"{dataset.root}: the scenes of split {config.split!r} share no input spp")
    config.spp = spp
    # cheap checks first (names, options, metrics: a typo is refused before any file is hashed),
    # then the files: one stat per file, then one sha256 per file (minutes at 10 000 frames)
    spatial, temporal = split_metrics(config.metrics)
    named = {s.strip() for s in config.denoisers if s.strip() not in ("all", "none")}
    specs = resolve_denoiser_specs(config.denoisers)
    config.denoisers = specs
    config.code = {spec: code for spec in specs if (code := denoiser_code_identity(spec))}
    denoisers = load_denoisers(
        specs, config.options, isolation=config.isolation, limits=config.limits(), required=named
    )
    pairs = []
    if config.samplers:
        taken = {d.label for d in denoisers} | {NOISY}
        pairs = plan_pairs(config.samplers, denoisers, taken, isolation=config.isolation, limits=config.limits())
    check_dataset(dataset, scenes, spp)
    skip_unrunnable(denoisers, named, unmet_needs(dataset, scenes, spp))
    if config.verify:
        # samples files included (cheap): a samples file that is listed must be genuine too
        verify_files(dataset, run_files(dataset, scenes, spp, samples=True), progress=progress)
    data_hash = dataset_hash(dataset)
    run_id = run_identity(data_hash, config)
    created = store.ensure_run(
        run_id,
        dataset_hash=data_hash,
        dataset_path=str(dataset.root.resolve()),
        config=config.as_dict(),
        versions=software_versions(),
    )
    store.add_denoiser(
        run_id=run_id, label=NOISY, spec=NOISY, kind="input", needs={"color"}, temporal=False, load_error=None
    )
    plan = RunPlan(
        run_id=run_id,
        scenes=scenes,
        spp=spp,
        denoisers=denoisers,
        spatial=spatial,
        temporal=temporal,
        resumed=not created,
        trim=config.trim,
        replaced=replaced_runs(store, run_id, data_hash=data_hash, config=config.as_dict()) if created else [],
    )
    seen = plan.trained_on()
    for d in denoisers:
        store.add_denoiser(
            run_id=run_id,
            label=d.label,
            spec=d.spec,
            kind="denoiser",
            needs=d.needs,
            temporal=d.temporal,
            load_error=d.load_error,
            trained_on=seen.get(d.label, []) if d.trained_scenes else None,
        )
    if pairs:
        plan.samplers = pairs
        register_pairs(store, run_id, pairs, denoisers=denoisers)
    return plan


def pending_groups(plan: RunPlan, done: set[UnitKey]) -> list[tuple[str, int, list[str]]]:
    """(scene, spp, labels still to measure) for every sequence with work left, in the plan's order."""
    groups: dict[tuple[str, int], list[str]] = {}
    for label, scene, spp in plan.missing(done):
        groups.setdefault((scene, spp), []).append(label)
    return [(scene, spp, labels) for (scene, spp), labels in groups.items()]


def measure_group(
    dataset: Dataset, plan: RunPlan, scene: str, spp: int, labels: list[str], instances: dict
) -> Iterable[UnitRecord]:
    """Load the sequence once and yield the unit of each label on it."""
    pairs = {p.label: p for p in plan.samplers}
    wants_samples = any("samples" in d.needs for d in plan.denoisers if d.label in labels)
    stored = [label for label in labels if label not in pairs]
    sequence = dataset.sequence(scene, spp, samples=wants_samples) if stored else None
    if len(stored) < len(labels):
        live = [pairs[label] for label in labels if label in pairs]
        yield from measure_pairs(dataset, plan, scene, spp=spp, pairs=live, instances=instances)
    for label in stored:
        if label != NOISY and label not in instances:
            raise KeyError(f"no denoiser instance for {label!r}")  # never measure a denoiser as the input
        yield measure_unit(
            label, instances.get(label), sequence, spatial=plan.spatial, temporal=plan.temporal, trim=plan.trim
        )


def run_local(
    dataset: Dataset, plan: RunPlan, store: ResultsStore, on_unit: Callable[[UnitRecord, bool], None]
) -> None:
    instances = {d.label: d.instance for d in plan.denoisers if d.instance is not None}
    for scene, spp, _ in pending_groups(plan, store.done_units(plan.run_id)):
        # re-read what is done: another process may be working on the same run
        done = store.done_units(plan.run_id)
        labels = [label for label, s, p in plan.missing(done) if (s, p) == (scene, spp)]
        if not labels:
            continue
        for unit in measure_group(dataset, plan, scene, spp=spp, labels=labels, instances=instances):
            on_unit(unit, store.write_unit(plan.run_id, unit))
