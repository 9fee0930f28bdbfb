"""The results store: one SQLite file (stdlib ``sqlite3``) that every benchmark run writes to.

Its tables, their schema versions and the migrations between them are in :mod:`.schema`.

Notes
-----
* **A unit is written in one transaction** (``BEGIN IMMEDIATE``), its ``units`` row last inside it:
  a unit row exists if and only if all its frames and metrics do. A process killed mid-way leaves
  either the whole unit or nothing, and a rerun computes only the units without a row.
* **Concurrent writers.** WAL mode lets readers work while one process writes; ``BEGIN IMMEDIATE``
  takes the write lock at the start of a transaction, so two writers never deadlock on a lock
  upgrade, and the busy timeout makes the second wait instead of failing. Two processes running the
  same run compute the same unit at worst twice: the second finds the row inside its transaction
  and writes nothing (:meth:`ResultsStore.write_unit` returns False).
* **Schema versions.** A database opened for writing is created or migrated to the current version
  (:func:`.schema.create_or_migrate`); opened read-only it is read as it is (:mod:`.schema`).
* **Rows.** Readers return typed rows (:mod:`.records`), read by attribute.
* The WAL journal mode is a property of the database file; network file systems do not support it
  (SQLite's documentation): keep the database on a local disk.
"""

from __future__ import annotations

import json
import os
import sqlite3
import zlib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.results import sampler_maps, schema
from denoisebench.results.finite import finite_or_none
from denoisebench.results.records import (
    EntryRow,
    FrameRow,
    NotApplicableCount,
    NotApplicableRow,
    RunRow,
    RunRows,
    SequenceRow,
    StripRow,
    UnitRecord,
    UnitRow,
)

#: Seconds a writer waits for another's transaction before giving up.
BUSY_TIMEOUT_S = 120.0


def utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def encode_image(image: np.ndarray) -> bytes:
    return zlib.compress(np.ascontiguousarray(image, dtype="<f4").tobytes(), 6)


def decode_image(blob: bytes, *, width: int, height: int) -> np.ndarray:
    return np.frombuffer(zlib.decompress(blob), dtype="<f4").reshape(height, width, 3).astype(np.float32)


def _by_name(record: type, cursor: sqlite3.Cursor, more: Callable[[], dict] | None = None) -> list:
    """The rows of ``cursor`` as ``record``s, each column passed by its name (``cursor.description``; a
    column missing from an older schema is selected as ``NULL AS <name>``). ``more()``: further fields,
    fresh for each row (a row's own dicts)."""
    names = [column[0] for column in cursor.description]
    return [record(**dict(zip(names, row)), **(more() if more else {})) for row in cursor]


class ResultsStore:
    """A connection to the results database at ``path`` (created with its schema when new)."""

    def __init__(self, path: str | os.PathLike, *, readonly: bool = False):
        self.path = Path(path)
        if readonly and not self.path.is_file():
            raise UserInputError(f"no results database at {self.path}")
        if not readonly:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            # isolation_level=None: we issue BEGIN IMMEDIATE / COMMIT ourselves
            self.conn = sqlite3.connect(str(self.path), timeout=BUSY_TIMEOUT_S, isolation_level=None)
            self.conn.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
            if not readonly:
                self.conn.execute("PRAGMA journal_mode = WAL")
                self.conn.execute("PRAGMA synchronous = NORMAL")  # durable at checkpoints; safe in WAL
                self._ensure_schema()
            self._check_version()
        except sqlite3.DatabaseError as error:
            raise UserInputError(f"{self.path} is not a usable SQLite results database ({error})") from None

    # ------------------------------------------------------------------ schema

    def _ensure_schema(self) -> None:
        with self.transaction() as conn:
            schema.create_or_migrate(conn)

    def _check_version(self) -> None:
        self.version = schema.read_version(self.conn, self.path)
        self._floor_columns = "floor, ref_se" if self.version >= 2 else "NULL AS floor, NULL AS ref_se"
        self._trained_column = "trained_on" if self.version >= 3 else "NULL AS trained_on"
        self._sampler_columns = (
            "sampler, denoiser_label" if self.version >= 5 else "NULL AS sampler, NULL AS denoiser_label"
        )

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """``BEGIN IMMEDIATE`` … ``COMMIT`` (``ROLLBACK`` on any exception, which propagates)."""
        self.conn.execute("BEGIN IMMEDIATE")
        try:
            yield self.conn
        except BaseException:
            self.conn.execute("ROLLBACK")
            raise
        self.conn.execute("COMMIT")

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ runs

    def ensure_run(self, run_id: str, *, dataset_hash: str, dataset_path: str, config: dict, versions: dict) -> bool:
        """Create the run row unless it exists; True when it was created (False: resuming)."""
        with self.transaction() as conn:
            exists = conn.execute("SELECT 1 FROM runs WHERE run_id = ?", (run_id,)).fetchone()
            if exists:
                return False
            conn.execute(
                "INSERT INTO runs (run_id, dataset_hash, dataset_path, config, versions, created_at) VALUES (?, ?, ?, ?, ?, ?)",
                (
                    run_id,
                    dataset_hash,
                    dataset_path,
                    json.dumps(config, sort_keys=True),
                    json.dumps(versions, sort_keys=True),
                    utc_now(),
                ),
            )
            return True

    def add_denoiser(
        self,
        *,
        run_id: str,
        label: str,
        spec: str,
        kind: str,
        needs,
        temporal: bool,
        load_error: str | None,
        trained_on=None,
        sampler: str | None = None,
        denoiser_label: str | None = None,
    ) -> None:
        """Record a label of the run (every argument is a keyword).

        ``trained_on``: the run's scenes the denoiser was trained on (None: it declared none);
        ``sampler``/``denoiser_label``: the label's place in the sampler dimension
        (:class:`~.records.EntryRow`); a plain denoiser (kind ``denoiser``, no sampler) is its own
        denoiser label.
        """
        if sampler is None and denoiser_label is None and kind == "denoiser":
            denoiser_label = label
        with self.transaction() as conn:
            conn.execute(
                "INSERT OR REPLACE INTO run_denoisers (run_id, label, spec, kind, needs, temporal, load_error, trained_on, "
                "sampler, denoiser_label) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    run_id,
                    label,
                    spec,
                    kind,
                    json.dumps(sorted(needs)),
                    int(bool(temporal)),
                    load_error,
                    None if trained_on is None else json.dumps(sorted(trained_on)),
                    sampler,
                    denoiser_label,
                ),
            )

    def finish_run(self, run_id: str) -> None:
        with self.transaction() as conn:
            conn.execute("UPDATE runs SET finished_at = ? WHERE run_id = ?", (utc_now(), run_id))

    def run(self, run_id: str) -> RunRow:
        row = self.conn.execute(
            "SELECT run_id, dataset_hash, dataset_path, config, versions, created_at, finished_at FROM runs WHERE run_id = ?",
            (run_id,),
        ).fetchone()
        if row is None:
            raise UserInputError(f"{self.path}: no run {run_id!r}")
        run, data_hash, path, config, versions, created, finished = row
        return RunRow(
            run_id=run,
            dataset_hash=data_hash,
            dataset_path=path,
            config=json.loads(config),
            versions=json.loads(versions),
            created_at=created,
            finished_at=finished,
        )

    def run_rows(self, run_id: str) -> RunRows:
        """Every row of ``run_id`` the analyses read, in one record (:class:`~.records.RunRows`)."""
        return RunRows(
            run=self.run(run_id),
            entries=self.denoisers(run_id),
            units=self.units(run_id),
            frames=self.frames(run_id),
            sequences=self.sequence_metrics(run_id),
        )

    def runs(self, dataset_hash: str | None = None) -> list[RunRow]:
        """Every run (newest first), optionally only those on one dataset."""
        query = (
            "SELECT run_id FROM runs"
            + (" WHERE dataset_hash = ?" if dataset_hash else "")
            + " ORDER BY created_at DESC, run_id"
        )
        return [self.run(r[0]) for r in self.conn.execute(query, (dataset_hash,) if dataset_hash else ())]

    def denoisers(self, run_id: str) -> list[EntryRow]:
        """The labels of a run in the order they were added (noisy input, denoisers, sampler pairs)."""
        rows = self.conn.execute(
            f"SELECT label, spec, kind, needs, temporal, load_error, {self._trained_column}, {self._sampler_columns} "
            "FROM run_denoisers WHERE run_id = ? ORDER BY rowid",
            (run_id,),
        )
        out = []
        for label, spec, kind, needs, temporal, load_error, trained, sampler, denoiser_label in rows:
            if self.version < 5:  # not stored yet: the rule the migration fills them in by
                sampler, denoiser_label = schema.sampler_dimension(kind, label, spec)
            out.append(
                EntryRow(
                    label=label,
                    spec=spec,
                    kind=kind,
                    needs=json.loads(needs),
                    temporal=bool(temporal),
                    load_error=load_error,
                    trained_on=json.loads(trained) if trained else [],
                    sampler=sampler,
                    denoiser_label=denoiser_label,
                )
            )
        return out

    # ------------------------------------------------------------------ units

    def done_units(self, run_id: str) -> set[tuple[str, str, int]]:
        """(denoiser, scene, spp) of every unit of ``run_id`` already written."""
        rows = self.conn.execute("SELECT denoiser, scene, spp FROM units WHERE run_id = ?", (run_id,))
        return {(r[0], r[1], int(r[2])) for r in rows}

    def write_unit(self, run_id: str, unit: UnitRecord) -> bool:
        """Write ``unit`` with all its frames, metrics and image in one transaction.

        Returns False (and writes nothing) when another process already wrote this unit.
        """
        key = (run_id, unit.denoiser, unit.scene, int(unit.spp))
        with self.transaction() as conn:
            if conn.execute(
                "SELECT 1 FROM units WHERE run_id = ? AND denoiser = ? AND scene = ? AND spp = ?", key
            ).fetchone():
                return False
            # leftovers of a unit whose transaction never committed cannot exist (atomicity), but a
            # unit row deleted by hand may have left its children: replace them
            for table in schema.UNIT_TABLES_OF[self.version]:
                conn.execute(f"DELETE FROM {table} WHERE run_id = ? AND denoiser = ? AND scene = ? AND spp = ?", key)
            for f in unit.frames:
                conn.execute(
                    "INSERT INTO frames (run_id, denoiser, scene, spp, frame, status, error, render_seconds, "
                    "denoise_seconds, total_seconds, sanitized) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        *key,
                        f.frame,
                        f.status,
                        f.error,
                        finite_or_none(f.render_seconds),
                        finite_or_none(f.denoise_seconds),
                        finite_or_none(f.total_seconds),
                        int(f.sanitized),
                    ),
                )
                conn.executemany(
                    "INSERT INTO frame_metrics (run_id, denoiser, scene, spp, frame, metric, value, floor, ref_se) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    [
                        (
                            *key,
                            f.frame,
                            name,
                            finite_or_none(value),
                            finite_or_none(f.floors.get(name)),
                            finite_or_none(f.ref_se.get(name)),
                        )
                        for name, value in f.metrics.items()
                    ],
                )
                conn.executemany(
                    "INSERT INTO not_applicable (run_id, denoiser, scene, spp, frame, metric, reason) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?)",
                    [(*key, f.frame, name, str(reason)) for name, reason in f.not_applicable.items()],
                )
            conn.executemany(
                "INSERT INTO not_applicable (run_id, denoiser, scene, spp, frame, metric, reason) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                [(*key, -1, name, str(reason)) for name, reason in unit.sequence_not_applicable.items()],
            )
            conn.executemany(
                "INSERT INTO sequence_metrics (run_id, denoiser, scene, spp, metric, value, floor, ref_se) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                [
                    (
                        *key,
                        name,
                        finite_or_none(value),
                        finite_or_none(unit.sequence_floors.get(name)),
                        finite_or_none(unit.sequence_ref_se.get(name)),
                    )
                    for name, value in unit.sequence_metrics.items()
                ],
            )
            sampler_maps.write(conn, key, unit.sampler_frames)  # the table is created with the schema
            conn.executemany(
                "INSERT INTO images (run_id, denoiser, scene, spp, frame, height, width, data) VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                [
                    (*key, int(frame), *image.shape[:2], encode_image(image))
                    for frame, image in sorted(unit.images.items())
                ],
            )
            if unit.strip is not None and unit.strip_window is not None:
                top, left, side = unit.strip_window
                conn.execute(
                    "INSERT INTO strips (run_id, denoiser, scene, spp, first_frame, frames, top, left_px, side, data) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        *key,
                        int(unit.strip_first or 0),
                        len(unit.strip),
                        int(top),
                        int(left),
                        int(side),
                        zlib.compress(np.ascontiguousarray(unit.strip, dtype="<f4").tobytes(), 6),
                    ),
                )
            conn.execute(
                "INSERT INTO units (run_id, denoiser, scene, spp, status, error, frames, frames_ok, denoise_seconds, "
                "render_seconds, finished_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    *key,
                    unit.status,
                    unit.error,
                    len(unit.frames),
                    sum(f.status == "ok" for f in unit.frames),
                    finite_or_none(unit.denoise_seconds),
                    finite_or_none(unit.render_seconds),
                    utc_now(),
                ),
            )
        return True

    # ------------------------------------------------------------------ reading

    def units(self, run_id: str) -> list[UnitRow]:
        rows = self.conn.execute(
            "SELECT denoiser, scene, spp, status, error, frames, frames_ok, denoise_seconds, render_seconds "
            "FROM units WHERE run_id = ? ORDER BY denoiser, scene, spp",
            (run_id,),
        )
        return _by_name(UnitRow, rows)

    def frames(self, run_id: str) -> list[FrameRow]:
        """Every frame row of ``run_id`` with its metrics as ``metrics: {name: value}``, and
        ``floors``/``ref_se`` ``{name: value}`` for the metrics that have them."""
        columns = (
            "denoiser, scene, spp, frame, status, error, render_seconds, denoise_seconds, total_seconds, sanitized"
        )
        cursor = self.conn.execute(
            f"SELECT {columns} FROM frames WHERE run_id = ? ORDER BY denoiser, scene, spp, frame", (run_id,)
        )
        rows = {
            (r.denoiser, r.scene, r.spp, r.frame): r
            for r in _by_name(FrameRow, cursor, lambda: {"metrics": {}, "floors": {}, "ref_se": {}})
        }
        for denoiser, scene, spp, frame, metric, value, floor, se in self.conn.execute(
            f"SELECT denoiser, scene, spp, frame, metric, value, {self._floor_columns} FROM frame_metrics WHERE run_id = ?",
            (run_id,),
        ):
            row = rows.get((denoiser, scene, spp, frame))
            if row is not None:  # a frozen row: its dicts are filled in here, once
                row.metrics[metric] = value
                if floor is not None:
                    row.floors[metric] = floor
                if se is not None:
                    row.ref_se[metric] = se
        return list(rows.values())

    def not_applicable(self, run_id: str) -> list[NotApplicableRow]:
        """Rows of metrics that did not apply: denoiser, scene, spp, frame (-1: the sequence), metric, reason."""
        if self.version < 4:
            return []
        rows = self.conn.execute(
            "SELECT denoiser, scene, spp, frame, metric, reason FROM not_applicable WHERE run_id = ? "
            "ORDER BY denoiser, scene, spp, frame, metric",
            (run_id,),
        )
        return _by_name(NotApplicableRow, rows)

    def not_applicable_summary(self, run_id: str) -> dict[str, NotApplicableCount]:
        """Per metric: how many frames (or sequences, frame -1) it did not apply to, and one reason."""
        if self.version < 4:
            return {}
        rows = self.conn.execute(
            "SELECT metric, COUNT(*), MIN(reason) FROM not_applicable WHERE run_id = ? GROUP BY metric ORDER BY metric",
            (run_id,),
        )
        return {metric: NotApplicableCount(count=int(count), reason=reason) for metric, count, reason in rows}

    def sequence_metrics(self, run_id: str) -> list[SequenceRow]:
        """Temporal metric rows: denoiser, scene, spp, metric, value, floor, ref_se (None without)."""
        rows = self.conn.execute(
            f"SELECT denoiser, scene, spp, metric, value, {self._floor_columns} FROM sequence_metrics WHERE run_id = ? "
            "ORDER BY denoiser, scene, spp, metric",
            (run_id,),
        )
        return _by_name(SequenceRow, rows)

    def image_frames(self, run_id: str, denoiser: str, *, spp: int, scene: str) -> list[int]:
        """The frames of a unit whose output is stored (its last frame and the frames its deciding scores
        are worst on; only the last in a database of version < 6), ascending."""
        rows = self.conn.execute(
            "SELECT frame FROM images WHERE run_id = ? AND denoiser = ? AND scene = ? AND spp = ? ORDER BY frame",
            (run_id, denoiser, scene, int(spp)),
        )
        return [int(r[0]) for r in rows]

    def image(
        self, run_id: str, denoiser: str, *, spp: int, scene: str, frame: int | None = None
    ) -> tuple[int, np.ndarray] | None:
        """(frame index, H×W×3 float32) of a unit's stored output at ``frame`` (None: its last stored
        frame), or None when that frame was not kept."""
        row = self.conn.execute(
            "SELECT frame, height, width, data FROM images WHERE run_id = ? AND denoiser = ? AND scene = ? AND spp = ? "
            + ("ORDER BY frame DESC LIMIT 1" if frame is None else "AND frame = ?"),
            (run_id, denoiser, scene, int(spp)) + (() if frame is None else (int(frame),)),
        ).fetchone()
        if row is None:
            return None
        return int(row[0]), decode_image(row[3], height=row[1], width=row[2])

    def strip(self, run_id: str, denoiser: str, *, spp: int, scene: str) -> StripRow | None:
        """The unit's strip (first frame, window, crops F×side×side×3), or None (none, or a v1 database)."""
        if self.version < 2:
            return None
        row = self.conn.execute(
            "SELECT first_frame, frames, top, left_px, side, data FROM strips WHERE run_id = ? AND denoiser = ? AND scene = ? AND spp = ?",
            (run_id, denoiser, scene, int(spp)),
        ).fetchone()
        if row is None:
            return None
        first, count, top, left, side, blob = row
        crops = np.frombuffer(zlib.decompress(blob), dtype="<f4").reshape(count, side, side, 3).astype(np.float32)
        return StripRow(first_frame=int(first), top=int(top), left=int(left), side=int(side), crops=crops)

    def integrity_problems(self) -> list[str]:
        """SQLite's integrity check plus ours: every frame row belongs to a unit row and vice versa."""
        problems = [r[0] for r in self.conn.execute("PRAGMA integrity_check") if r[0] != "ok"]
        tables = list(schema.UNIT_TABLES_OF[self.version])
        if sampler_maps.has_table(self.conn):  # spp maps of live sampler units, when the database has them
            tables.append(sampler_maps.TABLE)
        for table in tables:
            orphans = self.conn.execute(
                f"SELECT COUNT(*) FROM {table} t WHERE NOT EXISTS (SELECT 1 FROM units u WHERE u.run_id = t.run_id "
                "AND u.denoiser = t.denoiser AND u.scene = t.scene AND u.spp = t.spp)"
            ).fetchone()[0]
            if orphans:
                problems.append(f"{orphans} row(s) of {table} without a unit")
        short = self.conn.execute(
            "SELECT COUNT(*) FROM units u WHERE u.frames != (SELECT COUNT(*) FROM frames f WHERE f.run_id = u.run_id "
            "AND f.denoiser = u.denoiser AND f.scene = u.scene AND f.spp = u.spp)"
        ).fetchone()[0]
        if short:
            problems.append(f"{short} unit(s) whose frame rows are missing")
        return problems
