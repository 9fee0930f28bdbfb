"""run-benchmark and a plugin author's loop: a broken plugin is bad input, a fixed one is measured again.

* A plugin that cannot be loaded is refused (exit 2) with check-plugin's line, nothing written.
* A plugin that loads but fails on frames: the run completes, exit 3 (documented), report written.
* An edited plugin on the same command gets new units and the output names the run it replaces.
* ``--denoisers all`` on a dataset without per-sample data: rpf, rpf_fast and lightfield are named
  as not runnable with the flag that enables them, and have no (failed) units.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from denoisebench.benchmark.runner import BenchmarkConfig, prepare_run
from denoisebench.cli import main
from denoisebench.commands.benchmark import EXIT_UNITS_FAILED
from denoisebench.dataset import open_dataset
from denoisebench.results.store import ResultsStore

GOOD = """import numpy as np


def denoise(frame):
    return (frame.color * {scale}).astype(np.float32)
"""

FAILS_ON_FRAMES = """def denoise(frame):
    raise RuntimeError("not today")
"""


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bench") / "ds"
    args = ["generate", "--out", str(out), "--families", "cornell", "--frames", "1", "--width", "16"]
    args += ["--height", "16", "--spp", "1", "--ref-spp", "16", "--ref-error", "0", "--quiet"]
    assert main(args) == 0
    return out


def _bench(dataset: Path, tmp_path: Path, *extra: str) -> list[str]:
    return ["benchmark", "--data", str(dataset), "--split", "all", "--time-size", "none", "--no-render-probe"] + [
        "--metrics",
        "relmse",
        "--db",
        str(tmp_path / "b.sqlite"),
        "--out",
        str(tmp_path / "report"),
        *extra,
    ]


@pytest.mark.parametrize(
    "source, attr",
    [
        ("def denoise(frame)\n    return frame.color\n", "denoise"),  # a syntax error
        ("import no_such_module_anywhere\n", "denoise"),  # an import error
        ("x = 1\n", "x"),  # not a denoiser
    ],
)
def test_a_plugin_that_cannot_load_is_bad_input_and_nothing_is_written(dataset, tmp_path, capsys, source, attr):
    plugin = tmp_path / "bad.py"
    plugin.write_text(source)
    spec = f"{plugin}:{attr}"
    assert main(["check-plugin", spec]) == 2
    expected = capsys.readouterr().err.strip().splitlines()[-1]
    assert main(_bench(dataset, tmp_path, "--denoiser", spec)) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == expected and expected.startswith("error: ")
    assert not (tmp_path / "b.sqlite").exists() and not (tmp_path / "report").exists()


def test_a_plugin_failing_on_frames_completes_the_run_with_exit_3(dataset, tmp_path, capsys):
    plugin = tmp_path / "fails.py"
    plugin.write_text(FAILS_ON_FRAMES)
    assert main(_bench(dataset, tmp_path, "--denoisers", "identity", "--denoiser", f"{plugin}:denoise")) == 3
    assert EXIT_UNITS_FAILED == 3
    out = capsys.readouterr().out
    assert "3 units" in out and "1 failed" in out
    assert (tmp_path / "report" / "index.html").is_file()


def test_an_edited_plugin_gets_new_units_on_the_same_command(dataset, tmp_path, capsys):
    plugin = tmp_path / "mine.py"
    plugin.write_text(GOOD.format(scale=1.0))
    argv = _bench(dataset, tmp_path, "--denoiser", f"{plugin}:denoise", "--no-report")
    assert main(argv) == 0
    assert main(argv) == 0  # unchanged: resumed
    assert "(resumed)" in capsys.readouterr().out
    plugin.write_text(GOOD.format(scale=0.5))
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "(new)" in out and "replaces run" in out and "mine.py:denoise" in out
    new_id = re.search(r"run (\w+) \(new\)", out).group(1)
    with ResultsStore(tmp_path / "b.sqlite", readonly=True) as store:
        (new,) = [run for run in store.runs() if run.run_id == new_id]
        (old,) = [run for run in store.runs() if run.run_id != new_id]
        assert new.config["code"] != old.config["code"]
        scores = [{u.denoiser: u for u in store.units(run.run_id)}[f"{plugin}:denoise"].status for run in (new, old)]
        assert scores == ["ok", "ok"] and len(store.units(new.run_id)) == len(store.units(old.run_id)) == 2


def test_all_names_what_cannot_run_without_per_sample_data(dataset, tmp_path):
    with ResultsStore(tmp_path / "b.sqlite") as store:
        config = BenchmarkConfig(denoisers=["all"], spp=[], split="all", metrics=["relmse"])
        plan = prepare_run(open_dataset(dataset), config, store)
        skipped = {d.spec: d.load_error for d in plan.denoisers if d.load_error and "cannot run" in d.load_error}
        for d in plan.denoisers:
            if d.instance is not None and hasattr(d.instance, "close"):
                d.instance.close()
    assert {"rpf", "rpf_fast", "lightfield"} <= set(skipped)
    assert all("generate-dataset --samples" in reason for reason in skipped.values())
    labels = plan.labels
    assert "rpf" not in labels and "identity" in labels and "cross_bilateral" in labels
