"""`denoisebench scenes ...` as a user runs it: exit codes, one-line errors, real files."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.support.paths import DATA as TEST_DATA  # noqa: E402

DATA = TEST_DATA / "usd"


def run_cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "denoisebench.cli", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
    )


def test_help_has_an_example():
    result = run_cli("scenes", "--help")
    assert result.returncode == 0
    assert "denoisebench scenes preview" in result.stdout
    assert run_cli("--help").returncode == 0


@pytest.mark.parametrize(
    "name", ["bad_not_usd.usda", "bad_no_camera.usda", "bad_nan_points.usda", "bad_face_indices.usda"]
)
def test_bad_stage_exits_2_with_one_line(name, tmp_path):
    result = run_cli(
        "scenes", "preview", DATA / name, "--out", tmp_path / "p.png", "--width", 8, "--height", 8, "--spp", 1
    )
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert not (tmp_path / "p.png").exists()


def test_unknown_family_and_bad_frame_exit_2(tmp_path):
    result = run_cli("scenes", "make", "no_such_family", "--out", tmp_path)
    assert result.returncode == 2 and "no_such_family" in result.stderr and "Traceback" not in result.stderr
    result = run_cli("scenes", "preview", DATA / "zup_centimeters.usda", "--out", tmp_path / "p.png", "--frame", 9)
    assert result.returncode == 2 and "out of range" in result.stderr


def test_list_names_every_family_with_effects():
    from denoisebench.scenes import list_families

    result = run_cli("scenes", "list")
    assert result.returncode == 0
    for family in list_families():
        assert family.name in result.stdout


def _digest(folder: Path) -> dict:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def test_make_is_byte_identical_and_preview_writes_a_png(tmp_path):
    from PIL import Image

    from denoisebench.scenes import list_families

    family = list_families()[0].name
    for run in ("a", "b"):
        result = run_cli("scenes", "make", family, "--seed", 5, "--frames", 3, "--out", tmp_path / run)
        assert result.returncode == 0, result.stderr
    assert _digest(tmp_path / "a") == _digest(tmp_path / "b")
    result = run_cli(
        "scenes",
        "preview",
        tmp_path / "a" / "scene.usda",
        "--out",
        tmp_path / "p.png",
        "--width",
        24,
        "--height",
        16,
        "--spp",
        4,
        "--frame",
        2,
    )
    assert result.returncode == 0, result.stderr
    image = np.asarray(Image.open(tmp_path / "p.png"))
    assert image.shape == (16, 24, 3) and image.max() > 0


def test_check_prints_plan_and_warnings():
    import json

    result = run_cli("scenes", "check", DATA / "unsupported_and_degenerate.usda")
    assert result.returncode == 0
    assert "warning: /World/Hair: prim type NurbsCurves is not supported; skipped" in result.stderr
    out = json.loads(result.stdout)
    plan = out["render_plan"]
    assert plan["camera_model"] == "pinhole" and plan["random_parameters"] == ["pixel", "light", "bounce"]
    # the warnings are in the output too, not only on stderr
    assert "/World/Hair: prim type NurbsCurves is not supported; skipped" in out["warnings"]


def test_check_explains_each_declared_effect_it_could_not_infer(tmp_path):
    import json

    from denoisebench.scenes import get_family

    stage = get_family("cornell").author(str(tmp_path / "c"), seed=0, frames=1)
    result = run_cli("scenes", "check", stage)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout)
    assert "indirect" in out["effects_declared"] and "indirect" not in out["effects_inferred"]
    assert "declared only" in out["effects_explained"]["indirect"]
    assert set(out["effects_explained"]) == set(out["effects_declared"]) ^ set(out["effects_inferred"])
