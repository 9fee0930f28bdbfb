"""The report opens with its first screen, on a real (tiny) run: one row per denoiser, identical
denoisers in one row with the sentence that says so, the per-scene small multiples, and wide tables
collapsed with their lead columns first (HTML ``<details>``, Markdown a second table)."""

from __future__ import annotations

import re
import textwrap

import pytest

from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.reports import formatting as fmt
from denoisebench.reports.build import build_report
from denoisebench.reports.html import render_html
from denoisebench.reports.markdown import render_markdown
from denoisebench.results.store import ResultsStore

METRICS = ["relmse", "relmse_robust", "flip"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("first_screen")
    plugin = root / "twins.py"
    plugin.write_text(
        textwrap.dedent(
            """
            import numpy as np
            from scipy.ndimage import uniform_filter

            class Blur:
                '''A 3x3 box blur of the input.'''

                def denoise(self, frame):
                    return uniform_filter(np.asarray(frame.color, np.float32), size=(3, 3, 1))

            class BlurToo(Blur):
                '''The same blur under another name.'''
            """
        )
    )
    data = open_dataset(make_synthetic_dataset(root / "ds", scenes=2, frames=2, height=16, width=16, spp=(1, 4)))
    config = BenchmarkConfig(
        denoisers=["cross_bilateral_fast", f"{plugin}:Blur", f"{plugin}:BlurToo"],
        spp=[1, 4],
        split="all",
        metrics=METRICS,
        isolation="none",
    )
    with ResultsStore(root / "r.sqlite") as store:
        plan = run_benchmark(data, config, store, progress=False)
        report = build_report(store, plan.run_id, data, time_at=(16, 16))
    out = root / "report"  # written here from the one model (write_report would build it again)
    (out / "figures").mkdir(parents=True)
    (out / "index.html").write_text(render_html(report))
    (out / "report.md").write_text(render_markdown(report))
    for name, (png, _) in report.figures.items():
        (out / "figures" / f"{name}.png").write_bytes(png)
    return out, report


def test_the_first_screen_has_one_row_per_denoiser_and_one_for_the_identical_pair(run):
    _, report = run
    screen = report.first_screen
    assert screen is not None and screen.metric == "relmse_robust"
    names = [r.denoiser for r in screen.rows]
    assert len(names) == 2 and "cross_bilateral_fast" in names, names
    twins = next(n for n in names if n != "cross_bilateral_fast")
    assert "Blur" in twins and "BlurToo" in twins and " = " in twins
    for row in screen.rows:
        assert row.best_spp in (1, 4) and row.seconds > 0 and row.error > 0
    assert len(report.identical) == 1 and report.identical[0].images >= 2  # kept frames compared pixel by pixel
    assert "identical" in report.identical[0].sentence()
    # the reference cannot tell the twins apart on any score (difference 0); being identical, said once,
    # they are left out of the "not distinguishable" sentences
    twin_pairs = [p for p in report.indistinguishable if {p.a, p.b} == set(report.identical[0].labels)]
    assert twin_pairs
    assert not any("Blur and" in line and "BlurToo" in line for line in fmt.indistinguishable_lines(report))


def test_index_html_opens_with_the_summary_and_collapses_wide_tables(run):
    out, report = run
    html = (out / "index.html").read_text()
    sections = re.findall(r'<section id="([a-z]+)"', html)
    assert sections[0] == "summary", sections
    summary = html.split('<section id="summary">', 1)[1].split("</section>", 1)[0]
    assert summary.count("<tr>") == 1 + len(report.first_screen.rows)  # header + rows
    assert "are identical in this run" in summary and "Best at equal time" in summary
    # the per-spp result tables: lead columns shown, the whole table one click away
    results = html.split('<section id="results">', 1)[1].split("</section>", 1)[0]
    assert results.count("<details>") >= len(report.spp)
    lead_table = results.split("<table>", 2)[1]  # the first table after the small multiples
    lead_header = lead_table.split("</thead>")[0]
    assert "relmse_robust" in lead_header and " raw<" not in lead_header and " floor<" not in lead_header
    assert (out / "figures" / "scenes.png").is_file() and "where each denoiser wins" in html.lower()


def test_report_md_has_the_summary_first_and_splits_wide_tables(run):
    out, report = run
    markdown = (out / "report.md").read_text()
    assert markdown.index("## Summary") < markdown.index("## Accuracy against time")
    assert markdown.count("More columns") >= len(report.spp)
    assert "figures/scenes.png" in markdown
