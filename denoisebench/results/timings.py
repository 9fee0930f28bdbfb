"""The run's timing records in the store (table ``run_timings``), the machine they were taken on,
and the spread floor every measured cost carries.

Measurements (:mod:`denoisebench.benchmark.timing`) are written once per run and reused when the run
resumes or its report is rebuilt; the time model (:mod:`denoisebench.analysis.time_model`) reads them.
A store made before the table existed, or opened read-only before any timing, reads as no timings.
"""

from __future__ import annotations

import json
import os
import platform
import sqlite3

#: The least spread (largest / least plausible time) every measured cost carries: repeats on a shared
#: machine never see all of its load, so no time is taken as known to better than this.
MIN_SPREAD = 1.1
#: Timed renders per probe point after the warm-up, interleaved over the buffer sets and the two sizes (the minimum
#: is kept).
PROBE_REPEATS = 3
#: The buffers every render makes (with their variances), a colour-only one too: what rendering more samples
#: without a denoiser is charged (the render probe's line of this set; ``benchmark.timing.render_buffers``).
COLOUR_ONLY = ("color", "diffuse", "specular")
#: The buffer-set name of per-sample data (a denoiser that reads them is charged every feature and them).
SAMPLES = "samples"
#: Timed calls per denoiser at the second size (the minimum is kept; one when a call takes over 2 s).
TIMING_REPEATS = 3

_TABLE = (
    "CREATE TABLE IF NOT EXISTS run_timings (run_id TEXT NOT NULL, key TEXT NOT NULL, value TEXT NOT NULL, "
    "PRIMARY KEY (run_id, key))"
)


def machine() -> dict:
    """Cores, CPU and GPU (None without CUDA) of this machine, as a report states them."""
    gpu = None
    try:
        import torch

        if torch.cuda.is_available():
            gpu = torch.cuda.get_device_name(0)
    except Exception:  # noqa: BLE001 - no torch or no driver: no GPU to state
        gpu = None
    return {
        "cores": os.cpu_count(),
        "cpu": platform.processor() or platform.machine(),
        "system": platform.system(),
        "gpu": gpu,
    }


def read_timings(store, run_id: str) -> dict[str, dict]:
    """{key: value} of a run's timing records ({} for a store without the table)."""
    try:
        rows = store.conn.execute("SELECT key, value FROM run_timings WHERE run_id = ?", (run_id,)).fetchall()
    except sqlite3.OperationalError:  # an older store, or one opened read-only before any timing
        return {}
    return {key: json.loads(value) for key, value in rows}


def write_timing(store, run_id: str, key: str, value: dict) -> None:
    with store.transaction() as conn:
        conn.execute(_TABLE)
        conn.execute(
            "INSERT OR REPLACE INTO run_timings (run_id, key, value) VALUES (?, ?, ?)",
            (run_id, key, json.dumps(value, sort_keys=True)),
        )
