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

from denoisebench.errors import UserInputError
from denoisebench.leaderboard.analysis import metric_cell
from denoisebench.leaderboard.finite import finite_mean
from denoisebench.leaderboard.run_index import RunIndex
from denoisebench.leaderboard.store import ResultsStore
from denoisebench.metrics import get_metric


@dataclass
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
):
    """(metric object, spp, dataset hash, entries ranked best first).

    ``sampler``: rank only the entries whose input that live sampler made (``""``: only those on the
    dataset's stored inputs, the noisy input among them); None: every entry."""
    try:
        m = get_metric(metric)
    except ValueError as exc:
        raise UserInputError(str(exc)) from None
    data_hash = pick_dataset(store, dataset)
    runs = store.runs(data_hash)  # newest first
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
    for run in runs:
        run_id = run.run_id
        dimension = {d.label: (d.sampler, d.denoiser_label) for d in store.denoisers(run_id)}
        all_units = store.units(run_id)
        labels = {
            u.denoiser
            for u in all_units
            if u.spp == spp and (sampler is None or (dimension.get(u.denoiser, (None,))[0] or "") == sampler)
        } - set(entries)
        if not labels:
            continue
        run_index = RunIndex(all_units, store.frames(run_id), store.sequence_metrics(run_id))
        for label in sorted(labels):
            ok = run_index.ok_frames(label, spp)
            # the report's own cell: corrected for the reference's noise where the score has a floor
            value = metric_cell(run_index, label, spp, m.name, None).value
            failed = sum(1 for u in run_index.units_of(label, spp) if u.status != "ok")
            where = dimension.get(label, (None, label))
            if value is None and not failed:  # this run did not compute the metric: look further back
                unmeasured.setdefault(label, Entry(label, None, len(ok), 0, None, None, run_id, run.created_at, *where))
                continue
            entries[label] = Entry(
                label,
                value if not failed else None,
                len(ok),
                failed,
                finite_mean(f.denoise_seconds for f in ok),
                finite_mean(f.total_seconds for f in ok),
                run_id,
                run.created_at,
                *where,
            )
    for label, entry in unmeasured.items():
        entries.setdefault(label, entry)
    sign = -1.0 if m.higher_is_better else 1.0
    ranked = sorted(
        entries.values(), key=lambda e: (e.value is None, sign * e.value if e.value is not None else 0.0, e.denoiser)
    )
    return m, spp, data_hash, ranked


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


def format_leaderboard(metric, spp: int, data_hash: str, entries: list[Entry]) -> str:
    """A plain-text table for the terminal."""
    arrow = "higher is better" if metric.higher_is_better else "lower is better"
    if metric.aggregate == "relative_to_input":
        arrow += "; per scene relative to the noisy input, geometric mean over scenes"
    elif metric.aggregate == "geomean":
        arrow += "; geometric mean over scenes"
    header = ["#", "denoiser", metric.name, "s/frame denoise", "s/frame total", "frames", "run", "date"]
    rows = []
    for rank, e in enumerate(entries, 1):
        value = _fmt(e.value) if e.value is not None else ("failed" if e.failed_units else "—")
        rows.append(
            [
                str(rank) if e.value is not None else "-",
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
        line(header),
        line(["-" * w for w in widths]),
    ]
    out += [line(r) for r in rows]
    return "\n".join(out)
