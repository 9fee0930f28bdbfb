"""What the analyses of one run are handed: its rows from the store and what its dataset says of its
references. :mod:`denoisebench.analysis` takes rows and arrays and never opens a store or a file;
the report (:mod:`.build`), the leaderboard (:mod:`.leaderboard`) and the studies load them here.

Notes
-----
* :func:`reference_noisy_shares` reads a few reference EXRs per scene (:data:`NOISE_CHECK_FRAMES`,
  evenly spaced; the largest share is kept): a missing or unreadable reference is skipped, since its
  units have failed already.
"""

from __future__ import annotations

from denoisebench.analysis.aggregate import Unresolved
from denoisebench.analysis.summary import RunData, set_apart
from denoisebench.metrics.floors.closed_form import noisy_value_share

#: References read per scene to measure their noise (evenly spaced frames; the largest share is kept).
NOISE_CHECK_FRAMES = 4


def run_data(store, run_id: str) -> RunData:
    """One run's rows (:meth:`~denoisebench.results.store.ResultsStore.run_rows`), indexed for the analyses."""
    return RunData(store.run_rows(run_id))


def reference_noisy_shares(dataset, scenes: list[str]) -> dict[str, float]:
    """{scene: largest share of reference values too noisy for a floor} over a few frames of each scene
    (:func:`denoisebench.metrics.floors.closed_form.noisy_value_share`); scenes without a reference
    variance are left out."""
    out = {}
    for scene in scenes:
        count = dataset.scene(scene).frame_count
        picks = sorted({round(i * (count - 1) / max(NOISE_CHECK_FRAMES - 1, 1)) for i in range(NOISE_CHECK_FRAMES)})
        shares = []
        for index in picks if count else []:
            try:
                layers, _ = dataset.reference(scene, index)
            except Exception:  # noqa: BLE001 - a missing or unreadable reference: its units failed already
                continue
            if "color_var" in layers:
                shares.append(noisy_value_share(layers["color"], layers["color_var"]))
        if shares:
            out[scene] = max(shares)
    return out


def set_apart_of(data: RunData, dataset) -> list[Unresolved]:
    """The scenes of the run whose scores cannot rank (:func:`denoisebench.analysis.summary.set_apart`),
    judged from ``dataset``'s scene records and a few of its references."""
    return set_apart(
        data,
        records={scene: dataset.scene(scene).record for scene in data.scenes},
        noisy_shares=reference_noisy_shares(dataset, data.scenes),
    )
