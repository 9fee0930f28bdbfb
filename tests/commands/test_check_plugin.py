"""check-plugin: the example plugin package installed for real, exit codes, table and JSON output."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from denoisebench import cli
from denoisebench.commands.check_plugin import parse_options
from denoisebench.denoisers.hard_cases import CASES
from denoisebench.errors import UserInputError
from tests.support.paths import REPO  # noqa: E402

EXAMPLE = REPO / "examples" / "denoisebench-example-plugin"


def _run(*args: str) -> subprocess.CompletedProcess:
    # a fresh interpreter: the editable install's path hook is read at start-up
    return subprocess.run([sys.executable, "-m", "denoisebench.cli", *args], capture_output=True, text=True, cwd=REPO)


def test_installed_plugin_is_found_through_its_entry_point(installed_example):
    code = textwrap.dedent(
        f"""
        from denoisebench.denoisers.registry import available_denoisers, load_denoiser
        from denoisebench.denoisers.runner import run_frame
        from denoisebench.denoisers.synthetic import synthetic_frame
        from denoisebench.metrics.ours.spatial import relmse
        origin = available_denoisers()["{installed_example}"]
        denoiser = load_denoiser("{installed_example}", size=5)
        frame = synthetic_frame("textured", 32, 32, 4, seed=3)
        result = run_frame(denoiser, frame)
        print(origin, denoiser.size, result.status, relmse(result.output, frame.reference) < relmse(frame.color, frame.reference))
        """
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    origin, size, status, improved = done.stdout.split()[-4:]
    assert "entry point" in done.stdout and "denoisebench-example-plugin" in done.stdout
    assert (size, status, improved) == ("5", "ok", "True")


def test_installed_plugin_loads_in_process(installed_example):
    from denoisebench.denoisers.registry import load_denoiser

    assert load_denoiser(installed_example).name == installed_example


def test_check_plugin_passes_the_installed_example(installed_example):
    done = _run("check-plugin", installed_example)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"{len(CASES)}/{len(CASES)} cases passed" in done.stdout
    listed = _run("check-plugin", "--list")
    assert installed_example in listed.stdout and "fireflies" in listed.stdout


def test_check_plugin_on_a_builtin_prints_a_table(capsys):
    assert cli.main(["check-plugin", "cross_bilateral_fast"]) == 0
    out = capsys.readouterr().out
    for case in CASES:
        assert f"{case.name} " in out
    assert "FAIL" not in out


def test_failing_plugin_exits_1_and_names_the_failures(tmp_path, capsys):
    plugin = tmp_path / "flaky.py"
    plugin.write_text(
        textwrap.dedent(
            """
            import numpy as np

            class Flaky:
                name = "flaky"
                def denoise(self, frame):
                    if frame.width == 3:
                        raise RuntimeError("cannot do tiny images")
                    if frame.spp == 1:
                        return np.full(frame.color.shape, np.nan, np.float32)
                    return np.array(frame.color, np.float32)
            """
        )
    )
    code = cli.main(["check-plugin", f"{plugin}:Flaky", "--json"])
    report = json.loads(capsys.readouterr().out)
    assert code == 1 and report["passed"] is False
    failed = {case["case"]: case["reason"] for case in report["cases"] if not case["passed"]}
    assert set(failed) == {"tiny", "one_spp"}
    assert "RuntimeError: cannot do tiny images" in failed["tiny"] and "NaN" in failed["one_spp"]
    assert sum(case["passed"] for case in report["cases"]) == len(CASES) - 2


@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["check-plugin", "no_such_denoiser_xyz"], "unknown denoiser"),
        (["check-plugin", "identity", "--case", "bogus"], "unknown hard case"),
        (["check-plugin"], "SPEC"),
        (["check-plugin", "identity", "--option", "novalue"], "KEY=VALUE"),
        (["check-plugin", "cross_bilateral", "--option", "preset=\"ultra\""], "unknown cross_bilateral preset"),
    ],
)
def test_bad_input_exits_2_with_one_line(argv, fragment, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err and fragment in err[-1] and err[-1].startswith("error: ")


def test_parse_options():
    assert parse_options(["radius=7", "preset=fast", "features=[\"albedo\"]", "x=1.5"]) == {
        "radius": 7,
        "preset": "fast",
        "features": ["albedo"],
        "x": 1.5,
    }
    with pytest.raises(UserInputError):
        parse_options(["1bad=3"])


def test_selected_cases_only(capsys):
    assert cli.main(["check-plugin", "identity", "--case", "tiny", "--case", "fireflies", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [case["case"] for case in report["cases"]] == ["tiny", "fireflies"]
