"""A user's stage laid out as production assets are (layers, references and textures beside and
above its folder) is copied into the dataset with its paths rewritten, confined to the copy."""

from __future__ import annotations

import shutil

import pytest

from denoisebench.errors import UserInputError
from denoisebench.generator.dataset_scenes import check_confined, check_user_stage, copy_user_stage
from denoisebench.generator.usd.translate import translate_usd
from tests.support.plain_stages import author_plain_box


def _kit(root):
    """kit/asset/root.usda sublayers ../geo/box.usda and references kit/geo/ball.usda by an absolute path."""
    from pxr import Sdf, Usd, UsdGeom

    box = author_plain_box(root / "kit" / "geo" / "box.usda")
    ball = Usd.Stage.CreateNew(str(root / "kit" / "geo" / "ball.usda"))
    UsdGeom.Sphere.Define(ball, "/Ball").CreateRadiusAttr(0.2)
    ball.SetDefaultPrim(ball.GetPrimAtPath("/Ball"))
    ball.GetRootLayer().Save()
    (root / "kit" / "asset").mkdir(parents=True)
    stage = Usd.Stage.CreateNew(str(root / "kit" / "asset" / "root.usda"))
    stage.GetRootLayer().subLayerPaths.append("../geo/box.usda")
    extra = stage.DefinePrim("/Extra")
    extra.GetReferences().AddReference(Sdf.Reference(str((root / "kit" / "geo" / "ball.usda").resolve())))
    stage.GetRootLayer().Save()
    return root / "kit" / "asset" / "root.usda", box


def test_dependencies_outside_the_folder_are_copied_and_rewritten(tmp_path):
    path, box = _kit(tmp_path / "src")
    before = path.read_bytes(), box.read_bytes()
    original = translate_usd(path, strict=True)
    check_user_stage(path)  # no longer refused
    out = tmp_path / "dataset" / "usd_root"
    files = copy_user_stage(path, out)
    assert files == ("scene.usda", "files/geo/ball.usda", "files/geo/box.usda")
    text = (out / "scene.usda").read_text()
    assert "@./files/geo/box.usda@" in text and "@./files/geo/ball.usda@" in text
    assert str(tmp_path) not in text  # no absolute path survives
    assert (path.read_bytes(), box.read_bytes()) == before  # the user's files are untouched
    # the copy alone renders the same scene: moved elsewhere with the source gone
    moved = tmp_path / "elsewhere" / "usd_root"
    shutil.copytree(out, moved)
    shutil.rmtree(tmp_path / "src")
    copied = translate_usd(moved / "scene.usda", strict=True)
    assert sorted(s.name for s in copied.shapes) == sorted(s.name for s in original.shapes)
    assert len(copied.shapes) == len(original.shapes) >= 8  # the box's quads and spheres, and the ball
    check_confined(moved)


def test_a_self_contained_stage_is_copied_byte_for_byte(tmp_path):
    path = author_plain_box(tmp_path / "box" / "box.usda")
    files = copy_user_stage(path, tmp_path / "out")
    assert files == ("scene.usda",)
    from pxr import Sdf

    assert (tmp_path / "out" / "scene.usda").read_text() == Sdf.Layer.FindOrOpen(str(path)).ExportToString()


def test_a_copy_that_reaches_out_of_its_folder_is_refused(tmp_path):
    from pxr import Usd

    author_plain_box(tmp_path / "outside.usda")
    folder = tmp_path / "scene"
    folder.mkdir()
    stage = Usd.Stage.CreateNew(str(folder / "scene.usda"))
    stage.GetRootLayer().subLayerPaths.append("../outside.usda")  # a hostile dataset's stage
    stage.GetRootLayer().Save()
    with pytest.raises(UserInputError, match="outside its folder"):
        check_confined(folder)
