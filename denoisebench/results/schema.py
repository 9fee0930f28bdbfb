"""The results store's schema: its tables, their versions, and the migrations between them.

:class:`~.store.ResultsStore` creates the tables of a new database and migrates an older one
(:func:`create_or_migrate`) when it opens it for writing, and refuses a version it cannot read
(:func:`read_version`).

Tables (schema version :data:`SCHEMA_VERSION`, kept in ``schema_version``):

``runs``            one row per benchmark run: dataset hash, config (JSON), software versions (JSON)
``run_denoisers``   the labels of a run (noisy input, denoisers, sampler pairs): label, spec, needs,
                    temporal, load error (if any), ``trained_on``: the run's scenes the denoiser
                    declared it was trained on (JSON list), and the run's **sampler dimension**:
                    ``sampler`` (the live sampler whose image the label scores; NULL: the dataset's
                    stored input) and ``denoiser_label`` (the denoiser run on it; NULL: none)
``units``           one denoiser on one sequence (scene) at one input spp: status, error, seconds
``frames``          one row per frame of a unit: status, error, render/denoise/total seconds
``frame_metrics``   metric values per frame (spatial, gradient, and per-frame flicker), with the
                    reference-noise ``floor`` and ``ref_se`` of MSE-family metrics (else NULL)
``sequence_metrics``  temporal metric values per unit (same ``floor``/``ref_se`` columns)
``images``          denoised frames of each unit, for reports (zlib-compressed float32): its last frame and
                    the frame each deciding score is worst on (``names.DECIDING_SCORES``)
``strips``          a crop of the unit's first frames (:mod:`.strips`, zlib-compressed float32)
``not_applicable``  metrics that do not apply to a frame (``frame`` ≥ 0) or to a unit's sequence
                    (``frame`` = -1), with the reason (SSIM on frames under 11×11 px): such a
                    metric has no value there, the frame's other metrics are kept

Notes
-----
* **Schema versions.** Version 2 added ``floor`` and ``ref_se`` to ``frame_metrics`` and
  ``sequence_metrics`` and the ``strips`` table (:mod:`denoisebench.metrics.floors.closed_form`). A version-1 database opened for
  writing is migrated in place (``ALTER TABLE ... ADD COLUMN``, one transaction; its old rows get
  NULL floors); opened read-only it is read as it is, every floor None. Version 3 added
  ``run_denoisers.trained_on`` (migrated the same way; NULL: not declared). Version 4 added the
  ``not_applicable`` table (created when an older database is opened for writing; read as empty
  from an older one opened read-only). Version 5 added ``run_denoisers.sampler`` and
  ``run_denoisers.denoiser_label``; migrating fills them in from each row's kind, label and spec
  (:func:`sampler_dimension`, the rule :mod:`.sampler_units` labels pairs by), and an older
  database opened read-only gets the same values from the same rule when read. Version 6 keys
  ``images`` by frame too (several frames per unit); migrating rebuilds the table with the new key
  and keeps every row (one per unit, its last frame). A newer version than this code knows is refused.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

from denoisebench.errors import UserInputError
from denoisebench.results import sampler_maps
from denoisebench.results.names import PAIR_LABEL_SEPARATOR, PAIR_SPEC_SEPARATOR, SAMPLER_SPEC_PREFIX

SCHEMA_VERSION = 6
#: Versions this code reads (older ones are migrated when opened for writing).
READABLE_VERSIONS = (1, 2, 3, 4, 5, 6)
#: Every table of the current version (``CREATE TABLE IF NOT EXISTS``: an older database keeps its own).
TABLES = """
CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    run_id TEXT PRIMARY KEY,
    dataset_hash TEXT NOT NULL,
    dataset_path TEXT NOT NULL,
    config TEXT NOT NULL,
    versions TEXT NOT NULL,
    created_at TEXT NOT NULL,
    finished_at TEXT
);
CREATE TABLE IF NOT EXISTS run_denoisers (
    run_id TEXT NOT NULL REFERENCES runs(run_id),
    label TEXT NOT NULL,
    spec TEXT NOT NULL,
    kind TEXT NOT NULL,
    needs TEXT NOT NULL,
    temporal INTEGER NOT NULL,
    load_error TEXT,
    trained_on TEXT,
    sampler TEXT,
    denoiser_label TEXT,
    PRIMARY KEY (run_id, label)
);
CREATE TABLE IF NOT EXISTS units (
    run_id TEXT NOT NULL REFERENCES runs(run_id),
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    status TEXT NOT NULL,
    error TEXT,
    frames INTEGER NOT NULL,
    frames_ok INTEGER NOT NULL,
    denoise_seconds REAL,
    render_seconds REAL,
    finished_at TEXT NOT NULL,
    PRIMARY KEY (run_id, denoiser, scene, spp)
);
CREATE TABLE IF NOT EXISTS frames (
    run_id TEXT NOT NULL,
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    frame INTEGER NOT NULL,
    status TEXT NOT NULL,
    error TEXT,
    render_seconds REAL,
    denoise_seconds REAL,
    total_seconds REAL,
    sanitized INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (run_id, denoiser, scene, spp, frame)
);
CREATE TABLE IF NOT EXISTS frame_metrics (
    run_id TEXT NOT NULL,
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    frame INTEGER NOT NULL,
    metric TEXT NOT NULL,
    value REAL,
    floor REAL,
    ref_se REAL,
    PRIMARY KEY (run_id, denoiser, scene, spp, frame, metric)
);
CREATE TABLE IF NOT EXISTS not_applicable (
    run_id TEXT NOT NULL,
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    frame INTEGER NOT NULL,
    metric TEXT NOT NULL,
    reason TEXT NOT NULL,
    PRIMARY KEY (run_id, denoiser, scene, spp, frame, metric)
);
CREATE TABLE IF NOT EXISTS sequence_metrics (
    run_id TEXT NOT NULL,
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    metric TEXT NOT NULL,
    value REAL,
    floor REAL,
    ref_se REAL,
    PRIMARY KEY (run_id, denoiser, scene, spp, metric)
);
CREATE TABLE IF NOT EXISTS images (
    run_id TEXT NOT NULL,
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    frame INTEGER NOT NULL,
    height INTEGER NOT NULL,
    width INTEGER NOT NULL,
    data BLOB NOT NULL,
    PRIMARY KEY (run_id, denoiser, scene, spp, frame)
);
CREATE TABLE IF NOT EXISTS strips (
    run_id TEXT NOT NULL,
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    first_frame INTEGER NOT NULL,
    frames INTEGER NOT NULL,
    top INTEGER NOT NULL,
    left_px INTEGER NOT NULL,
    side INTEGER NOT NULL,
    data BLOB NOT NULL,
    PRIMARY KEY (run_id, denoiser, scene, spp)
);
"""

UNIT_TABLES = ("frames", "frame_metrics", "sequence_metrics", "images", "strips", "not_applicable")
#: The tables of a unit that exist in a database of each schema version.
UNIT_TABLES_OF = {
    1: UNIT_TABLES[:4],
    2: UNIT_TABLES[:5],
    3: UNIT_TABLES[:5],
    4: UNIT_TABLES,
    5: UNIT_TABLES,
    6: UNIT_TABLES,
}


def sampler_dimension(kind: str, label: str, spec: str) -> tuple[str | None, str | None]:
    """(sampler, denoiser_label) of a ``run_denoisers`` row from its kind, label and spec.

    The rule rows written before schema version 5 are read (and migrated) by: the noisy input (kind
    ``input``) has neither; a denoiser is its own label on the stored inputs; a ``sampler`` row's
    spec is ``sampler SPEC`` (the sampler alone, labelled ``SPEC``) or ``sampler SPEC + DSPEC``
    (labelled ``SPEC+DLABEL``), as :mod:`.sampler_units` writes them (:mod:`.names`).
    """
    if kind == "input":
        return None, None
    if kind != "sampler":
        return None, label
    sampler = spec.removeprefix(SAMPLER_SPEC_PREFIX).split(PAIR_SPEC_SEPARATOR)[0]
    if not label.startswith(sampler + PAIR_LABEL_SEPARATOR):
        return sampler, None
    return sampler, label[len(sampler) + len(PAIR_LABEL_SEPARATOR) :]


def create_or_migrate(conn: sqlite3.Connection) -> None:
    """Create the tables a new database lacks and migrate an older one to :data:`SCHEMA_VERSION`,
    inside the caller's transaction (module docstring)."""
    # one statement at a time: executescript() would COMMIT the caller's transaction
    for statement in filter(str.strip, TABLES.split(";")):
        conn.execute(statement)
    conn.execute(sampler_maps.SCHEMA)  # spp maps of live sampler units (report)
    if conn.execute("SELECT COUNT(*) FROM schema_version").fetchone()[0] == 0:
        conn.execute("INSERT INTO schema_version (version) VALUES (?)", (SCHEMA_VERSION,))
    version = conn.execute("SELECT MAX(version) FROM schema_version").fetchone()[0]
    if version == 1:  # 1 → 2: floors (CREATE TABLE IF NOT EXISTS left the old tables as they were)
        for table in ("frame_metrics", "sequence_metrics"):
            have = {row[1] for row in conn.execute(f"PRAGMA table_info({table})")}
            for column in ("floor", "ref_se"):
                if column not in have:
                    conn.execute(f"ALTER TABLE {table} ADD COLUMN {column} REAL")
        conn.execute("UPDATE schema_version SET version = 2")
        version = 2
    if version == 2:  # 2 → 3: the scenes a denoiser was trained on
        have = {row[1] for row in conn.execute("PRAGMA table_info(run_denoisers)")}
        if "trained_on" not in have:
            conn.execute("ALTER TABLE run_denoisers ADD COLUMN trained_on TEXT")
        conn.execute("UPDATE schema_version SET version = 3")
        version = 3
    if version == 3:  # 3 → 4: the not_applicable table (created above)
        conn.execute("UPDATE schema_version SET version = 4")
        version = 4
    if version == 4:  # 4 → 5: the sampler dimension, filled in from the rows' kind, label and spec
        have = {row[1] for row in conn.execute("PRAGMA table_info(run_denoisers)")}
        for column in ("sampler", "denoiser_label"):
            if column not in have:
                conn.execute(f"ALTER TABLE run_denoisers ADD COLUMN {column} TEXT")
        rows = conn.execute("SELECT rowid, kind, label, spec FROM run_denoisers").fetchall()
        conn.executemany(
            "UPDATE run_denoisers SET sampler = ?, denoiser_label = ? WHERE rowid = ?",
            [(*sampler_dimension(kind, label, spec), rowid) for rowid, kind, label, spec in rows],
        )
        conn.execute("UPDATE schema_version SET version = 5")
        version = 5
    if version == 5:  # 5 → 6: images keyed by frame too (a primary key cannot be altered: rebuild)
        conn.execute("ALTER TABLE images RENAME TO images_v5")
        (create,) = [s for s in TABLES.split(";") if "CREATE TABLE IF NOT EXISTS images (" in s]
        conn.execute(create)
        conn.execute(
            "INSERT INTO images (run_id, denoiser, scene, spp, frame, height, width, data) "
            "SELECT run_id, denoiser, scene, spp, frame, height, width, data FROM images_v5"
        )
        conn.execute("DROP TABLE images_v5")
        conn.execute("UPDATE schema_version SET version = 6")


def read_version(conn: sqlite3.Connection, path: Path) -> int:
    """The schema version of the database at ``path``; a :class:`UserInputError` for one this code cannot read."""
    try:
        row = conn.execute("SELECT MAX(version) FROM schema_version").fetchone()
    except sqlite3.OperationalError:
        raise UserInputError(f"{path} is not a denoisebench results database (no schema_version table)") from None
    if row is None or row[0] not in READABLE_VERSIONS:
        raise UserInputError(
            f"{path} has results schema version {row[0] if row else None}; "
            f"this denoisebench reads versions {', '.join(map(str, READABLE_VERSIONS))}"
        )
    return int(row[0])
