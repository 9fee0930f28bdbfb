"""The data-value study: the same model, trained at the same budget on several training sets drawn
from the generator's families, scored on a third-party dataset through the normal benchmark.

Inputs are datasets made by ``generate-dataset``: a **pool** of family scenes (``--families
... --scenes N``) and one or more **third-party** datasets (``--scene-list``, ``--usd``/``--mitsuba``:
scenes nobody here wrote; several because one ``generate`` run has one camera choice, so a list
rendered from its own sensors and one from the orbit are two datasets). Scores pool the scenes of
all third-party datasets as if they were one run: every aggregate and interval is over their union.
Training sets are subsets of the pool's scenes (``train_scenes`` of
:class:`~denoisebench.models.training_options.TrainOptions`, so training is ``denoisebench train``'s
own loop), named by :func:`resolve_sets`:

* ``full``: every trainable pool scene (the generator's whole mix);
* ``family:F``: family F alone (e.g. ``family:cornell``);
* ``without:E``: the mix without the families that declare effect E (``without:textures``);
* ``leave_one_out:F``: the mix without family F (``loo:F`` for short);
* ``n:K``: the first K scenes of the mix, taken round-robin over the families (the scaling curve's
  points; ``--scaling 8,16`` adds them, and ``full`` is the curve's last point).

Trainable pool scenes are those outside its val split (which validates every run) and outside
held-out variants (``variants["pool"] == "held_out"``). Every run has the same budget: steps ×
batch × crop pixels, one seed per run (several seeds: their spread is shown).

Scores: each checkpoint is benchmarked on each whole third-party dataset (split ``all``) at one spp
(default 4) by :func:`~denoisebench.benchmark.run.run_benchmark` into ``OUT/study.sqlite``, and read
as a report reads them: corrected scores aggregated over scenes by the metric's rule with their 95 %
bootstrap intervals over scenes (:func:`~denoisebench.analysis.summary.metric_cell`). The scenes a
report would set apart are judged once, from the reference run (noisy input, cross_bilateral,
OIDN), and left out of every aggregate alike, so rows compare over the same scenes; the per-scene
table still shows them.

``report_only`` (``--report-only``) trains nothing: it reports the finished parts, scores the
checkpoints already trained to the budget whose scores are missing, and lists the rest as not run.
Parts of one study run side by side in several folders (one process per model, say) are gathered
by copying their ``checkpoints/`` (and ``parts/``) into one folder and reporting there; copying the
checkpoints alone scores them anew with today's code.

Resumable: a checkpoint's name carries its budget; a run that stopped is resumed from its last
checkpoint (same seed, same batches); a benchmark run's identity includes the checkpoint's sha256
(a retrained checkpoint is scored anew); a finished part's record ``OUT/parts/*.json`` is reused.

Pitfalls: the pool and the third-party datasets must not share scenes (a family scene is not
third-party), nor may two third-party datasets (scene names key every score); scaling points with
fewer scenes than families hold fewer families too (the curve
measures the generator's scenes as it makes them, variety and count together).
"""

from __future__ import annotations

import hashlib
import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

from tqdm import tqdm

from denoisebench.analysis import aggregate as agg
from denoisebench.analysis.summary import RunData, metric_cell
from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.dataset import open_dataset
from denoisebench.errors import UserInputError
from denoisebench.reports.run_inputs import run_data, set_apart_of
from denoisebench.results.names import NOISY
from denoisebench.results.records import RunRows
from denoisebench.results.store import ResultsStore

# Lazy imports: torch and the trainer only where a model is trained; matplotlib only for the figure.

STORE_NAME = "study.sqlite"
REPORT_JSON = "study.json"
REPORT_MD = "study.md"
FIGURE = "scaling.png"
#: Metrics scored (relmse always comes with the benchmark); the first leads tables and the curve.
METRICS = ("relmse_robust", "flip")
DEFAULT_SETS = ("full", "family:cornell", "without:textures")
REFERENCES = ("cross_bilateral", "oidn")


@dataclass(frozen=True, kw_only=True)
class TrainingSet:
    """One training set: its name (:func:`resolve_sets`), kind, pool scenes and their families."""

    name: str
    kind: str  # full | family | without | leave_one_out | scaling
    scenes: tuple[str, ...]
    families: tuple[str, ...]


@dataclass(frozen=True, kw_only=True)
class StudyOptions:
    """What ``denoisebench study data-value`` asks for (see the module docstring)."""

    out: Path
    pool: Path
    third_party: tuple[Path, ...]
    models: tuple[str, ...] = ("kpcn", "rae")
    sets: tuple[str, ...] = DEFAULT_SETS
    scaling: tuple[int, ...] = ()
    seeds: tuple[int, ...] = (0,)
    steps: int = 300
    batch_size: int = 8
    crop: int = 32
    lr: float = 1e-3
    spp: int = 4
    references: tuple[str, ...] = REFERENCES
    threads: int = 1
    progress: bool = True
    #: write the report from the finished parts only: train and score nothing new (a study stopped
    #: at a deadline, or parts gathered from several study folders run side by side)
    report_only: bool = False


@dataclass(frozen=True, kw_only=True)
class PoolScene:
    name: str
    family: str
    effects: tuple[str, ...]


def trainable_scenes(ds) -> list[PoolScene]:
    """Pool scenes a training set may hold: not in the val split, not a held-out variant, from a family."""
    val = set(ds.split("val"))
    out = []
    for name in ds.scenes:
        record = ds.scene(name).record
        family = str(record.get("family") or "")
        if name in val or not family or family == "usd" or (record.get("variants") or {}).get("pool") == "held_out":
            continue
        effects = record.get("effects") or {}
        declared = effects.get("declared", []) if isinstance(effects, dict) else list(effects)
        out.append(PoolScene(name=name, family=family, effects=tuple(declared)))
    return out


def round_robin(scenes: list[PoolScene]) -> list[PoolScene]:
    """Scenes ordered one per family at a time (families and scenes by name): prefixes stay mixed."""
    by_family: dict[str, list[PoolScene]] = {}
    for scene in sorted(scenes, key=lambda s: s.name):
        by_family.setdefault(scene.family, []).append(scene)
    order, depth = [], 0
    while len(order) < len(scenes):
        order += [members[depth] for _, members in sorted(by_family.items()) if depth < len(members)]
        depth += 1
    return order


def _set(name: str, kind: str, scenes: list[PoolScene]) -> TrainingSet:
    return TrainingSet(
        name=name,
        kind=kind,
        scenes=tuple(sorted(s.name for s in scenes)),
        families=tuple(sorted({s.family for s in scenes})),
    )


def resolve_sets(names, scaling, scenes: list[PoolScene]) -> list[TrainingSet]:
    """The training sets ``names`` and the scaling points ``scaling`` name, over the trainable ``scenes``.

    An unknown name, a family or effect the pool lacks, or a set left empty is a UserInputError.
    A scaling point at or above the pool's size is ``full`` itself (the curve's last point)."""
    if not scenes:
        raise UserInputError("the pool has no trainable scene (family scenes outside its val split)")
    families = sorted({s.family for s in scenes})
    effects = sorted({e for s in scenes for e in s.effects})
    out: dict[str, TrainingSet] = {}
    for raw in list(names) + ["full"]:
        kind, _, arg = raw.partition(":")
        kind = {"loo": "leave_one_out"}.get(kind, kind)
        if kind == "full" and not arg:
            chosen = scenes
        elif kind in ("family", "leave_one_out") and arg:
            if arg not in families:
                raise UserInputError(
                    f"training set {raw!r}: the pool has no family {arg!r} (families: {', '.join(families)})"
                )
            chosen = [s for s in scenes if (s.family == arg) == (kind == "family")]
        elif kind == "without" and arg:
            if arg not in effects:
                raise UserInputError(
                    f"training set {raw!r}: no pool family declares {arg!r} (effects: {', '.join(effects)})"
                )
            chosen = [s for s in scenes if arg not in s.effects]
        else:
            raise UserInputError(
                f"unknown training set {raw!r}: use full, family:F, without:EFFECT, leave_one_out:F (loo:F) or n:K"
            )
        if not chosen:
            raise UserInputError(f"training set {raw!r} holds no pool scene")
        name = "full" if kind == "full" else f"{kind}:{arg}"
        out.setdefault(name, _set(name, kind, chosen))
    ordered = round_robin(scenes)
    for count in sorted(set(int(c) for c in scaling)):
        if count < 1:
            raise UserInputError(f"--scaling wants positive scene counts (got {count})")
        if count < len(scenes):
            out.setdefault(f"n:{count}", _set(f"n:{count}", "scaling", ordered[:count]))
    return list(out.values())


def _plain(value):
    """An option as JSON holds it: paths as text, tuples of paths as lists of text."""
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, tuple) and any(isinstance(v, Path) for v in value):
        return [str(v) for v in value]
    return value


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def part_stem(model: str, training_set: str, seed: int, options: StudyOptions) -> str:
    """File stem of one (model, set, seed) run: the budget is in it, so another budget trains anew."""
    safe = training_set.replace(":", "-")
    return f"{model}__{safe}__seed{seed}__{options.steps}x{options.batch_size}x{options.crop}"


def _train(options: StudyOptions, model: str, training_set: TrainingSet, seed: int, checkpoint: Path) -> dict:
    """Train (or resume) one run to ``options.steps``; return the checkpoint's metadata."""
    from denoisebench.models.checkpoint import load_checkpoint
    from denoisebench.models.training import train
    from denoisebench.models.training_options import TrainOptions

    done = 0
    if checkpoint.is_file():
        done = int(load_checkpoint(checkpoint, expect_model=model)["meta"].get("steps", 0))
    if done >= options.steps:
        return dict(load_checkpoint(checkpoint)["meta"])
    return train(
        TrainOptions(
            model=model,
            data=str(options.pool),
            config="small",
            steps=options.steps - done,
            out=str(checkpoint),
            resume=str(checkpoint) if done else None,
            seed=seed,
            batch_size=options.batch_size,
            crop=options.crop,
            lr=options.lr,
            threads=options.threads,
            device="cpu",
            progress=options.progress,
            train_scenes=training_set.scenes,
        )
    )


def _benchmark(options: StudyOptions, store, denoisers: list[str], extra: dict | None = None) -> list[str]:
    """Run (or resume) the benchmark of ``denoisers`` on each third-party dataset; return the run ids."""
    return benchmark_third_party(options.third_party, options.spp, store, denoisers, extra, options.progress)


def open_third_party(folders) -> list:
    """Open the third-party datasets; refuse none, and a scene given twice (scene names key every score)."""
    if not folders:
        raise UserInputError("--third-party: give at least one dataset of third-party scenes")
    thirds, owner = [], {}
    for folder in folders:
        third = open_dataset(folder)
        twice = sorted(set(owner) & set(third.scenes))
        if twice:
            raise UserInputError(f"{folder}: scene {twice[0]} is also in {owner[twice[0]]}; give each scene once")
        owner.update({name: folder for name in third.scenes})
        thirds.append(third)
    return thirds


def benchmark_third_party(
    folders, spp: int, store, denoisers: list[str], extra: dict | None = None, progress: bool = True
) -> list[str]:
    """Run (or resume) the benchmark of ``denoisers`` on each dataset of ``folders`` (split ``all``, one
    ``spp``) into ``store``; return the run ids. ``extra``: ``{"options": {denoiser: {...}}, "nonce": str}``
    (a checkpoint's options, and its sha256 so that new weights are new runs)."""
    run_ids = []
    for folder in folders:
        config = BenchmarkConfig(
            denoisers=denoisers,
            spp=[spp],
            split="all",
            metrics=list(METRICS),
            options=(extra or {}).get("options", {}),
            nonce=(extra or {}).get("nonce"),
        )
        run_ids.append(run_benchmark(open_dataset(folder), config, store, progress=progress).run_id)
    return run_ids


def pooled_run_data(store, run_ids: list[str]) -> RunData:
    """The rows of several runs (one per third-party dataset, same denoisers) as one run's: units,
    frames and sequence rows side by side, so aggregates and intervals are over the union of scenes.

    The first run's record and label order stand for all. Pitfall: the runs must not share a scene
    (:func:`run_study` refuses a scene in two third-party datasets before anything runs)."""
    rows = [store.run_rows(run_id) for run_id in run_ids]
    first = rows[0]
    return RunData(
        RunRows(
            run=first.run,
            entries=first.entries,
            units=[u for one in rows for u in one.units],
            frames=[f for one in rows for f in one.frames],
            sequences=[q for one in rows for q in one.sequences],
        )
    )


def read_scores(data: RunData, label: str, spp: int, kept: list[str]) -> dict:
    """{metric: {value, low, high, raw, rule, per_scene: {scene: corrected}}} of ``label`` in ``data``
    (the runs of every third-party dataset, pooled by :func:`pooled_run_data`).

    ``value``/``low``/``high``: the corrected aggregate over ``kept`` and its 95 % interval over
    scenes (the report's cell); ``per_scene``: every scene's corrected score (or the raw one where
    the metric has no floor), set-apart scenes included."""
    out = {}
    for metric in METRICS:
        cell = metric_cell(data, label, spp, metric, kept)
        mine, floors, ses = data.per_scene(label, spp, metric, None)
        per_scene = dict(mine)
        if floors and len(floors) == len(mine):
            per_scene = agg.corrected_values(mine, floors, ses, agg.higher_is_better(metric))[0]
        out[metric] = {
            "value": cell.value,
            "low": cell.low,
            "high": cell.high,
            "raw": cell.raw,
            "rule": cell.rule,
            "corrected": cell.floor is not None,
            "scenes": cell.scenes,
            "per_scene": {scene: float(v) for scene, v in sorted(per_scene.items())},
        }
    return out


@dataclass(kw_only=True)
class StudyResult:
    """What :func:`run_study` returns and writes as ``study.json``."""

    options: dict
    pool: dict
    third_party: dict
    sets: list[dict]
    parts: list[dict] = field(default_factory=list)
    references: dict = field(default_factory=dict)
    scaling: dict = field(default_factory=dict)
    #: parts asked for but not run (``report_only``): "model set seed"
    missing: list[str] = field(default_factory=list)


def set_apart_in(store, run_ids: list[str], datasets) -> tuple[list[str], dict]:
    """(every scene of the runs, {scene a report sets apart: reason}): one run per third-party dataset."""
    scenes, apart = [], {}
    for run_id, dataset in zip(run_ids, datasets):
        data = run_data(store, run_id)
        scenes += list(data.scenes)
        apart.update({u.scene: u.reason for u in set_apart_of(data, dataset)})
    return scenes, apart


def kept_scenes(scenes: list[str], apart) -> list[str]:
    """The scenes scored: those not set apart (all of them when every one is set apart)."""
    return [s for s in scenes if s not in apart] or list(scenes)


def _references(options: StudyOptions, store, datasets) -> tuple[dict, list[str], dict]:
    """(scores of the noisy input and the references, scenes kept, {scene set apart: reason})."""
    run_ids = _benchmark(options, store, list(options.references))
    scenes, apart = set_apart_in(store, run_ids, datasets)
    kept = kept_scenes(scenes, apart)
    pooled = pooled_run_data(store, run_ids)
    scores = {label: read_scores(pooled, label, options.spp, kept) for label in [NOISY, *options.references]}
    return scores, kept, apart


def run_study(options: StudyOptions, on_part=None) -> StudyResult:
    """Train, score and report every part that is not done yet; return the study's numbers.

    ``on_part(result)`` is called after each part with the numbers so far (the command writes the
    report then, so a study stopped half-way still has one)."""
    if options.steps < 1 or options.batch_size < 1 or options.crop < 4:
        raise UserInputError("--steps and --batch-size must be >= 1 and --crop >= 4")
    pool = open_dataset(options.pool)
    thirds = open_third_party(options.third_party)
    for folder, third in zip(options.third_party, thirds):
        shared = sorted(set(pool.scenes) & set(third.scenes))
        if shared:
            raise UserInputError(
                f"{folder}: scene {shared[0]} is also in the pool; third-party scenes must not be trained on"
            )
        if options.spp not in {s for name in third.scenes for s in third.scene(name).spp}:
            raise UserInputError(f"{folder}: no {options.spp}-spp inputs to score at")
    scenes = trainable_scenes(pool)
    sets = resolve_sets(options.sets, options.scaling, scenes)
    out = Path(options.out)
    (out / "checkpoints").mkdir(parents=True, exist_ok=True)
    (out / "parts").mkdir(parents=True, exist_ok=True)
    result = StudyResult(
        options={k: _plain(v) for k, v in asdict(options).items() if k != "progress"},
        pool={"path": str(options.pool), "config_hash": pool.config_hash, "trainable": [s.name for s in scenes]},
        third_party={
            "path": ", ".join(str(folder) for folder in options.third_party),
            "datasets": [
                {"path": str(folder), "config_hash": third.config_hash, "scenes": list(third.scenes)}
                for folder, third in zip(options.third_party, thirds)
            ],
            "scenes": [name for third in thirds for name in third.scenes],
        },
        sets=[asdict(s) for s in sets],
    )
    with ResultsStore(out / STORE_NAME) as store:
        references, kept, apart = _references(options, store, thirds)
        result.references = references
        result.third_party.update({"kept": kept, "set_apart": apart})
        jobs = [(m, s, seed) for m in options.models for s in sets for seed in options.seeds]
        order = {(m, s.name, seed): i for i, (m, s, seed) in enumerate(jobs)}
        # finished parts first: a study extended with more seeds reports the old ones at once
        jobs.sort(key=lambda job: _finished(options, *job, kept) is None)
        if options.report_only:
            ready = [job for job in jobs if _trained(options, *job[:3], kept)]
            result.missing = [f"{m} {s.name} seed {seed}" for m, s, seed in jobs if (m, s, seed) not in ready]
            jobs = ready
        bar = tqdm(jobs, desc="study: model × set × seed", unit="run", disable=not options.progress, file=sys.stderr)
        for model, training_set, seed in bar:
            bar.set_postfix_str(f"{model} {training_set.name} seed {seed}")
            result.parts.append(_part(options, store, model, training_set, seed, kept))
            result.parts.sort(key=lambda p: order[(p["model"], p["set"], p["seed"])])
            if on_part is not None:
                result.scaling = scaling_curve(result.parts, sets, options.models)
                on_part(result)
        bar.close()
    result.scaling = scaling_curve(result.parts, sets, options.models)
    return result


def _finished(options: StudyOptions, model: str, training_set: TrainingSet, seed: int, kept: list[str]) -> dict | None:
    """The record of a finished part with the same scenes and scored scenes, else None."""
    stem = part_stem(model, training_set.name, seed, options)
    record_path = Path(options.out) / "parts" / f"{stem}.json"
    if record_path.is_file() and (Path(options.out) / "checkpoints" / f"{stem}.pt").is_file():
        record = json.loads(record_path.read_text())
        if record.get("scenes") == list(training_set.scenes) and record.get("kept") == kept:
            return record
    return None


def _trained(options: StudyOptions, model: str, training_set: TrainingSet, seed: int, kept: list[str]) -> bool:
    """A finished part, or a checkpoint trained to the budget whose scores are still to be taken."""
    if _finished(options, model, training_set, seed, kept) is not None:
        return True
    checkpoint = Path(options.out) / "checkpoints" / f"{part_stem(model, training_set.name, seed, options)}.pt"
    if not checkpoint.is_file():
        return False
    from denoisebench.models.checkpoint import load_checkpoint

    return int(load_checkpoint(checkpoint, expect_model=model)["meta"].get("steps", 0)) >= options.steps


def _part(options: StudyOptions, store, model: str, training_set: TrainingSet, seed: int, kept: list[str]) -> dict:
    """One (model, set, seed): trained, scored and recorded (a finished record is reused)."""
    finished = _finished(options, model, training_set, seed, kept)
    if finished is not None:
        return finished
    stem = part_stem(model, training_set.name, seed, options)
    record_path = Path(options.out) / "parts" / f"{stem}.json"
    checkpoint = Path(options.out) / "checkpoints" / f"{stem}.pt"
    meta = _train(options, model, training_set, seed, checkpoint)
    digest = _sha256(checkpoint)
    run_ids = _benchmark(
        options,
        store,
        [model],
        {"options": {model: {"checkpoint": str(checkpoint.resolve())}}, "nonce": f"checkpoint sha256 {digest}"},
    )
    record = {
        "model": model,
        "set": training_set.name,
        "kind": training_set.kind,
        "seed": seed,
        "scenes": list(training_set.scenes),
        "families": list(training_set.families),
        "steps": int(meta.get("steps", options.steps)),
        "budget_pixels": options.steps * options.batch_size * options.crop * options.crop,
        "train_seconds": float(meta.get("seconds", 0.0)),
        "checkpoint": str(checkpoint),
        "checkpoint_sha256": digest,
        "run_ids": run_ids,
        "kept": kept,
        "scores": read_scores(pooled_run_data(store, run_ids), model, options.spp, kept),
    }
    record_path.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    return record


def seed_summary(parts: list[dict], metric: str) -> dict:
    """Mean over seeds of the aggregate and its interval ends, and the seeds' min and max."""
    values = [p["scores"][metric]["value"] for p in parts if p["scores"][metric]["value"] is not None]
    if not values:
        return {"value": None, "low": None, "high": None, "seeds": len(parts), "spread": None}
    lows = [p["scores"][metric]["low"] for p in parts if p["scores"][metric]["low"] is not None]
    highs = [p["scores"][metric]["high"] for p in parts if p["scores"][metric]["high"] is not None]
    mean = lambda xs: sum(xs) / len(xs) if xs else None  # noqa: E731
    return {
        "value": mean(values),
        "low": mean(lows),
        "high": mean(highs),
        "seeds": len(values),
        "spread": [min(values), max(values)] if len(values) > 1 else None,
    }


def scaling_curve(parts: list[dict], sets: list[TrainingSet], models) -> dict:
    """{model: [{scenes, set, metric: seed summary}]}: error against the number of training scenes
    for the mix's prefixes (``n:K``) and ``full``, in order of scene count."""
    points = [s for s in sets if s.kind in ("scaling", "full")]
    out = {}
    for model in models:
        rows = []
        for s in sorted(points, key=lambda s: len(s.scenes)):
            mine = [p for p in parts if p["model"] == model and p["set"] == s.name]
            if mine:
                rows.append({"scenes": len(s.scenes), "set": s.name, **{m: seed_summary(mine, m) for m in METRICS}})
        out[model] = rows
    return out
