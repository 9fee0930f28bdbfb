"""The report's hard-case stability table: a hook into the denoisers' hard-case suite.

The suite (fireflies, black frames, zero albedo, 1e-6..1e6 range, NaN/Inf inputs, odd sizes) lives
in ``denoisebench.denoisers.hard_cases``. The contract this hook expects of it:

``run_hard_cases(denoiser) -> list[dict]``
    one dict per case with ``case`` (name), ``status`` (``"ok"`` or ``"failed"``) and ``detail``
    (one line: the error, or a number such as the output's relMSE).

When that module (or the function) is not there, :func:`stability_table` returns None and the
report says the suite is not available, instead of showing an empty table.
"""

from __future__ import annotations

import importlib


def stability_table(denoisers: dict[str, object]) -> dict[str, list[dict]] | None:
    """{label: rows} for every denoiser instance, or None when the hard-case suite is absent."""
    try:
        module = importlib.import_module("denoisebench.denoisers.hard_cases")
    except ModuleNotFoundError:
        return None
    run = getattr(module, "run_hard_cases", None)
    if not callable(run):
        return None
    table = {}
    for label, denoiser in denoisers.items():
        try:
            table[label] = [dict(row) for row in run(denoiser)]
        except Exception as exc:  # noqa: BLE001 - the suite itself failing is shown, not fatal
            table[label] = [{"case": "(suite)", "status": "failed", "detail": f"{type(exc).__name__}: {exc}"}]
    return table
