"""The ranking ``denoisebench leaderboard`` prints: denoisers ranked by one metric at one input spp,
across the runs on one dataset.

Each denoiser's entry comes from the newest run that measured it at that spp (a rerun with newer
code replaces the older number); the run id and its date are shown, so numbers from different runs
are never silently mixed. The value combines the scenes by the metric's aggregation rule
(:mod:`.aggregate`: per scene the mean over its frames, or the sequence's temporal value; then the
mean, the geometric mean, or the geometric mean of the ratio to the same run's noisy input; for the
lead scores the anchored trimmed geometric mean of :mod:`.lead`, a share of the same run's noisy input
at its lowest spp, so runs on one dataset compare when they share that spp), so a bright scene never
decides a linear score and no single scene decides a lead score; a score with a reference-noise floor is ranked corrected,
as the report's tables show it (the same :func:`.summary.metric_cell`); failed units count as
failed, not as missing, and rank last.

This module is pure: it takes each run as its report reads it (:class:`RunView`: the run's rows,
the scenes its report aggregates, its time model), loaded by
:func:`denoisebench.reports.leaderboard.leaderboard`, which also picks the dataset and the runs.

Notes
-----
* Runs are grouped by **dataset hash** (the manifest's content without timings), not by path: a
  dataset moved to another folder is the same dataset; one regenerated with another seed is not.
* Seconds are those of the run the entry comes from; runs made on different machines or under
  different load are not comparable in time, only in accuracy.
* **Samplers are a dimension.** Every entry says which live sampler made its input (None: the
  dataset's stored input) and which denoiser ran on it (:class:`~.records.EntryRow`);
  :func:`labels_to_rank` keeps one sampler's entries (``""``: the stored inputs' only), and
  :func:`by_sampler` groups a ranking by sampler.
* Per-scene values come from :class:`.run_index.RunIndex`, the one place they are computed.
"""

from __future__ import annotations

from dataclasses import dataclass

from denoisebench.analysis.summary import RunData, metric_cell
from denoisebench.analysis.time_model import TimeModel
from denoisebench.results.finite import finite_mean
from denoisebench.results.records import EntryRow, RunRow, UnitRow


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
    """What :func:`denoisebench.reports.leaderboard.leaderboard` returns: the metric, spp, dataset hash,
    entries best first, and the lines that say how the numbers were read (scenes left out, the
    seconds' basis)."""

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


@dataclass(frozen=True, kw_only=True)
class RunView:
    """One run as its report reads it: its rows (``data``), the scenes its report aggregates
    (``scenes``: the scenes it sets apart left out) and its time model (``model``; None: seconds as
    measured at the dataset's size)."""

    row: RunRow
    data: RunData
    scenes: set[str]
    model: TimeModel | None


def labels_to_rank(units: list[UnitRow], entries: list[EntryRow], *, spp: int, sampler: str | None) -> set[str]:
    """The labels of a run's ``units`` measured at ``spp`` whose input ``sampler`` made (``""``: the
    dataset's stored inputs; None: any)."""
    made_by = {e.label: e.sampler for e in entries}
    return {
        u.denoiser for u in units if u.spp == spp and (sampler is None or (made_by.get(u.denoiser) or "") == sampler)
    }


def run_entries(view: RunView, labels: set[str], *, spp: int, metric: str) -> tuple[dict[str, Entry], dict[str, Entry]]:
    """({label: entry} of ``labels`` in one run, {label: entry} of those the run did not compute
    ``metric`` for): the report's own corrected cell over the run's ``scenes``, seconds per frame
    from its time model where it has one."""
    data, row = view.data, view.row
    measured: dict[str, Entry] = {}
    unmeasured: dict[str, Entry] = {}
    for label in sorted(labels):
        ok = [f for f in data.ok_frames(label, spp) if f.scene in view.scenes]
        # the report's own cell: corrected for the reference's noise where the score has a floor
        value = metric_cell(data, label, spp, metric=metric, scenes=sorted(view.scenes)).value
        failed = sum(1 for u in data.units_of(label, spp) if u.status != "ok")
        entry = data.entry(label)
        sampler, denoiser_label = (entry.sampler, entry.denoiser_label) if entry is not None else (None, label)
        if value is None and not failed:  # this run did not compute the metric: look further back
            unmeasured[label] = Entry(
                denoiser=label,
                value=None,
                frames=len(ok),
                failed_units=0,
                denoise_seconds=None,
                total_seconds=None,
                run_id=row.run_id,
                created_at=row.created_at,
                sampler=sampler,
                denoiser_label=denoiser_label,
            )
            continue
        denoise = finite_mean(f.denoise_seconds for f in ok)
        total = finite_mean(f.total_seconds for f in ok)
        if view.model is not None:
            denoise, total = view.model.denoise_seconds(label, spp), view.model.total_seconds(label, spp)
        measured[label] = Entry(
            denoiser=label,
            value=value if not failed else None,
            frames=len(ok),
            failed_units=failed,
            denoise_seconds=denoise,
            total_seconds=total,
            run_id=row.run_id,
            created_at=row.created_at,
            sampler=sampler,
            denoiser_label=denoiser_label,
        )
    return measured, unmeasured


def best_first(entries: list[Entry], higher_is_better: bool) -> list[Entry]:
    """``entries`` best first (unmeasured and failed last, ties by name)."""
    sign = -1.0 if higher_is_better else 1.0
    return sorted(entries, key=lambda e: (e.value is None, sign * e.value if e.value is not None else 0.0, e.denoiser))


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
