"""The config key ``stage_options`` (formerly ``usd_options``): old datasets still resume, untouched.

``generate-dataset`` records ``--camera``/``--auto-camera``/``--default-light`` under
``stage_options`` (they apply to ``--mitsuba`` files as well as ``--usd`` stages). A dataset written
before the rename carries ``usd_options`` and a config hash over that key: it must resume under its
own hash with nothing rendered again, and a legacy dataset made with *other* options must still be
refused. The legacy dataset is made from a new one by renaming the key back and re-hashing, which
is exactly what the code before the rename wrote (``dataset_config`` differed only in that key).
"""

from __future__ import annotations

import json

import pytest

from denoisebench.cli import main
from denoisebench.dataset.manifest import config_hash
from denoisebench.generator.dataset_run import (
    LEGACY_STAGE_OPTIONS_KEY,
    STAGE_OPTIONS_KEY,
    legacy_config,
    resumable_config,
)

BOX = """<scene version="3.0.0">
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
  <shape type="cube"><bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf></shape>
</scene>
"""


def _generate(source, out, *extra):
    args = ["generate", "--out", str(out), "--mitsuba", str(source), "--auto-camera", "--frames", "2"]
    args += ["--width", "16", "--height", "16", "--spp", "1", "--ref-spp", "4", "--ref-error", "0", "--quiet"]
    return main([*args, *extra])


def _to_legacy(out, **option_changes):
    """Rewrite ``out``'s manifest as the code before the rename would have written it."""
    path = out / "dataset.json"
    manifest = json.loads(path.read_text())
    config = legacy_config(manifest["config"])
    config[LEGACY_STAGE_OPTIONS_KEY].update(option_changes)
    manifest["config"], manifest["config_hash"] = config, config_hash(config)
    path.write_text(json.dumps(manifest, indent=1))
    return manifest["config_hash"]


def _exr_stamps(out):
    return {p.relative_to(out): (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(out.rglob("*.exr"))}


@pytest.fixture
def dataset(tmp_path):
    source = tmp_path / "src" / "box.xml"
    source.parent.mkdir()
    source.write_text(BOX)
    out = tmp_path / "ds"
    assert _generate(source, out) == 0
    return source, out


def test_new_datasets_record_stage_options(dataset):
    _, out = dataset
    config = json.loads((out / "dataset.json").read_text())["config"]
    assert config[STAGE_OPTIONS_KEY] == {"camera": None, "auto_camera": True, "default_light": False}
    assert LEGACY_STAGE_OPTIONS_KEY not in config
    assert resumable_config(out, config) == config  # a new dataset keeps the new spelling


def test_old_format_dataset_resumes_under_its_own_hash_without_rendering(dataset, capsys):
    source, out = dataset
    old_hash = _to_legacy(out)
    before = _exr_stamps(out)
    assert before  # frames and references were written
    capsys.readouterr()
    assert _generate(source, out) == 0
    captured = capsys.readouterr()
    assert "0 frame(s) rendered" in captured.out + captured.err
    manifest = json.loads((out / "dataset.json").read_text())
    assert manifest["config_hash"] == old_hash  # not re-keyed, not regenerated
    assert LEGACY_STAGE_OPTIONS_KEY in manifest["config"] and STAGE_OPTIONS_KEY not in manifest["config"]
    assert _exr_stamps(out) == before  # no file rewritten


def test_old_format_dataset_with_other_options_is_still_refused(dataset, capsys):
    source, out = dataset
    _to_legacy(out, default_light=True)  # made with --default-light; this run does not ask for it
    capsys.readouterr()
    assert _generate(source, out) == 2
    assert "different config" in capsys.readouterr().err
