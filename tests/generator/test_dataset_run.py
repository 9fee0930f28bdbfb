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
