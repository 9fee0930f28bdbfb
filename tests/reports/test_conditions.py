"""Report conditions on a synthetic run (8×8 px, so SSIM cannot apply): metrics that did not apply are
named in report.md and index.html with their scenes, counts and reason; no sampler or cvvdp section
appears in a run without them; the report model is a typed record, read by attribute only, whose
results.json keeps its keys.

Checked by hand when the model became a dataclass: on a fixed store (2 cornell scenes, 16×16, 2 frames,
spp 1 and 2, identity and cross_bilateral_fast, samplers uniform and a half-frame plugin, cvvdp) the
report written before and after the change is byte-identical (results.json, results.csv, report.md,
index.html, PNGs)."""

from __future__ import annotations

import json
import re

import pytest

from denoisebench.cli import main
from denoisebench.dataset.synthetic import make_synthetic_dataset


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    root = tmp_path_factory.mktemp("conditions")
    data = make_synthetic_dataset(root / "ds", scenes=2, frames=2, height=8, width=8, spp=(1,), ref_spp=4)
    args = ["--data", str(data), "--db", str(root / "db.sqlite"), "--out", str(root / "report")]
    args += ["--time-size", "64x64"]
    assert main(["benchmark", *args, "--denoisers", "identity", "--metrics", "relmse,ssim,psnr", "--split", "all"]) == 0
    return root / "report"


#: results.json's top-level keys, in order, for a run without samplers or cvvdp (``samplers`` and
#: ``cvvdp_viewing`` come after ``not_applicable`` when measured).
RESULTS_KEYS = [
    "run",
    "denoisers",
    "scenes",
    "scene_effects",
    "spp",
    "reference",
    "summary",
    "accuracy_time",
    "readings",
    "time_model",
    "equal_tables",
    "effects",
    "flicker",
    "not_distinguishable",
    "failures",
    "unresolved_references",
    "not_applicable",
    "stability",
    "deciding_frames",
    "frames",
    "sequence_metrics",
]

#: ReportModel's fields results.json does not hold: images, figures and what the Markdown and HTML
#: render from the other fields (metric orders, verdict sentences, the first screen, identical groups).
RENDERED_ONLY = {
    "comparisons",
    "figures",
    "first_screen",
    "frame_metrics",
    "identical",
    "not_applicable_detail",
    "palette",
    "sequence_metrics",
    "strips",
    "temporal_metrics",
    "verdicts",
}


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


def test_the_report_model_is_a_documented_record_read_by_attribute(report, tmp_path):
    import ast
    import dataclasses
    import inspect

    from denoisebench.dataset import open_dataset
    from denoisebench.reports import model as report_model
    from denoisebench.reports.build import build_report, results_json, write_report
    from denoisebench.reports.model import ReportModel
    from denoisebench.results.store import ResultsStore

    # every field typed and followed by its docstring
    body = next(n for n in ast.parse(inspect.getsource(report_model)).body if getattr(n, "name", "") == "ReportModel")
    documented = {
        a.target.id
        for a, doc in zip(body.body, body.body[1:])
        if isinstance(a, ast.AnnAssign) and isinstance(doc, ast.Expr) and isinstance(doc.value, ast.Constant)
    }
    names = [f.name for f in dataclasses.fields(ReportModel)]
    assert set(names) == documented
    # every field is results.json's or one of the parts only the rendered report shows: a new field is
    # added to one side on purpose (results.json's keys are pinned below)
    written = set(re.findall(r"\breport\.(\w+)", inspect.getsource(results_json)))
    assert set(names) == written | RENDERED_ONLY and not written & RENDERED_ONLY, set(names) ^ (written | RENDERED_ONLY)
    root = report.parent
    with ResultsStore(root / "db.sqlite", readonly=True) as store:
        (run,) = store.runs()
        data = open_dataset(root / "ds")
        model = build_report(store, run.run_id, data)
        for out in ("one", "two"):  # without denoiser instances: no stability table, else as the CLI's
            write_report(store, run.run_id, data, tmp_path / out)
    assert isinstance(model, ReportModel)
    with pytest.raises(TypeError):  # no key access
        model["summary"]
    assert not hasattr(model, "get")
    # the same store gives the same bytes, and results.json keeps its keys in their order
    for name in ("results.json", "results.csv", "report.md", "index.html"):
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes(), name
    assert list(json.loads((report / "results.json").read_text())) == RESULTS_KEYS
    assert json.loads((tmp_path / "one" / "results.json").read_text())["stability"] is None
