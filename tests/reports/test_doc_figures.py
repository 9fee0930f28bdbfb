"""scripts/check_doc_figures.py: the figures docs/ quotes from a demo report, checked against a report.

A tiny real run (one synthetic scene, 16×16, spp 1 and 2) writes a report; a page quoting its figures
passes, a planted wrong figure fails (exit 1), ``--update`` rewrites it to the report's value, and a
path the report does not have is bad input (exit 2). The tables docs/ ships are read by the same code.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.reports.build import write_report
from denoisebench.results.store import ResultsStore

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "scripts" / "check_doc_figures.py"


def _script():
    spec = importlib.util.spec_from_file_location("check_doc_figures", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)  # its dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def report(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("tiny")
    data = open_dataset(make_synthetic_dataset(root / "ds", scenes=1, frames=2, height=16, width=16, spp=(1, 2)))
    with ResultsStore(root / "r.sqlite") as store:
        plan = run_benchmark(
            data,
            BenchmarkConfig(denoisers=["cross_bilateral_fast"], spp=[1, 2], split="all", metrics=["relmse"]),
            store,
            progress=False,
        )
        write_report(store, plan.run_id, data, root / "report")
    return root / "report" / "results.json"


def _page(docs: Path, rows: list[tuple[str, str, str]]) -> Path:
    docs.mkdir(exist_ok=True)
    lines = ["# a page", "", "<!-- figures: a tiny run -->", "| figure | value | results.json |", "|---|---|---|"]
    lines += [f"| {figure} | {value} | `{path}` |" for figure, value, path in rows]
    page = docs / "page.md"
    page.write_text("\n".join(lines + ["<!-- /figures -->", ""]))
    return page


def _run(report: Path, docs: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), "--report", str(report), "--docs", str(docs), *extra],
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_figures_of_the_run_pass_and_a_wrong_one_fails_then_updates(report, tmp_path):
    results = json.loads(report.read_text())
    offset = results["time_model"]["render"]["offset_s"]
    rows = [
        ("scenes", "1", "scenes#"),
        ("spp ladder", "1, 2", "run.config.spp"),
        ("labels", "2", "denoisers#"),
        ("denoisers", "1", "denoisers[kind!=input]#"),
        ("the denoiser", "cross_bilateral_fast", "denoisers[kind=denoiser].label"),
        ("fixed render seconds", f"{offset:.3g}", "time_model.render.offset_s"),
    ]
    page = _page(tmp_path / "docs", rows)
    done = _run(report, tmp_path / "docs")
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.count("ok ") == len(rows)

    page.write_text(page.read_text().replace("| scenes | 1 |", "| scenes | 3 |"))
    wrong = _run(report, tmp_path / "docs")
    assert wrong.returncode == 1 and "scenes: docs 3, report 1" in wrong.stdout

    assert _run(report, tmp_path / "docs", "--update").returncode == 0
    assert "| scenes | 1 |" in page.read_text()
    assert _run(report, tmp_path / "docs").returncode == 0


def test_a_number_matches_at_the_digits_quoted():
    script = _script()
    assert script._matches("2.95", 2.9512) and script._matches("0.121", 0.12149) and script._matches("325", 325)
    assert not script._matches("2.95", 2.96) and not script._matches("0.121", 0.1216)
    assert script._matches("1, 2, 4", [1, 2, 4]) and not script._matches("1, 2", [1, 2, 4])
    assert script._as_quoted("2.95", 3.0149) == "3.01" and script._as_quoted("1, 2", [1, 4]) == "1, 4"


def test_a_path_the_report_does_not_have_is_bad_input(report, tmp_path):
    _page(tmp_path / "docs", [("nothing", "1", "time_model.no_such_key")])
    done = _run(report, tmp_path / "docs")
    assert done.returncode == 2 and "no key 'no_such_key'" in done.stderr


def test_the_shipped_tables_name_their_run_and_read_results_json():
    """Every table in docs/ says which run its figures come from, and every path is one the code reads."""
    found = _script().figures(REPO / "docs")
    assert {f.page.name for f in found} >= {"demo.md", "time.md"}
    assert all("denoisebench demo" in f.source for f in found)
    assert all(
        f.path.split(".")[0].split("[")[0].rstrip("#") in {"run", "scenes", "denoisers", "time_model", "equal_tables"}
        for f in found
    )
