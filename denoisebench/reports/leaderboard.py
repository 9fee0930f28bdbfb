"""``denoisebench leaderboard``'s ranking, loaded: picks the dataset and its runs in the store, reads
each run as its report reads it (its rows, the scenes its report sets apart, its time model) and
hands them to :mod:`denoisebench.analysis.ranking`, which ranks.

Notes
-----
* Runs are read newest first; a run is loaded only when it holds a label at the spp that no newer
  run has ranked.
* A run whose dataset folder is gone is ranked from what the store holds: no scene set apart, its
  seconds as measured at the dataset's size; its note says so.
"""

from __future__ import annotations

from denoisebench.analysis.ranking import Entry, Ranking, RunView, best_first, labels_to_rank, run_entries
from denoisebench.analysis.time_model import build_time_model
from denoisebench.dataset import open_dataset
from denoisebench.errors import UserInputError
from denoisebench.metrics import get_metric
from denoisebench.reports.run_inputs import run_data, set_apart_of
from denoisebench.results.store import ResultsStore
from denoisebench.results.timings import read_timings


def pick_dataset(store: ResultsStore, dataset: str | None) -> str:
    """The dataset hash to rank: the one given (hash prefix or dataset path), else the newest run's."""
    runs = store.runs()
    if not runs:
        raise UserInputError(f"{store.path} holds no runs")
    if dataset is None:
        return runs[0].dataset_hash
    matches = {
        r.dataset_hash
        for r in runs
        if r.dataset_hash.startswith(dataset) or r.dataset_path.rstrip("/") == dataset.rstrip("/")
    }
    if len(matches) != 1:
        known = ", ".join(sorted({f"{r.dataset_hash[:12]} ({r.dataset_path})" for r in runs}))
        raise UserInputError(f"dataset {dataset!r} matches {len(matches)} datasets in {store.path}; known: {known}")
    return matches.pop()


def leaderboard(
    store: ResultsStore,
    metric: str = "relmse_robust",
    spp: int | None = None,
    *,
    dataset: str | None = None,
    sampler: str | None = None,
    run: str | None = None,
    split: str | None = None,
    include_unresolved: bool = False,
    time_at: tuple[int, int] | None = None,
) -> Ranking:
    """The ranking (:class:`~denoisebench.analysis.ranking.Ranking`, entries best first) of ``metric``
    at ``spp`` on one dataset.

    ``sampler``: rank only the entries whose input that live sampler made (``""``: only those on the
    dataset's stored inputs, the noisy input among them); None: every entry. ``run`` (a run id
    prefix) and ``split`` keep only the runs they name. Each run is read as its report reads it: the
    scenes its report sets apart are left out (unless ``include_unresolved``; judged when the run's
    dataset folder is still there), scores are the report's corrected cells, and seconds are the
    run's time model at ``time_at`` (default the report's, 1920×1080, projected)."""
    try:
        m = get_metric(metric)
    except ValueError as exc:
        raise UserInputError(str(exc)) from None
    data_hash = pick_dataset(store, dataset)
    runs = store.runs(data_hash)  # newest first
    if run is not None:
        runs = [r for r in runs if r.run_id.startswith(run)]
        if not runs:
            raise UserInputError(f"no run {run!r} on dataset {data_hash[:12]} in {store.path}")
    if split is not None:
        splits = sorted({str(r.config.get("split")) for r in runs})
        runs = [r for r in runs if str(r.config.get("split")) == split]
        if not runs:
            raise UserInputError(f"no run on split {split!r}; runs here are on: {', '.join(splits)}")
    available = sorted({u.spp for r in runs for u in store.units(r.run_id)})
    if not available:
        raise UserInputError(f"{store.path}: no results for dataset {data_hash[:12]}")
    if spp is None:
        spp = available[0]
    elif spp not in available:
        raise UserInputError(f"no results at {spp} spp; measured: {', '.join(map(str, available))}")
    if sampler:
        known = sorted({d.sampler for r in runs for d in store.denoisers(r.run_id) if d.sampler})
        if sampler not in known:
            raise UserInputError(
                f"no results of sampler {sampler!r} on dataset {data_hash[:12]}; samplers measured: "
                + (", ".join(known) or "none")
            )
    entries: dict[str, Entry] = {}
    unmeasured: dict[str, Entry] = {}
    notes: list[str] = []
    for row in runs:
        labels = labels_to_rank(store.units(row.run_id), store.denoisers(row.run_id), spp=spp, sampler=sampler)
        labels -= set(entries)
        if not labels:
            continue
        view, note = _as_its_report(store, row, include_unresolved=include_unresolved, time_at=time_at)
        notes += note
        measured, missing = run_entries(view, labels, spp=spp, metric=m.name)
        entries.update(measured)
        for label, entry in missing.items():
            unmeasured.setdefault(label, entry)
    for label, entry in unmeasured.items():
        entries.setdefault(label, entry)
    return Ranking(
        metric=m,
        spp=spp,
        data_hash=data_hash,
        entries=best_first(list(entries.values()), m.higher_is_better),
        notes=list(dict.fromkeys(notes)),
    )


def _as_its_report(store: ResultsStore, row, *, include_unresolved: bool, time_at) -> tuple[RunView, list[str]]:
    """(one run as its report reads it, lines saying how)."""
    data = run_data(store, row.run_id)
    scenes = set(data.scenes)
    try:
        dataset = open_dataset(row.dataset_path, verify=False)
    except Exception:  # noqa: BLE001 - moved or deleted: rank what the store holds, and say so
        dataset = None
    if dataset is None:
        note = (
            f"run {row.run_id[:8]}: its dataset folder {row.dataset_path} is not readable here: no scene set apart, "
            "seconds as measured at the dataset's size (its report projects them)"
        )
        return RunView(row=row, data=data, scenes=scenes, model=None), [note]
    notes = []
    apart = set_apart_of(data, dataset)
    if apart and not include_unresolved:
        scenes -= {u.scene for u in apart}
        notes.append(
            f"run {row.run_id[:8]}: left out as in its report: "
            + "; ".join(f"{u.scene} ({u.reason})" for u in apart)
            + " (--include-unresolved keeps them)"
        )
    record = dataset.scene(data.scenes[0]).record if data.scenes else {}
    size = (int(record.get("width", 0)), int(record.get("height", 0)))
    model = build_time_model(data, read_timings(store, row.run_id), time_at, dataset_size=size) if size[0] else None
    if model is not None:
        w, h = model.time_at
        notes.append(
            f"seconds per frame at {w}×{h}" + (" (projected, as in the run's report)" if model.projected else "")
        )
    return RunView(row=row, data=data, scenes=scenes, model=model), notes
