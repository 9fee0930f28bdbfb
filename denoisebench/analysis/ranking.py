"""The leaderboard: denoisers ranked by one metric at one input spp, across the runs on one dataset.

Each denoiser's entry comes from the newest run that measured it at that spp (a rerun with newer
code replaces the older number); the run id and its date are shown, so numbers from different runs
are never silently mixed. The value combines the scenes by the metric's aggregation rule
(:mod:`.aggregate`: per scene the mean over its frames, or the sequence's temporal value; then the
mean, the geometric mean, or the geometric mean of the ratio to the same run's noisy input), so a
bright scene never decides a linear score; a score with a reference-noise floor is ranked corrected,
as the report's tables show it (the same :func:`.analysis.metric_cell`); failed units count as
failed, not as missing, and rank last.

Notes
-----
* Runs are grouped by **dataset hash** (the manifest's content without timings), not by path: a
  dataset moved to another folder is the same dataset; one regenerated with another seed is not.
* Seconds are those of the run the entry comes from; runs made on different machines or under
  different load are not comparable in time, only in accuracy.
* **Samplers are a dimension.** Every entry says which live sampler made its input (None: the
  dataset's stored input) and which denoiser ran on it (:class:`~.records.EntryRow`);
  ``leaderboard(sampler=...)`` ranks one sampler's entries (``""``: the stored inputs' only), and
  :func:`by_sampler` groups a ranking by sampler.
* Per-scene values come from :class:`.run_index.RunIndex`, the one place they are computed.
"""

from __future__ import annotations

from dataclasses import dataclass

from denoisebench.analysis.summary import RunData, metric_cell, set_apart
from denoisebench.analysis.time_model import build_time_model
from denoisebench.dataset import open_dataset
from denoisebench.errors import UserInputError
from denoisebench.metrics import get_metric
from denoisebench.results.finite import finite_mean
from denoisebench.results.store import ResultsStore
from denoisebench.results.timings import read_timings


@dataclass(kw_only=True)
class Entry:
    denoiser: str
    value: float | None
    frames: int
    failed_units: int
    denoise_seconds: float | None  # per frame
    total_seconds: float | None  # per frame: render at the spp + denoise
    run_id: str
    created_at: str
    sampler: str | None = None  # the live sampler that made the input (None: the dataset's stored input)
    denoiser_label: str | None = None  # the denoiser run on it (None: none)


@dataclass(kw_only=True)
class Ranking:
    """What :func:`leaderboard` returns: the metric, spp, dataset hash, entries best first, and the lines
    that say how the numbers were read (scenes left out, the seconds' basis)."""

    metric: object
    spp: int
    data_hash: str
    entries: list[Entry]
    notes: list[str]

    def text(self) -> str:
        """:func:`format_leaderboard` of this ranking, its notes included."""
        return format_leaderboard(self.metric, self.spp, self.data_hash, entries=self.entries, notes=self.notes)


def ranks(entries: list[Entry]) -> list[int | None]:
    """Competition ranks of entries sorted best first: equal values share a rank (1, 1, 3); None unranked."""
    out: list[int | None] = []
    for i, e in enumerate(entries):
        if e.value is None:
            out.append(None)
        elif i and entries[i - 1].value == e.value:
            out.append(out[-1])
        else:
            out.append(i + 1)
    return out


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
    dataset: str | None = None,
    sampler: str | None = None,
    *,
    run: str | None = None,
    split: str | None = None,
    include_unresolved: bool = False,
    time_at: tuple[int, int] | None = None,
) -> Ranking:
    """The ranking (:class:`Ranking`, entries best first) of ``metric`` at ``spp`` on one dataset.

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
        run_id = row.run_id
        dimension = {d.label: (d.sampler, d.denoiser_label) for d in store.denoisers(run_id)}
        all_units = store.units(run_id)
        labels = {
            u.denoiser
            for u in all_units
            if u.spp == spp and (sampler is None or (dimension.get(u.denoiser, (None,))[0] or "") == sampler)
        } - set(entries)
        if not labels:
            continue
        data = RunData(store, run_id)
        scenes, model, note = _as_its_report(store, data, row, include_unresolved=include_unresolved, time_at=time_at)
        notes += note
        for label in sorted(labels):
            ok = [f for f in data.ok_frames(label, spp) if f.scene in scenes]
            # the report's own cell: corrected for the reference's noise where the score has a floor
            value = metric_cell(data, label, spp, metric=m.name, scenes=sorted(scenes)).value
            failed = sum(1 for u in data.units_of(label, spp) if u.status != "ok")
            where = dimension.get(label, (None, label))
            if value is None and not failed:  # this run did not compute the metric: look further back
                sampler, denoiser_label = where
                unmeasured.setdefault(
                    label,
                    Entry(
                        denoiser=label,
                        value=None,
                        frames=len(ok),
                        failed_units=0,
                        denoise_seconds=None,
                        total_seconds=None,
                        run_id=run_id,
                        created_at=row.created_at,
                        sampler=sampler,
                        denoiser_label=denoiser_label,
                    ),
                )
                continue
            denoise = finite_mean(f.denoise_seconds for f in ok)
            total = finite_mean(f.total_seconds for f in ok)
            if model is not None:
                denoise, total = model.denoise_seconds(label, spp), model.total_seconds(label, spp)
            sampler, denoiser_label = where
            entries[label] = Entry(
                denoiser=label,
                value=value if not failed else None,
                frames=len(ok),
                failed_units=failed,
                denoise_seconds=denoise,
                total_seconds=total,
                run_id=run_id,
                created_at=row.created_at,
                sampler=sampler,
                denoiser_label=denoiser_label,
            )
    for label, entry in unmeasured.items():
        entries.setdefault(label, entry)
    sign = -1.0 if m.higher_is_better else 1.0
    ranked = sorted(
        entries.values(), key=lambda e: (e.value is None, sign * e.value if e.value is not None else 0.0, e.denoiser)
    )
    return Ranking(metric=m, spp=spp, data_hash=data_hash, entries=ranked, notes=list(dict.fromkeys(notes)))


def _as_its_report(store, data, row, include_unresolved: bool, time_at) -> tuple[set[str], object, list[str]]:
    """(scenes the run's report aggregates, its time model or None, lines saying how) for one run."""
    scenes = set(data.scenes)
    try:
        dataset = open_dataset(row.dataset_path, verify=False)
    except Exception:  # noqa: BLE001 - moved or deleted: rank what the store holds, and say so
        dataset = None
    if dataset is None:
        return (
            scenes,
            None,
            [
                f"run {row.run_id[:8]}: its dataset folder {row.dataset_path} is not readable here: no scene set apart, "
                "seconds as measured at the dataset's size (its report projects them)"
            ],
        )
    notes = []
    apart = set_apart(data, dataset)
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
    return scenes, model, notes


def by_sampler(entries: list[Entry]) -> dict[str | None, list[Entry]]:
    """A ranking grouped by the sampler that made each entry's input (None: the stored inputs), in rank order."""
    groups: dict[str | None, list[Entry]] = {}
    for entry in entries:
        groups.setdefault(entry.sampler, []).append(entry)
    return groups


def _fmt(value: float | None, digits: int = 4) -> str:
    if value is None:
        return "—"
    return f"{value:.{digits}g}"


def format_leaderboard(metric, spp: int, data_hash: str, entries: list[Entry], notes=()) -> str:
    """A plain-text table for the terminal (``notes``: :attr:`Ranking.notes`, printed under the heading)."""
    arrow = "higher is better" if metric.higher_is_better else "lower is better"
    if metric.aggregate == "relative_to_input":
        arrow += "; per scene relative to the noisy input, geometric mean over scenes"
    elif metric.aggregate == "geomean":
        arrow += "; geometric mean over scenes"
    header = ["#", "denoiser", metric.name, "s/frame denoise", "s/frame total", "frames", "run", "date"]
    rows = []
    for rank, e in zip(ranks(entries), entries):
        value = _fmt(e.value) if e.value is not None else ("failed" if e.failed_units else "—")
        rows.append(
            [
                str(rank) if rank is not None else "-",
                e.denoiser,
                value,
                _fmt(e.denoise_seconds, 3),
                _fmt(e.total_seconds, 3),
                str(e.frames),
                e.run_id[:8],
                e.created_at[:16].replace("T", " "),
            ]
        )
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(header)]
    right = {0, 2, 3, 4, 5}

    def line(cells):
        return "  ".join(
            c.rjust(w) if i in right else c.ljust(w) for i, (c, w) in enumerate(zip(cells, widths))
        ).rstrip()

    out = [
        f"leaderboard: {metric.name} ({arrow}) at {spp} spp, dataset {data_hash[:12]}",
        *(f"  {note}" for note in notes),
        line(header),
        line(["-" * w for w in widths]),
    ]
    out += [line(r) for r in rows]
    return "\n".join(out)
