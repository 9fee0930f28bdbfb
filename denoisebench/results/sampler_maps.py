"""What a live sampler did to each frame, kept for reports: its spp map and its pixels without a sample.

A sampler × denoiser unit (:mod:`.sampler_units`) carries one :class:`SamplerFrame` per frame in
``UnitRecord.sampler_frames``; :meth:`~.store.ResultsStore.write_unit` writes them with the unit, in
its transaction, to the table ``sampler_frames`` (:func:`write`); the report reads them back
(:func:`read`) to show each sampler's spp map beside its image and to say where it left pixels with
fewer than one sample (their value is 0, not an estimate).

Notes
-----
* **One map per unit**: the spp map of the frame whose output the store keeps as the unit's image
  (the last one), zlib-compressed little-endian int32; every frame keeps its counts (samples,
  mean, max, pixels with fewer than one sample).
* The table is created when a store is opened for writing (``CREATE TABLE IF NOT EXISTS``), so a
  database that never held a sampler unit has it empty; one opened read-only without it reads as
  empty (:func:`read`).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, field

import numpy as np

TABLE = "sampler_frames"

SCHEMA = f"""
CREATE TABLE IF NOT EXISTS {TABLE} (
    run_id TEXT NOT NULL,
    denoiser TEXT NOT NULL,
    scene TEXT NOT NULL,
    spp INTEGER NOT NULL,
    frame INTEGER NOT NULL,
    samples INTEGER NOT NULL,
    mean_spp REAL NOT NULL,
    max_spp INTEGER NOT NULL,
    pixels_without_samples INTEGER NOT NULL,
    height INTEGER,
    width INTEGER,
    data BLOB,
    PRIMARY KEY (run_id, denoiser, scene, spp, frame)
)
"""


@dataclass(kw_only=True)
class SamplerFrame:
    """One live-rendered frame of a sampler.

    Attributes
    ----------
    frame : int
        Frame index in the scene's sequence.
    samples : int
        Samples the sampler spent on the frame.
    mean_spp, max_spp : float, int
        Mean and largest samples per pixel.
    pixels_without_samples : int
        Pixels with fewer than one sample (value 0, not an estimate).
    spp : numpy.ndarray or None
        H×W int32 samples per pixel; kept for the unit's image frame only.
    """

    frame: int
    samples: int
    mean_spp: float
    max_spp: int
    pixels_without_samples: int
    spp: np.ndarray | None = field(default=None, repr=False)


@dataclass(frozen=True, slots=True, kw_only=True)
class SamplerMapRow:
    """One live-rendered frame as the store reads it back: the unit's label (``denoiser``), scene,
    spp and frame, the frame's counts (:class:`SamplerFrame`) and ``spp_map`` (H×W int32, or None: kept
    for the unit's image frame only)."""

    denoiser: str
    scene: str
    spp: int
    frame: int
    samples: int
    mean_spp: float
    max_spp: int
    pixels_without_samples: int
    spp_map: np.ndarray | None = field(default=None, repr=False)


def frame_records(maps: list[tuple[int, np.ndarray]]) -> list[SamplerFrame]:
    """SamplerFrame of every (frame index, spp map); the last frame (the unit's image) keeps its map."""
    out = []
    for n, (index, counts) in enumerate(maps):
        counts = np.asarray(counts, dtype=np.int32)
        out.append(
            SamplerFrame(
                frame=int(index),
                samples=int(counts.sum(dtype=np.int64)),
                mean_spp=float(counts.mean()) if counts.size else 0.0,
                max_spp=int(counts.max()) if counts.size else 0,
                pixels_without_samples=int((counts < 1).sum()),
                spp=counts if n == len(maps) - 1 else None,
            )
        )
    return out


def write(conn, key: tuple, frames: list[SamplerFrame]) -> None:
    """Replace the rows of unit ``key`` (run_id, denoiser, scene, spp) with ``frames`` (inside the caller's transaction)."""
    conn.execute(f"DELETE FROM {TABLE} WHERE run_id = ? AND denoiser = ? AND scene = ? AND spp = ?", key)
    rows = []
    for f in frames:
        shape = (None, None, None) if f.spp is None else (*f.spp.shape[:2], _encode(f.spp))
        rows.append((*key, f.frame, f.samples, f.mean_spp, f.max_spp, f.pixels_without_samples, *shape))
    conn.executemany(
        f"INSERT INTO {TABLE} (run_id, denoiser, scene, spp, frame, samples, mean_spp, max_spp, "
        "pixels_without_samples, height, width, data) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
        rows,
    )


def _encode(counts: np.ndarray) -> bytes:
    return zlib.compress(np.ascontiguousarray(counts, dtype="<i4").tobytes(), 6)


def has_table(conn) -> bool:
    """Whether the database holds the table (stores written before it existed do not)."""
    return (
        conn.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (TABLE,)).fetchone() is not None
    )


def read(store, run_id: str) -> list[SamplerMapRow]:
    """Every sampler frame of ``run_id`` (:class:`SamplerMapRow`), ordered by label, scene, spp, frame;
    [] when the store has no such table."""
    if not has_table(store.conn):
        return []
    rows = store.conn.execute(
        f"SELECT denoiser, scene, spp, frame, samples, mean_spp, max_spp, pixels_without_samples, height, width, data "
        f"FROM {TABLE} WHERE run_id = ? ORDER BY denoiser, scene, spp, frame",
        (run_id,),
    )
    out = []
    for label, scene, spp, frame, samples, mean, top, empty, height, width, blob in rows:
        counts = None
        if blob is not None:
            counts = np.frombuffer(zlib.decompress(blob), dtype="<i4").reshape(height, width).astype(np.int32)
        out.append(
            SamplerMapRow(
                denoiser=label,
                scene=scene,
                spp=int(spp),
                frame=int(frame),
                samples=int(samples),
                mean_spp=float(mean),
                max_spp=int(top),
                pixels_without_samples=int(empty),
                spp_map=counts,
            )
        )
    return out
