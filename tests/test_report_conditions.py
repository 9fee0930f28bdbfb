"""Report conditions on a synthetic run (8×8 px, so SSIM cannot apply): metrics that did not apply are
named in report.md and index.html with their scenes, counts and reason; no sampler or cvvdp section
appears in a run without them."""

from __future__ import annotations

import json

import pytest

from denoisebench.cli import main
from denoisebench.dataset.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("conditions")
    data = make_synthetic_dataset(root / "ds", scenes=2, frames=2, height=8, width=8, spp=(1,), ref_spp=4)
    args = ["--data", str(data), "--db", str(root / "db.sqlite"), "--out", str(root / "report")]
    assert main(["benchmark", *args, "--denoisers", "identity", "--metrics", "relmse,ssim,psnr", "--split", "all"]) == 0
    return root / "report"


def test_metrics_that_did_not_apply_are_named_with_their_scenes_and_reason(report):
    results = json.loads((report / "results.json").read_text())
    assert results["not_applicable"]["ssim"]["count"] == 2 * 2 * 2  # scenes × frames × (noisy, identity)
    scenes = ", ".join(sorted(results["scenes"]))
    md, page = (report / "report.md").read_text(), (report / "index.html").read_text()
    line = next(x for x in md.splitlines() if x.startswith("- ssim: no value"))
    assert line.replace("\\_", "_").startswith(f"- ssim: no value on 8 frame(s) of scene(s) {scenes}")
    assert "at least 11×11" in line and "8×8" in line
    assert "Metrics that did not apply" in page and f"ssim: no value on 8 frame(s) of scene(s) {scenes}" in page


def test_a_run_without_samplers_or_cvvdp_has_no_such_sections(report):
    results = json.loads((report / "results.json").read_text())
    assert "samplers" not in results and "cvvdp_viewing" not in results
    md, page = (report / "report.md").read_text(), (report / "index.html").read_text()
    assert "## Samplers" not in md and "cvvdp viewing conditions" not in md
    assert 'id="samplers"' not in page and "cvvdp viewing conditions" not in page
