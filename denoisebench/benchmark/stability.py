"""The report's hard-case stability table, from the denoisers' hard-case suite.

The suite (:mod:`denoisebench.denoisers.hard_cases`: fireflies, black frames, zero albedo,
1e-6..1e6 range, NaN/Inf inputs, odd and tiny sizes, ...) runs every denoiser instance of the
run on its synthetic cases; a case passes when every output is finite, non-negative and keeps the
input's energy (the suite's docstring says exactly what is checked).

Notes
-----
* The suite's frames are small and fixed, so this adds seconds, not minutes, per denoiser; it runs
  on the instances the benchmark used, after the benchmark (a temporal denoiser is reset by the
  suite before each case).
* When the suite is not importable the function returns None and the report says so, instead of
  showing an empty table.
"""

from __future__ import annotations

import importlib


def stability_table(denoisers: dict[str, object]) -> dict[str, list[dict]] | None:
    """{label: [{case, status, detail}]} for every denoiser instance, or None without the suite."""
    try:
        suite = importlib.import_module("denoisebench.denoisers.hard_cases")
    except ModuleNotFoundError:
        return None
    table = {}
    for label, denoiser in denoisers.items():
        try:
            results = suite.check_denoiser(denoiser, name=label)
        except Exception as exc:  # noqa: BLE001 - the suite itself failing is shown, not fatal
            table[label] = [{"case": "(suite)", "status": "failed", "detail": f"{type(exc).__name__}: {exc}"}]
            continue
        table[label] = [
            {
                "case": r.case,
                "status": "ok" if r.passed else "failed",
                "detail": r.reason or (f"{r.sanitized} NaN/Inf replaced" if r.sanitized else ""),
                "seconds": r.seconds,
            }
            for r in results
        ]
    return table
