"""Sampler plugins: the example package installed for real and found by its entry point; check-plugin --sampler."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from tests.support.editable import editable_install
from tests.support.paths import REPO  # noqa: E402

EXAMPLE = REPO / "examples" / "denoisebench-example-sampler"


@pytest.fixture(scope="module")
def installed_sampler():
    """``pip install --no-deps --no-build-isolation -e`` the example sampler package into this environment
    for the module (removed after it: tests/support/editable.py)."""
    with editable_install(EXAMPLE, "denoisebench-example-sampler"):
        yield "example_variance"


def _cli(*args: str) -> subprocess.CompletedProcess:
    # a fresh interpreter: the editable install's path hook is read at start-up
    return subprocess.run([sys.executable, "-m", "denoisebench.cli", *args], capture_output=True, text=True, cwd=REPO)


def test_the_installed_example_is_found_and_passes_the_convergence_check(installed_sampler):
    done = _cli("check-plugin", "--sampler", installed_sampler, "--option", "rounds=3")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "converges: pass" in done.stdout and "relMSE" in done.stdout
    listed = _cli("check-plugin", "--list")
    assert "example_variance" in listed.stdout and "entry point" in listed.stdout.split("samplers (--sampler):")[1]


def test_a_biased_file_plugin_fails_with_exit_1_and_an_unknown_one_exits_2(tmp_path):
    plugin = tmp_path / "biased.py"
    plugin.write_text(
        textwrap.dedent(
            """
            import numpy as np

            class DarkCorner:
                name = "dark_corner"

                def sample(self, budget, rounds):
                    counts = np.ones((rounds.height, rounds.width), dtype=int)
                    counts[:4, :4] = 0  # never samples the top-left corner
                    while rounds.remaining_samples() > 0 and not rounds.cut:
                        rounds.render(counts)
            """
        )
    )
    done = _cli("check-plugin", "--sampler", f"{plugin}:DarkCorner", "--json")
    assert done.returncode == 1, done.stdout + done.stderr
    assert '"passed": false' in done.stdout and "without a sample" in done.stdout
    missing = _cli("check-plugin", "--sampler", "no_such_sampler")
    assert missing.returncode == 2 and "unknown sampler 'no_such_sampler'" in missing.stderr
    assert "Traceback" not in missing.stderr
