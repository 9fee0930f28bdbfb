"""Scene list files: what a list may say, and the one-line refusals."""

from __future__ import annotations

import pytest

from denoisebench.errors import UserInputError
from denoisebench.generator.scene_lists import SHIPPED, read_scene_list, request_fields

HEAD = 'name = "t"\nrepository = "https://example.invalid/repo"\n'


def _write(tmp_path, text):
    path = tmp_path / "list.toml"
    path.write_text(HEAD + text)
    return path


def _scene(source="mitsuba", path="a.xml", extra=""):
    return f'[[scene]]\nsource = "{source}"\npath = "{path}"\n{extra}\n'


def test_shipped_lists_parse_and_name_their_repository():
    names = sorted(p.stem for p in SHIPPED.glob("*.toml"))
    assert names == ["mitsuba_docs", "mitsuba_tests", "usd_wg_assets"]
    repos = {name: read_scene_list(name).repository for name in names}
    assert repos["usd_wg_assets"] == "https://github.com/usd-wg/assets"
    assert repos["mitsuba_docs"] == repos["mitsuba_tests"] == "https://github.com/mitsuba-renderer/mitsuba-data"
    usd = read_scene_list("usd_wg_assets")
    assert {s.source for s in usd.scenes} == {"usd"} and all(s.licence for s in usd.scenes)
    assert any("ambulanceFullAsset.usda" in s.path for s in usd.scenes)  # a production asset layout


def test_fields_merge_scenes_and_defines(tmp_path):
    root = tmp_path / "root"
    (root / "x").mkdir(parents=True)
    for name in ("a.xml", "x/b.xml", "c.usda"):
        (root / name).write_text("")
    path = _write(
        tmp_path,
        'camera = "own"\n'
        + _scene(extra='defines = { spp = "4" }')
        + _scene(path="x/b.xml", extra='defines = { spp = "4", res = "8" }')
        + _scene("usd", "c.usda"),
    )
    fields = request_fields(read_scene_list(path), root)
    assert fields["xml"] == (str(root / "a.xml"), str(root / "x/b.xml")) and fields["usd"] == (str(root / "c.usda"),)
    assert fields["defines"] == (("res", "8"), ("spp", "4")) and fields["auto_camera"] is False


@pytest.mark.parametrize(
    "text, message",
    [
        (_scene(path="../outside.xml"), "stay under it"),
        (_scene(path="/etc/passwd"), "stay under it"),
        (_scene(source="obj"), "is not one of"),
        (_scene(extra='camera = "fisheye"'), "orbit, own"),
        (_scene("usd", "c.usda", 'defines = { a = "1" }'), "mitsuba scenes only"),
        ("", r"no \[\[scene\]\] entries"),
        ("this is = = not toml", "not a TOML scene list"),
    ],
)
def test_malformed_lists_are_one_line(tmp_path, text, message):
    with pytest.raises(UserInputError, match=message) as info:
        read_scene_list(_write(tmp_path, text))
    assert "\n" not in str(info.value)


def test_what_one_run_cannot_do_is_refused(tmp_path):
    root = tmp_path / "root"
    root.mkdir()
    (root / "a.xml").write_text("")
    (root / "b.xml").write_text("")
    mixed = _write(tmp_path, _scene() + _scene(path="b.xml", extra='camera = "own"'))
    with pytest.raises(UserInputError, match="split the list"):
        request_fields(read_scene_list(mixed), root)
    clash = _write(
        tmp_path, _scene(extra='defines = { r = "1" }') + _scene(path="b.xml", extra='defines = { r = "2" }')
    )
    with pytest.raises(UserInputError, match=r"\$r is given two values"):
        request_fields(read_scene_list(clash), root)
    with pytest.raises(UserInputError, match="git clone https://example.invalid/repo"):
        request_fields(read_scene_list(_write(tmp_path, _scene(path="missing.xml"))), root)
    with pytest.raises(UserInputError, match="clone https://example.invalid/repo"):
        request_fields(read_scene_list(_write(tmp_path, _scene())), tmp_path / "nowhere")
