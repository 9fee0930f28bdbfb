"""A plugin's code identity: a hash of the code it runs, found without running it."""

from __future__ import annotations

import sys

from denoisebench.denoisers.registry import denoiser_code_identity


def test_a_file_plugins_identity_follows_its_bytes(tmp_path):
    plugin = tmp_path / "mine.py"
    plugin.write_text("def denoise(frame):\n    return frame.color\n")
    first = denoiser_code_identity(f"{plugin}:denoise")
    assert first and denoiser_code_identity(f"{plugin}:denoise") == first  # stable
    plugin.write_text("def denoise(frame):\n    return frame.color * 1\n")
    assert denoiser_code_identity(f"{plugin}:denoise") not in (None, first)
    assert denoiser_code_identity(f"{plugin}:other") == denoiser_code_identity(f"{plugin}:denoise")  # the file's


def test_a_module_plugin_is_hashed_without_being_imported(tmp_path, monkeypatch):
    package = tmp_path / "pkg_h4_identity"
    package.mkdir()
    (package / "__init__.py").write_text("raise SystemExit('imported')\n")
    (package / "filters.py").write_text("def denoise(frame):\n    return frame.color\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    first = denoiser_code_identity("pkg_h4_identity.filters:denoise")
    assert first and "pkg_h4_identity" not in sys.modules
    (package / "helpers.py").write_text("SCALE = 2\n")  # a file the plugin may import: part of its code
    assert denoiser_code_identity("pkg_h4_identity.filters:denoise") != first


def test_built_ins_and_the_packages_own_modules_have_none():
    assert denoiser_code_identity("identity") is None
    assert denoiser_code_identity("denoisebench.baselines.identity:Identity") is None
    assert denoiser_code_identity("no_such_module_h4:denoise") is None
