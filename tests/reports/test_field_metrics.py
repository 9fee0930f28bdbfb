"""run-benchmark with the field's metrics: ``--metrics cvvdp,noisebase`` end to end (16×16, 3 frames).

The report's flicker table carries cvvdp right after the scale-free temporal relMSE;
the Noisebase set expands to its six metrics and is stored like any other.
"""

from __future__ import annotations

import json

import pytest

from denoisebench.cli import main
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.metrics.field.noisebase import NOISEBASE_METRICS


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("field")
    data = make_synthetic_dataset(root / "ds", scenes=4, frames=3, height=16, width=16, spp=(1,))
    code = main(
        [
            "benchmark",
            "--time-size",
            "64x64",
            "--data",
            str(data),
            "--db",
            str(root / "db.sqlite"),
            "--out",
            str(root / "report"),
            "--denoisers",
            "identity",
            "--metrics",
            "cvvdp,noisebase",
        ]
    )
    assert code == 0
    return root / "report"


def test_flicker_table_shows_cvvdp_beside_the_scale_free_score(report):
    md = (report / "report.md").read_text()
    flicker = md[md.index("## Temporal flicker") :]
    header = next(line for line in flicker.splitlines() if line.startswith("| denoiser"))
    columns = [c.strip() for c in header.strip("|").split("|")]
    lead = [c for c in columns if not c.startswith("temporal\\_relmse")][1]
    assert lead == "cvvdp ↑"  # first column after temporal_relmse and its floor columns
    assert "ColorVideoVDP" in (report / "index.html").read_text()


def test_noisebase_set_is_measured_and_stored(report):
    results = json.loads((report / "results.json").read_text())
    row = next(r for r in results["summary"] if r["denoiser"] == "identity")
    assert set(NOISEBASE_METRICS) <= set(row["metrics"])
    jod = [s["value"] for s in results["sequence_metrics"] if s["metric"] == "cvvdp"]
    assert jod and all(0.0 < v <= 10.0 for v in jod)
