"""Registry: built-ins, module:attr and file.py:attr specs, entry points, one-line errors."""

from __future__ import annotations

import importlib.metadata
import sys
import textwrap

import numpy as np
import pytest

from denoisebench.denoisers import registry
from denoisebench.denoisers.protocol import Denoiser, describe
from denoisebench.denoisers.registry import (
    BUILTINS,
    DenoiserLoadError,
    UnknownDenoiserError,
    available_denoisers,
    load_denoiser,
)
from denoisebench.denoisers.synthetic import synthetic_frame
from denoisebench.errors import UserInputError

BASELINES = sorted(name for name, (target, _) in BUILTINS.items() if target.startswith("denoisebench.baselines."))
OTHERS = sorted(set(BUILTINS) - set(BASELINES))  # the learned models: their weights ship with them


@pytest.mark.parametrize("name", OTHERS)
def test_other_builtins_load_or_fail_with_one_line(name):
    try:
        denoiser = load_denoiser(name)
    except DenoiserLoadError as error:
        assert "\n" not in str(error) and name in str(error)
    else:
        assert describe(denoiser).name == name


@pytest.mark.parametrize("name", BASELINES)
def test_every_baseline_loads_and_follows_the_protocol(name):
    denoiser = load_denoiser(name)
    assert isinstance(denoiser, Denoiser)
    info = describe(denoiser)
    assert info.name == name  # presets carry their own name (cross_bilateral_fast, oidn_fast)
    assert info.needs and all(isinstance(need, str) for need in info.needs)


def test_unknown_name_is_a_one_line_user_error_listing_the_known():
    with pytest.raises(UnknownDenoiserError) as caught:
        load_denoiser("no_such_denoiser")
    message = str(caught.value)
    assert isinstance(caught.value, UserInputError)
    assert "\n" not in message and "no_such_denoiser" in message and "cross_bilateral" in message


@pytest.mark.parametrize(
    "spec", ["", "   ", "pkg:", ":Attr", "denoisebench.baselines.identity:Nope", "no_module_xyz:Thing"]
)
def test_malformed_or_missing_specs_are_unknown(spec):
    with pytest.raises(UnknownDenoiserError):
        load_denoiser(spec)


def test_module_attr_and_dotted_attr(tmp_path, monkeypatch):
    package = tmp_path / "my_plugin_pkg"
    package.mkdir()
    (package / "__init__.py").write_text(
        textwrap.dedent(
            """
            import numpy as np

            class Outer:
                class Halve:
                    name = "halve"
                    def __init__(self, factor=0.5):
                        self.factor = factor
                    def denoise(self, frame):
                        return (np.asarray(frame.color) * self.factor).astype(np.float32)

            def make(factor=0.25):
                return Outer.Halve(factor)

            ready = Outer.Halve(0.75)
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    frame = synthetic_frame("shapes", 8, 8, 2, seed=1, samples=False)
    cls = load_denoiser("my_plugin_pkg:Outer.Halve", factor=2.0)
    np.testing.assert_allclose(cls.denoise(frame), frame.color * 2.0, rtol=1e-6)
    factory = load_denoiser("my_plugin_pkg:make")
    assert factory.factor == 0.25
    ready = load_denoiser("my_plugin_pkg:ready")
    assert ready.factor == 0.75
    with pytest.raises(DenoiserLoadError, match="ready instance"):
        load_denoiser("my_plugin_pkg:ready", factor=1.0)
    monkeypatch.delitem(sys.modules, "my_plugin_pkg", raising=False)


def test_file_spec_and_missing_file(tmp_path):
    plugin = tmp_path / "plugin_file.py"
    plugin.write_text(
        "import numpy as np\nclass Zero:\n    def denoise(self, frame):\n        return np.zeros_like(frame.color)\n"
    )
    denoiser = load_denoiser(f"{plugin}:Zero")
    assert describe(denoiser).name == f"{plugin}:Zero"  # no name attribute: the spec names it
    with pytest.raises(UnknownDenoiserError, match="no such plugin file"):
        load_denoiser(f"{tmp_path / 'absent.py'}:Zero")


def test_plugin_that_fails_to_import_is_a_one_line_load_error(tmp_path):
    plugin = tmp_path / "broken_plugin.py"
    plugin.write_text("import numpy\nraise RuntimeError('native library missing\\nsecond line')\n")
    with pytest.raises(DenoiserLoadError) as caught:
        load_denoiser(f"{plugin}:Anything")
    assert str(caught.value).count("\n") == 0
    assert "RuntimeError: native library missing" in str(caught.value)
    # an import error *inside* an existing module is a load error, not "unknown"
    nested = tmp_path / "needs_missing_dep.py"
    nested.write_text("import definitely_not_installed_dep_xyz\n")
    with pytest.raises(DenoiserLoadError, match="definitely_not_installed_dep_xyz"):
        load_denoiser(f"{nested}:X")


def test_constructor_failures_and_non_denoisers_are_load_errors(tmp_path):
    with pytest.raises(DenoiserLoadError, match="unknown cross_bilateral preset"):
        load_denoiser("cross_bilateral", preset="ultra")
    # an option the constructor does not take is bad input (exit 2), not a load failure ("not run")
    with pytest.raises(registry.UnknownOptionError, match="has no option 'radius'") as caught:
        load_denoiser("identity", radius=3)
    assert not isinstance(caught.value, DenoiserLoadError)
    plugin = tmp_path / "not_a_denoiser.py"
    plugin.write_text("VALUE = 3\nclass NoDenoise:\n    pass\n")
    with pytest.raises(DenoiserLoadError, match="not a denoiser"):
        load_denoiser(f"{plugin}:VALUE")
    with pytest.raises(DenoiserLoadError, match="no callable denoise"):
        load_denoiser(f"{plugin}:NoDenoise")


def test_entry_points_are_found_and_builtins_win(monkeypatch):
    points = [
        importlib.metadata.EntryPoint(
            "fake_ep", "denoisebench.baselines.identity:Identity", registry.ENTRY_POINT_GROUP
        ),
        importlib.metadata.EntryPoint("identity", "no_such_module_xyz:Thing", registry.ENTRY_POINT_GROUP),
        importlib.metadata.EntryPoint("broken_ep", "no_such_module_xyz:Thing", registry.ENTRY_POINT_GROUP),
    ]
    monkeypatch.setattr(registry, "_entry_points", lambda: {p.name: p for p in points})
    assert "fake_ep" in available_denoisers() and available_denoisers()["identity"].startswith("built-in")
    assert load_denoiser("fake_ep").name == "identity"
    assert load_denoiser("identity").name == "identity"  # the built-in, not the broken entry point
    with pytest.raises(UserInputError) as caught:
        load_denoiser("broken_ep")
    assert "\n" not in str(caught.value) and "no_such_module_xyz" in str(caught.value)


def test_describe_reads_trained_scenes_and_refuses_a_bare_string():
    class Learned:
        trained_scenes = ["cornell_100", "glass_env_101"]

        def denoise(self, frame):
            return frame.color

    assert describe(Learned()).trained_scenes == frozenset({"cornell_100", "glass_env_101"})
    Learned.trained_scenes = "cornell_100"  # would be read as its letters
    with pytest.raises(TypeError, match="trained_scenes must be a collection of scene names"):
        describe(Learned())
    del Learned.trained_scenes
    assert describe(Learned()).trained_scenes == frozenset()
