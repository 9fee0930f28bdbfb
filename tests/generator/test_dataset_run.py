"""generate-dataset into a folder that holds someone's files: refused, or with --force written beside them."""

from __future__ import annotations

import hashlib

from denoisebench.cli import main

TINY = ["--families", "cornell", "--frames", "1", "--width", "16", "--height", "16", "--spp", "1"]
TINY += ["--ref-spp", "16", "--ref-error", "0", "--quiet"]


def _tree(folder):
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
        for p in sorted(folder.rglob("*"))
    }


def _users_folder(tmp_path):
    out = tmp_path / "photos"
    (out / "2024").mkdir(parents=True)
    (out / "notes.txt").write_text("mine\n")
    (out / "2024" / "a.jpg").write_bytes(b"\xff\xd8 not really a jpeg")
    return out


def test_a_foreign_folder_is_refused_in_one_line(tmp_path, capsys):
    out = _users_folder(tmp_path)
    before = _tree(out)
    assert main(["generate", "--out", str(out), *TINY]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "not a denoisebench dataset" in err and "--force" in err
    assert _tree(out) == before  # nothing written


def test_force_writes_the_dataset_beside_the_users_files(tmp_path):
    out = _users_folder(tmp_path)
    before = _tree(out)
    assert main(["generate", "--out", str(out), *TINY, "--force"]) == 0
    after = _tree(out)
    assert {k: v for k, v in after.items() if k in before} == before  # every file of the user's, unchanged
    assert "dataset.json" in after and any(k.endswith(".exr") for k in after)
    assert main(["generate", "--out", str(out), *TINY]) == 0  # now a dataset: the same command resumes


def test_force_refuses_where_a_dataset_name_is_taken(tmp_path, capsys):
    out = _users_folder(tmp_path)
    (out / "cornell_000").mkdir()
    (out / "cornell_000" / "keep.txt").write_text("mine too\n")
    before = _tree(out)
    assert main(["generate", "--out", str(out), *TINY, "--force"]) == 2
    assert "cornell_000" in capsys.readouterr().err
    assert _tree(out) == before


def test_an_empty_folder_is_not_foreign(tmp_path):
    out = tmp_path / "empty"
    out.mkdir()
    assert main(["generate", "--out", str(out), *TINY]) == 0


def _animated_stage(folder, last: int):
    """The plain box with its camera dollying in over time codes 0..last (24 per second)."""
    from pxr import Usd, UsdGeom

    from tests.support.plain_stages import author_plain_box

    path = author_plain_box(folder / "shot.usda")
    stage = Usd.Stage.Open(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(last)
    stage.SetTimeCodesPerSecond(24)
    (op,) = UsdGeom.Xformable(stage.GetPrimAtPath("/Camera")).GetOrderedXformOps()
    op.GetAttr().Clear()
    for t in (0, last):
        op.Set((0.0, 0.0, 3.4 - 0.5 * t / last), t)
    stage.GetRootLayer().Save()
    return path


USD_TINY = ["--width", "8", "--height", "8", "--spp", "1", "--ref-spp", "4", "--ref-error", "0", "--quiet"]


def test_frames_takes_an_even_subsample_of_a_stages_own_time_codes(tmp_path):
    from denoisebench.dataset import open_dataset

    stage = _animated_stage(tmp_path / "src", last=99)
    out = tmp_path / "ds"
    assert main(["generate", "--out", str(out), "--usd", str(stage), "--frames", "3", *USD_TINY]) == 0
    info = open_dataset(out).scene("usd_shot")
    assert info.frame_count == 3
    selection = info.record["frame_selection"]
    expected = {"stage_time_codes": [0.0, 99.0], "stage_frames": 100, "frames": 3, "times": [0.0, 50.0, 99.0]}
    assert selection == expected
    assert open_dataset(out).config["stage_frames"] == 3
    poses = [open_dataset(out).record("usd_shot", 1, k)["camera_pose"] for k in range(3)]
    assert [round(pose[2][3], 4) for pose in poses] == [round(3.4 - 0.5 * t / 99, 4) for t in (0, 50, 99)]
    # a window, then 3 of its 11 codes
    windowed = tmp_path / "window"
    argv = ["generate", "--out", str(windowed), "--usd", str(stage), "--time-range", "10:20", "--frames", "3"]
    assert main([*argv, *USD_TINY]) == 0
    assert open_dataset(windowed).scene("usd_shot").record["frame_selection"]["times"] == [10.0, 15.0, 20.0]


def test_a_window_outside_the_stage_and_a_long_stage(tmp_path, capsys, monkeypatch):
    from denoisebench.generator import dataset_scenes

    stage = _animated_stage(tmp_path / "src", last=2)
    out = tmp_path / "ds"
    assert main(["generate", "--out", str(out), "--usd", str(stage), "--time-range", "50:60", *USD_TINY]) == 2
    assert "holds none of the stage's time codes" in capsys.readouterr().err and not out.exists()
    monkeypatch.setattr(dataset_scenes, "LONG_STAGE_FRAMES", 2)  # 3 time codes count as long here
    assert main(["generate", "--out", str(out), "--usd", str(stage), *USD_TINY]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note:")]
    assert notes == [
        "note: usd_shot renders all 3 time codes of its stage; --frames N takes N of them evenly, "
        "--time-range START:END a window"
    ]
