"""The frame records of a dataset in an SQLite index (``OUT/dataset.sqlite``): append cheap, read by key.

Why SQLite (and not a JSON-lines journal folded into ``dataset.json``, nor one file per scene):

* **Constant cost per record.** Recording a frame is one ``INSERT OR REPLACE`` and one commit,
  whatever the number of records already there (B-tree insert: O(log n), a few pages written).
  Rewriting a whole manifest per file, what this replaced, cost O(records) per record.
* **Durable at once, nothing to fold.** In WAL mode with ``synchronous=FULL`` a commit is on disk
  when it returns, and a process killed mid-commit loses only that transaction: SQLite's own
  recovery replaces the "torn last line" handling a hand-made journal needs. The same file is
  then the readers' index, so no O(records) fold (and its own crash window) happens at the end.
* **Readers load only what they ask for.** A frame's record is one primary-key look-up, a scene's
  records one range scan; a 100 000-frame dataset opens in the time its header takes to parse.
  A per-scene JSON file still loads a whole (possibly huge) scene for one frame.

Schema: one table ``frames(scene, kind, frame, record)`` with primary key ``(scene, kind,
frame)``, ``WITHOUT ROWID``; ``kind`` is the manifest's render key (``spp0004``, ``reference``),
``frame`` the frame key (``0000``), ``record`` the frame record as canonical JSON (sorted keys, no
spaces). ``PRAGMA user_version`` holds :data:`INDEX_VERSION`.

Notes
-----
The index's **bytes** are not reproducible: SQLite's page layout depends on the history of
writes (an interrupted and resumed run lays pages out differently). Its **contents** are, except
for timings; compare datasets with :func:`~denoisebench.dataset.manifest.manifest_without_timings`.
A finished dataset's index is switched back to a rollback journal (``journal_mode=DELETE``) so that
it is one self-contained file that read-only media and ``mode=ro`` readers can open.
A connection must not cross ``fork()`` (torch DataLoader workers): :class:`FrameIndexReader`
opens its connection lazily and again in each new process.
The index is untrusted input like the rest of the dataset: SQLite reads malformed files safely
(``sqlite3.DatabaseError``), which is turned into a one-line DatasetError naming the file.
"""

from __future__ import annotations

import json
import os
import sqlite3
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

from denoisebench.dataset.errors import DatasetError
from denoisebench.dataset.exr_io import canonical_json

INDEX_VERSION = 1

_SCHEMA = (
    "CREATE TABLE IF NOT EXISTS frames ("
    "scene TEXT NOT NULL, kind TEXT NOT NULL, frame TEXT NOT NULL, record TEXT NOT NULL, "
    "PRIMARY KEY (scene, kind, frame)) WITHOUT ROWID"
)

__all__ = ["INDEX_VERSION", "FrameIndexWriter", "FrameIndexReader", "remove_index"]


def remove_index(path: str | os.PathLike) -> None:
    """Delete the index and its WAL/shared-memory side files (symbolic links unlinked, not followed)."""
    path = Path(path)
    for suffix in ("", "-wal", "-shm", "-journal"):
        Path(f"{path}{suffix}").unlink(missing_ok=True)


def _nest(path: Path, rows: Iterable[tuple[str, str, str, str]]) -> dict[str, dict[str, dict[str, dict]]]:
    out: dict[str, dict[str, dict[str, dict]]] = {}
    for scene, kind, frame, text in rows:
        out.setdefault(scene, {}).setdefault(kind, {})[frame] = _decode(path, text)
    return out


class FrameIndexWriter:
    """Read-write index for the dataset writer (one writing process; every put is its own commit)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL").fetchall()
            self._db.execute("PRAGMA synchronous=FULL")
            self._db.execute(_SCHEMA)
            self._db.execute(f"PRAGMA user_version={INDEX_VERSION}")
        except sqlite3.DatabaseError as exc:
            raise DatasetError(f"{self.path} is not a readable frame index ({exc})") from None

    def put(self, scene: str, kind: str, frame: str, record: dict) -> None:
        """Record one frame (replacing an older record of the same key); durable when it returns."""
        self.put_many([(scene, kind, frame, record)])

    def put_many(self, rows: Iterable[tuple[str, str, str, dict]]) -> None:
        """Several records in one transaction (all or none survive a crash)."""
        with self._db:  # BEGIN ... COMMIT (rollback on error)
            self._db.execute("BEGIN")
            self._db.executemany(
                "INSERT OR REPLACE INTO frames VALUES (?, ?, ?, ?)",
                ((s, k, f, canonical_json(r)) for s, k, f, r in rows),
            )

    def delete_scene(self, scene: str) -> None:
        with self._db:
            self._db.execute("BEGIN")
            self._db.execute("DELETE FROM frames WHERE scene = ?", (scene,))

    def replace_all(self, renders: dict[str, dict[str, dict[str, dict]]]) -> None:
        """Make the index hold exactly ``renders`` (scene → kind → frame → record), in one transaction."""
        with self._db:
            self._db.execute("BEGIN")
            self._db.execute("DELETE FROM frames")
            self._db.executemany(
                "INSERT INTO frames VALUES (?, ?, ?, ?)",
                (
                    (scene, kind, frame, canonical_json(record))
                    for scene, kinds in renders.items()
                    for kind, frames in kinds.items()
                    for frame, record in frames.items()
                ),
            )

    def load_all(self) -> dict[str, dict[str, dict[str, dict]]]:
        """Every record, nested like the manifest's ``renders`` (resume: one pass, O(records))."""
        return _nest(self.path, self._db.execute("SELECT scene, kind, frame, record FROM frames"))

    def count(self) -> int:
        return int(self._db.execute("SELECT COUNT(*) FROM frames").fetchone()[0])

    def seal(self) -> None:
        """Fold the WAL into the file and leave one self-contained file (rollback journal from now on)."""
        self._db.execute(
            "PRAGMA wal_checkpoint(TRUNCATE)"
        ).fetchall()  # read to the end: an open statement holds a lock
        self._db.execute("PRAGMA journal_mode=DELETE").fetchall()

    def close(self, *, seal: bool = False) -> None:
        """Close; ``seal``: :meth:`seal` first."""
        if seal:
            self.seal()
        self._db.close()


class FrameIndexReader:
    """Read-only access by key; the connection is opened on first use, once per process."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._db: sqlite3.Connection | None = None
        self._pid = None
        self._lock = threading.Lock()

    def __getstate__(self):  # picklable (Ray, DataLoader spawn): the connection is not carried
        return {"path": self.path}

    def __setstate__(self, state):
        self.__init__(state["path"])

    def _connection(self) -> sqlite3.Connection:
        if self._db is None or self._pid != os.getpid():
            if not self.path.is_file():
                raise DatasetError(f"{self.path} is missing: the manifest's frame records are kept there")
            try:
                db = sqlite3.connect(f"{self.path.resolve().as_uri()}?mode=ro", uri=True, check_same_thread=False)
                version = db.execute("PRAGMA user_version").fetchone()[0]
            except sqlite3.DatabaseError as exc:
                raise DatasetError(f"{self.path} is not a readable frame index ({exc})") from None
            if version != INDEX_VERSION:
                raise DatasetError(f"{self.path} has index version {version}; this denoisebench reads {INDEX_VERSION}")
            self._db, self._pid = db, os.getpid()
        return self._db

    def _query(self, sql: str, args: tuple = ()) -> list:
        with self._lock:
            try:
                return self._connection().execute(sql, args).fetchall()
            except sqlite3.DatabaseError as exc:
                raise DatasetError(f"{self.path}: cannot read frame records ({exc})") from None

    def get(self, scene: str, kind: str, frame: str) -> dict | None:
        rows = self._query("SELECT record FROM frames WHERE scene = ? AND kind = ? AND frame = ?", (scene, kind, frame))
        return _decode(self.path, rows[0][0]) if rows else None

    def scene(self, scene: str) -> dict[str, dict[str, dict]]:
        """One scene's records (kind → frame → record)."""
        rows = self._query("SELECT scene, kind, frame, record FROM frames WHERE scene = ?", (scene,))
        return _nest(self.path, rows).get(scene, {})

    def scenes(self) -> Iterator[tuple[str, dict[str, dict[str, dict]]]]:
        """(scene, records) for every scene that has records, in name order: one scene in memory at a time."""
        for (name,) in self._query("SELECT DISTINCT scene FROM frames ORDER BY scene"):
            yield name, self.scene(name)

    def count(self) -> int:
        return int(self._query("SELECT COUNT(*) FROM frames")[0][0])

    def close(self) -> None:
        """Close the connection (a writer in this process then has the file to itself)."""
        with self._lock:
            if self._db is not None and self._pid == os.getpid():
                self._db.close()
            self._db = None


def _decode(path: Path, text: str) -> dict:
    try:
        value = json.loads(text)
    except (TypeError, json.JSONDecodeError):
        value = None
    if not isinstance(value, dict):
        raise DatasetError(f"{path}: a frame record is not a JSON object")
    return value
