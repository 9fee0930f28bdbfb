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
* The suite is part of the package and imported as any module is (no import by name at run time,
  so the architecture test sees the arrow). A suite that raises on a denoiser is shown as that
  denoiser's ``(suite)`` row, not fatal.
"""

from __future__ import annotations

from denoisebench.denoisers import hard_cases


def stability_table(denoisers: dict[str, object]) -> dict[str, list[dict]]:
    """{label: [{case, status, detail, seconds}]} for every denoiser instance."""
    table = {}
    for label, denoiser in denoisers.items():
        try:
            results = hard_cases.check_denoiser(denoiser, name=label)
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
