"""A plugin author's first minutes: the README's plugin, plain functions, sibling imports, tracebacks,
hints on failing hard cases, one failure type for both proxies, and a quiet, clean run-benchmark."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from denoisebench import cli
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.denoisers import hard_cases
from denoisebench.denoisers.isolation import IsolatedDenoiser
from denoisebench.denoisers.registry import DenoiserLoadError, UnknownOptionError, load_denoiser
from denoisebench.denoisers.runner import run_sequence
from denoisebench.denoisers.synthetic import synthetic_sequence
from denoisebench.plugins import Limits, PluginFailure, PluginProxy, sandbox
from denoisebench.sampling import synthetic
from denoisebench.sampling.harness import run_sampler
from denoisebench.sampling.isolation import IsolatedSampler
from denoisebench.sampling.protocol import Budget
from tests.support.paths import REPO  # noqa: E402

SANDBOXED = sandbox.unavailable_reason() is None
POLICY = "plugins" if SANDBOXED else "process"

HELPERS = """
def scale(color, gain):
    return color * gain
"""

PLUGIN = '''
import numpy as np
import helpers  # the module beside this file


def denoise(frame, gain=1.0):
    return helpers.scale(frame.color, gain).astype(np.float32)


denoise.needs = {"color", "albedo"}


def two_arguments(frame, other):
    return frame.color


def boom(frame):
    return _deeper(frame)


def _deeper(frame):
    raise ValueError("plugin bug on purpose")


def sample(budget, rounds):
    rounds.render(np.full((rounds.height, rounds.width), 2))


def boom_sampler(budget, rounds):
    raise RuntimeError("sampler bug on purpose")
'''


@pytest.fixture(scope="module")
def plugin_dir(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("author")
    (folder / "helpers.py").write_text(textwrap.dedent(HELPERS))
    (folder / "plug.py").write_text(textwrap.dedent(PLUGIN))
    return folder


def _readme_plugin() -> str:
    """The README's minimal plugin, as written there."""
    text = (REPO / "README.md").read_text()
    match = re.search(r"```python\n(# my_denoiser\.py\n.*?)```", text, re.S)
    assert match, "the README has no minimal plugin (```python # my_denoiser.py ...)"
    return match.group(1)


def test_a_plain_function_is_a_denoiser_with_its_options_and_attributes(plugin_dir):
    denoiser = load_denoiser(f"{plugin_dir}/plug.py:denoise", gain=2.0)
    assert denoiser.needs == {"color", "albedo"}
    sequence = synthetic_sequence(frames=1, height=8, width=8)
    (result,) = run_sequence(denoiser, sequence)
    assert result.ok, result.error
    np.testing.assert_allclose(result.output, 2.0 * sequence[0].color, rtol=1e-6)
    with pytest.raises(UnknownOptionError, match="it takes gain"):
        load_denoiser(f"{plugin_dir}/plug.py:denoise", gian=2.0)


def test_a_function_of_other_arguments_is_refused_with_what_to_write(plugin_dir):
    with pytest.raises(DenoiserLoadError, match=r"a denoiser plugin is a function denoise\(frame\)"):
        load_denoiser(f"{plugin_dir}/plug.py:two_arguments")


def test_a_file_plugin_imports_the_module_beside_it_in_its_worker(plugin_dir):
    denoiser = IsolatedDenoiser(f"{plugin_dir}/plug.py:denoise", {"gain": 0.5}, sandboxed=SANDBOXED)
    try:
        sequence = synthetic_sequence(frames=1, height=8, width=8)
        (result,) = run_sequence(denoiser, sequence)
        assert result.ok, result.error
        np.testing.assert_allclose(result.output, 0.5 * sequence[0].color, rtol=1e-6)
    finally:
        denoiser.close()


def test_the_readme_plugin_passes_every_hard_case_and_a_plain_blur_fails_fireflies_with_a_hint(tmp_path, capsys):
    """The README's plugin passes all ten hard cases; what the README says a FAIL looks like holds for
    its own example (a plain Gaussian blur fails ``fireflies``, with a hint)."""
    (tmp_path / "my_denoiser.py").write_text(_readme_plugin())
    code = cli.main(["check-plugin", f"{tmp_path}/my_denoiser.py:denoise", "--isolation", POLICY, "--json"])
    cases = {c["case"]: c for c in json.loads(capsys.readouterr().out)["cases"]}
    assert code == 0 and len(cases) == 10 and all(c["passed"] for c in cases.values()), cases
    readme = (REPO / "README.md").read_text()
    assert "passes all ten hard cases" in readme and "plain Gaussian\nblur, for one, fails `fireflies`" in readme
    (tmp_path / "blur.py").write_text(
        "import numpy as np\nfrom scipy.ndimage import gaussian_filter\n\n\n"
        "def denoise(frame):\n    return gaussian_filter(frame.color, sigma=(1.0, 1.0, 0)).astype(np.float32)\n"
    )
    spec = f"{tmp_path}/blur.py:denoise"
    code = cli.main(["check-plugin", spec, "--case", "tiny", "--case", "fireflies", "--isolation", POLICY, "--json"])
    cases = {c["case"]: c for c in json.loads(capsys.readouterr().out)["cases"]}
    assert code == 1 and cases["tiny"]["passed"] and not cases["fireflies"]["passed"], cases
    assert cases["fireflies"]["hint"].startswith("tests isolated samples") and "usual fix" in cases["fireflies"]["hint"]


def test_a_raising_plugins_traceback_reaches_check_plugin_json_and_verbose(plugin_dir, capsys):
    spec = f"{plugin_dir}/plug.py:boom"
    assert cli.main(["check-plugin", spec, "--case", "tiny", "--isolation", POLICY, "--json"]) == 1
    (case,) = json.loads(capsys.readouterr().out)["cases"]
    assert case["reason"] == "frame 0: raised ValueError: plugin bug on purpose"
    assert "plug.py" in case["traceback"] and "_deeper" in case["traceback"], case["traceback"]
    assert cli.main(["check-plugin", spec, "--case", "tiny", "--isolation", POLICY, "--verbose"]) == 1
    out = capsys.readouterr().out
    assert "traceback of case tiny:" in out and 'raise ValueError("plugin bug on purpose")' in out


def test_a_raising_plugin_in_this_process_keeps_its_traceback_and_logs_it(plugin_dir, caplog):
    denoiser = load_denoiser(f"{plugin_dir}/plug.py:boom")
    with caplog.at_level("WARNING", logger="denoisebench.plugins"):
        results = run_sequence(denoiser, synthetic_sequence(frames=2, height=8, width=8), name="boom")
    assert all("_deeper" in (r.traceback or "") for r in results)
    logged = [r for r in caplog.records if r.name == "denoisebench.plugins"]
    assert len(logged) == 1 and "_deeper" in logged[0].getMessage()  # once per distinct error


def test_a_raising_sampler_logs_its_traceback(plugin_dir, caplog):
    sampler = IsolatedSampler(f"{plugin_dir}/plug.py:boom_sampler", sandboxed=SANDBOXED)
    try:
        with caplog.at_level("WARNING", logger="denoisebench.plugins"):
            record = run_sampler(sampler, synthetic.constant(8, 8), Budget(spp=4))
    finally:
        sampler.close()
    assert record.stopped == "error" and "sampler bug on purpose" in record.error
    (logged,) = [r.getMessage() for r in caplog.records if r.name == "denoisebench.plugins"]
    assert "plug.py" in logged and "boom_sampler" in logged


def test_each_hard_case_has_a_hint():
    assert all(case.hint for case in hard_cases.CASES)


def test_one_failure_type_and_one_limits_for_both_proxies(plugin_dir):
    assert issubclass(IsolatedDenoiser, PluginProxy) and issubclass(IsolatedSampler, PluginProxy)
    denoiser = IsolatedDenoiser(f"{plugin_dir}/plug.py:boom", limits=Limits(time_limit=60), sandboxed=SANDBOXED)
    try:
        with pytest.raises(PluginFailure) as raised:
            denoiser.denoise(synthetic_sequence(frames=1, height=8, width=8)[0])
        assert "_deeper" in raised.value.traceback
    finally:
        denoiser.close()
    # a plain function is a sampler too, and its worker's failure is the same type
    sampler = IsolatedSampler(f"{plugin_dir}/plug.py:sample", limits=Limits(time_limit=60), sandboxed=SANDBOXED)
    try:
        assert sampler.limits == Limits(time_limit=60)
        record = run_sampler(sampler, synthetic.constant(8, 8), Budget(spp=4))
        assert record.stopped != "error", record.error
        sampler._disabled = "disabled on purpose"
        with pytest.raises(PluginFailure, match="disabled on purpose"):
            sampler.sample(Budget(spp=4), None)
    finally:
        sampler.close()


def test_a_refused_run_writes_no_files(tmp_path, capsys):
    dataset = make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=1, height=8, width=8, spp=(1,))
    argv = ["benchmark", "--data", str(dataset), "--denoisers", "identiy", "--out", str(tmp_path / "out")]
    assert cli.main([*argv, "--db", str(tmp_path / "r.sqlite")]) == 2
    assert "unknown denoiser 'identiy'" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]
    argv = [*argv[:4], "identity", "--option", "identity:strength=1", *argv[5:]]  # refused while loading
    assert cli.main([*argv, "--db", str(tmp_path / "r.sqlite")]) == 2
    assert "has no option 'strength'" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_run_benchmark_scores_plain_function_plugins_quietly(tmp_path, plugin_dir):
    """The README's plugin and a sibling-importing one score; stderr holds no bindings' leak report."""
    (tmp_path / "my_denoiser.py").write_text(_readme_plugin())
    dataset = make_synthetic_dataset(tmp_path / "ds", scenes=1, frames=2, height=16, width=16, spp=(1,))
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "denoisebench.cli",
            "benchmark",
            "--time-size",
            "64x64",
            "--data",
            str(dataset),
            "--denoisers",
            "identity",
            "--denoiser",
            f"{tmp_path}/my_denoiser.py:denoise",
            "--denoiser",
            f"{plugin_dir}/plug.py:denoise",
            "--isolation",
            POLICY,
            "--out",
            str(tmp_path / "out"),
            "--db",
            str(tmp_path / "r.sqlite"),
            "--time-budget",
            "1",
            "--no-render-probe",
        ],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "nanobind: leaked" not in done.stderr, done.stderr[-3000:]
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    rows = {row["denoiser"]: row for row in results["summary"]}
    for label in (f"{tmp_path}/my_denoiser.py:denoise", f"{plugin_dir}/plug.py:denoise"):
        assert rows[label]["failed_units"] == 0 and rows[label]["errors"] == [], rows.get(label)
        assert rows[label]["metrics"], rows[label]
    # the newcomer's last step: the leaderboard shows the report's numbers for that run
    board = subprocess.run(
        [sys.executable, "-m", "denoisebench.cli", "leaderboard", "--db", str(tmp_path / "r.sqlite"), "--spp", "1"],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert board.returncode == 0, board.stderr[-3000:]
    lines = board.stdout.strip().splitlines()
    table = lines[next(i for i, line in enumerate(lines) if line.startswith("-")) + 1 :]
    shown = {line.split()[1]: float(line.split()[2]) for line in table}
    assert set(shown) == set(rows)
    for label, value in shown.items():
        assert value == pytest.approx(rows[label]["metrics"]["relmse_robust"]["mean"], rel=1e-3), label


def test_a_plugin_that_fails_to_load_shows_its_traceback_with_verbose(tmp_path, capsys):
    (tmp_path / "broken.py").write_text("import math\n\nmath.no_such_function()\n\n\ndef denoise(frame):\n    pass\n")
    argv = ["check-plugin", f"{tmp_path}/broken.py:denoise", "--case", "tiny", "--isolation", POLICY]
    assert cli.main(argv) == 2
    assert "Traceback" not in capsys.readouterr().err  # one line without --verbose
    assert cli.main([*argv, "--verbose"]) == 2
    err = capsys.readouterr().err
    assert "broken.py\", line 3" in err and "math.no_such_function()" in err
    assert err.rstrip().splitlines()[-1].startswith("error: cannot import")


def test_check_plugin_sampler_shows_where_a_plain_function_sampler_raised(plugin_dir, capsys):
    argv = ["check-plugin", "--sampler", f"{plugin_dir}/plug.py:boom_sampler", "--isolation", POLICY]
    assert cli.main([*argv, "--json"]) == 1
    summary = json.loads(capsys.readouterr().out)
    assert summary["reasons"][0].endswith("the sampler failed: RuntimeError: sampler bug on purpose")
    assert "boom_sampler" in summary["budgets"][0]["tracebacks"][0]
    assert cli.main([*argv, "--verbose"]) == 1
    out = capsys.readouterr().out
    assert "traceback of the sampler:" in out and 'raise RuntimeError("sampler bug on purpose")' in out
