"""`denoisebench train`: checkpoints with metadata, exact resume, one-line errors."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
import torch

from denoisebench.cli import main
from denoisebench.dataset.reader import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.models.checkpoint import load_checkpoint

SMALL = ["--batch-size", "2", "--crop", "16", "--quiet"]


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    # 5 scenes: 3 train, 1 val, 1 test (manifest.assign_splits).
    return make_synthetic_dataset(
        tmp_path_factory.mktemp("syn") / "data", scenes=5, frames=3, height=20, width=20, spp=(2,)
    )


def train(*args):
    return main(["train", *map(str, args), *SMALL])


@pytest.mark.parametrize("model", ["kpcn", "rae"])
def test_checkpoint_carries_metadata(model, data, tmp_path):
    out = tmp_path / f"{model}.pt"
    assert train("--model", model, "--data", data, "--steps", 3, "--out", out) == 0
    payload = load_checkpoint(out, expect_model=model)  # weights_only=True inside
    meta = payload["meta"]
    assert payload["config"]["kernel_size" if model == "kpcn" else "levels"]
    assert meta["steps"] == 3 and meta["dataset_hash"] == open_dataset(data).config_hash
    assert meta["train_scenes"] == open_dataset(data).split("train")
    val = meta["validation"]
    assert val["scenes"] == open_dataset(data).split("val") and val["frames"] > 0
    assert 0.0 < val["relmse"] < float("inf") and 0.0 < val["relmse_noisy"] < float("inf")
    if model == "rae":
        assert meta["sequence_length"] == 3  # the dataset's 3 frames cap the 7-frame default


def test_resume_continues_exactly(data, tmp_path):
    straight, split = tmp_path / "straight.pt", tmp_path / "split.pt"
    assert train("--model", "dpcn", "--data", data, "--steps", 4, "--out", straight) == 0
    assert train("--model", "dpcn", "--data", data, "--steps", 2, "--out", split) == 0
    assert train("--model", "dpcn", "--data", data, "--steps", 2, "--resume", split, "--out", split) == 0
    a, b = load_checkpoint(straight), load_checkpoint(split)
    assert b["meta"]["steps"] == 4
    for name, tensor in a["state_dict"].items():
        assert torch.equal(tensor, b["state_dict"][name]), name


def test_ship_writes_weights_and_a_card_that_replays_the_commands(data, tmp_path):
    ck, shipped = tmp_path / "ck.pt", tmp_path / "ship"
    shipped.mkdir()
    assert train("--model", "rae", "--data", data, "--steps", 1, "--out", ck) == 0
    assert train("--model", "rae", "--data", data, "--steps", 1, "--resume", ck, "--out", ck, "--threads", 2) == 0
    # --steps 0: validate and ship the checkpoint as it is (e.g. the one the val split chose)
    assert train("--model", "rae", "--data", data, "--steps", 0, "--resume", ck, "--out", ck, "--ship", shipped) == 0
    payload = load_checkpoint(shipped / "rae_small.pt", expect_model="rae")
    assert "optimizer" not in payload and payload["meta"]["steps"] == 2 and payload["meta"]["threads"] == [1, 2]
    card = (shipped / "rae_small.md").read_text()
    first, second, third = payload["meta"]["commands"]
    assert "--threads" not in first and second.endswith("--threads 2") and "--resume" in second
    assert all(c in card for c in (first, second, third)) and "1 and 2 CPU threads" in card
    # the machine is the one each stage ran on, as recorded, not a fixed phrase
    import os

    assert payload["meta"]["machines"] == [f"a {os.cpu_count()}-core machine, no GPU"] * 2
    assert f"CPU threads (see the commands) of a {os.cpu_count()}-core machine, no GPU" in card
    assert "shared 2-core" not in card
    assert "--steps 0" in third and "It adds no steps" in card
    # two stages: the --steps 0 command trained nothing and is no stage
    assert [(s["from_step"], s["steps"]) for s in payload["meta"]["stages"]] == [(0, 1), (1, 1)]
    assert "2. steps 1–2" in card and "3. steps" not in card
    test_scenes = open_dataset(data).split("test")
    assert f"test (held-out) scenes: {', '.join(test_scenes)}" in card
    for peer in ("identity", "cross_bilateral"):
        assert re.search(rf"against {peer}: relMSE [0-9.]+ vs [0-9.]+, ratio [0-9.]+ \([0-9.]+% (lower|HIGHER)\)", card)


def run_cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "denoisebench.cli", *map(str, args)], capture_output=True, text=True, timeout=300
    )


def test_bad_input_exits_2_with_one_line(data, tmp_path, capsys):
    ckpt = tmp_path / "d.pt"
    assert train("--model", "dpcn", "--data", data, "--steps", 1, "--out", ckpt) == 0
    (tmp_path / "junk.pt").write_bytes(b"junk")
    cases = [
        (["--model", "kpcn", "--data", data, "--resume", ckpt, "--out", tmp_path / "k.pt"], "not 'kpcn'"),
        (
            ["--model", "dpcn", "--data", data, "--resume", tmp_path / "junk.pt", "--out", tmp_path / "k.pt"],
            "not a loadable",
        ),
        (["--model", "dpcn", "--data", data, "--spp", "64", "--out", tmp_path / "k.pt"], "not rendered"),
    ]
    capsys.readouterr()
    for args, message in cases:
        assert main(["train", *map(str, args), "--steps", "1", "--quiet"]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "k.pt").exists()
    # And as a user runs it: a real process, no traceback.
    result = run_cli("train", "--model", "kpcn", "--data", tmp_path / "nowhere", "--steps", 1)
    assert result.returncode == 2 and "not a dataset folder" in result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_set_overrides_a_configuration_key_and_the_checkpoint_loads_as_trained(data, tmp_path, capsys):
    from denoisebench.models.checkpoint import model_from_checkpoint

    out = tmp_path / "direct.pt"
    assert train("--model", "rae", "--data", data, "--steps", 2, "--out", out, "--set", "residual=false") == 0
    payload = load_checkpoint(out, expect_model="rae")
    assert payload["config"]["residual"] is False
    assert model_from_checkpoint(payload).residual is False  # the ablation, not the shipped form
    assert "--set residual=false" in payload["meta"]["commands"][-1]
    # resuming continues the checkpoint's configuration; a --set that contradicts it is refused
    capsys.readouterr()
    assert train("--model", "rae", "--data", data, "--steps", 1, "--resume", out, "--out", out) == 0
    assert load_checkpoint(out)["config"]["residual"] is False
    assert (
        train("--model", "rae", "--data", data, "--steps", 1, "--resume", out, "--out", out, "--set", "residual=false")
        == 0
    )
    assert (
        train("--model", "rae", "--data", data, "--steps", 1, "--resume", out, "--out", out, "--set", "residual=true")
        == 2
    )
    assert "trained with config" in capsys.readouterr().err
    assert (
        train("--model", "rae", "--data", data, "--steps", 1, "--resume", out, "--out", out, "--config", "paper") == 2
    )
    assert "trained with config" in capsys.readouterr().err
    for bad, message in (
        (["--set", "no_such_key=1"], "not a rae configuration key"),
        (["--set", "residual"], "expects KEY=VALUE"),
        (["--set", "residual=3"], "expected a value like"),
    ):
        assert train("--model", "rae", "--data", data, "--steps", 1, "--out", tmp_path / "x.pt", *bad) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "x.pt").exists()


def test_steps_0_scores_shipped_weights_on_another_dataset_and_keeps_their_provenance(data, tmp_path, capsys):
    """Shipped weights (no optimiser state) cannot be trained further, but ``--steps 0`` scores them on
    another dataset: the card keeps the training run's data, scenes and validation, and adds the scoring
    dataset's command, hash and val figure, with the held-out table and intervals from its test split."""
    other = make_synthetic_dataset(tmp_path / "other", scenes=5, frames=3, height=20, width=20, spp=(2,), seed=9)
    ck, first, second = tmp_path / "ck.pt", tmp_path / "ship1", tmp_path / "ship2"
    first.mkdir(), second.mkdir()
    assert train("--model", "dpcn", "--data", data, "--steps", 2, "--out", ck, "--ship", first) == 0
    shipped = first / "dpcn_small.pt"
    capsys.readouterr()
    assert train("--model", "dpcn", "--data", other, "--steps", 1, "--resume", shipped, "--out", tmp_path / "x.pt") == 2
    assert "--steps 0 scores them" in capsys.readouterr().err and not (tmp_path / "x.pt").exists()
    rescored = tmp_path / "rescored.pt"
    assert (
        train(
            "--model", "dpcn", "--data", other, "--steps", 0, "--resume", shipped, "--out", rescored, "--ship", second
        )
        == 0
    )
    before, after = load_checkpoint(shipped)["meta"], load_checkpoint(second / "dpcn_small.pt")["meta"]
    for key in ("dataset_hash", "train_scenes", "val_scenes", "validation", "stages", "steps", "seconds"):
        assert after[key] == before[key], key
    assert after["evaluated_on"]["dataset_hash"] == open_dataset(other).config_hash != before["dataset_hash"]
    assert after["evaluated_on"]["validation"]["scenes"] == open_dataset(other).split("val")
    torch.testing.assert_close(
        load_checkpoint(second / "dpcn_small.pt")["state_dict"], load_checkpoint(shipped)["state_dict"]
    )
    card = (second / "dpcn_small.md").read_text()
    assert f"dataset config hash `{before['dataset_hash']}`" in card
    assert f"Scored on another dataset than the training one: config hash `{open_dataset(other).config_hash}`" in card
    assert f"test (held-out) scenes: {', '.join(open_dataset(other).split('test'))}" in card
    seen = sorted(set(open_dataset(other).split("test")) & set(before["train_scenes"]))  # synthetic names repeat
    assert (
        f"share a name (family and seed) with a training scene: {', '.join(seen)}."
        if seen
        else "None of its test scenes shares a name"
    ) in card
    assert after["commands"][-1] in card and "--steps 0" in after["commands"][-1]
    assert "not the one they were trained on" in card and "[95% CI" in card


def test_init_from_fine_tunes_on_another_dataset_and_the_card_lists_both_runs(data, tmp_path, capsys):
    """--resume continues a run on its own data only; --init-from fine-tunes weights (shipped ones too) on
    another dataset: the earlier run's data, commands and stages stay in ``earlier_runs`` and its card."""
    other = make_synthetic_dataset(tmp_path / "other", scenes=5, frames=3, height=20, width=20, spp=(2,), seed=9)
    ck, first, second = tmp_path / "ck.pt", tmp_path / "ship1", tmp_path / "ship2"
    first.mkdir(), second.mkdir()
    # weights of another shape than today's small configuration (as the first shipped dpcn_small.pt)
    assert (
        train("--model", "dpcn", "--data", data, "--steps", 2, "--out", ck, "--ship", first, "--set", "layers=3") == 0
    )
    shipped = first / "dpcn_small.pt"
    capsys.readouterr()
    refused = [
        (["--resume", ck, "--steps", 1], "--init-from fine-tunes the weights on this one"),  # another dataset
        (["--init-from", shipped, "--steps", 0], "give --steps >= 1"),
        (["--init-from", shipped, "--steps", 1, "--set", "layers=3"], "--set cannot change it"),
        (["--init-from", shipped, "--resume", ck, "--steps", 1], "give one"),
        (["--init-from", shipped, "--steps", 1, "--config", "paper"], "add --config small"),
    ]
    for extra, message in refused:
        assert train("--model", "dpcn", "--data", other, "--out", tmp_path / "x.pt", *extra) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "x.pt").exists()
    tuned = tmp_path / "tuned.pt"
    assert (
        train(
            "--model",
            "dpcn",
            "--data",
            other,
            "--init-from",
            shipped,
            "--steps",
            2,
            "--lr",
            "1e-4",
            "--loss",
            "relmse",
            "--out",
            tuned,
            "--ship",
            second,
        )
        == 0
    )
    before, after = load_checkpoint(shipped)["meta"], load_checkpoint(tuned)["meta"]
    assert after["steps"] == 4 and after["dataset_hash"] == open_dataset(other).config_hash != before["dataset_hash"]
    assert after["train_scenes"] == open_dataset(other).split("train")
    (run,) = after["earlier_runs"]
    assert run["dataset_hash"] == before["dataset_hash"] and run["train_scenes"] == before["train_scenes"]
    assert run["commands"] == before["commands"] and run["validation"] == before["validation"]
    assert [s["steps"] for s in run["stages"]] == [2] and run["stages"][0]["dataset_hash"] == before["dataset_hash"]
    (stage,) = after["stages"]
    assert (stage["from_step"], stage["steps"], stage["loss"], stage["dataset_hash"]) == (
        2,
        2,
        "relmse",
        after["dataset_hash"],
    )
    assert "--init-from" in after["commands"][-1] and len(after["commands"]) == 1
    assert not torch.equal(
        load_checkpoint(tuned)["state_dict"]["diffuse.0.weight"],
        load_checkpoint(shipped)["state_dict"]["diffuse.0.weight"],
    )
    card = (second / "dpcn_small.md").read_text()
    assert f"`{before['dataset_hash']}`" in card and f"dataset config hash `{after['dataset_hash']}`" in card
    assert before["commands"][0] in card and after["commands"][-1] in card
    assert card.index(before["commands"][0]) < card.index(after["commands"][-1])
    assert "`--init-from` keeps a checkpoint's shape" in card and "'layers': 3" in card
    assert "1. run 1, steps 0–2" in card and "2. run 2, steps 2–4" in card and "fine-tuned from run 1" in card
    seen = sorted(set(open_dataset(other).split("test")) & (set(before["train_scenes"]) | set(after["train_scenes"])))
    assert (
        f"share a name (family and seed) with a training scene: {', '.join(seen)}."
        if seen
        else "None of its test scenes shares a name"
    ) in card
    # and resuming the fine-tune on its own data continues it, earlier runs kept
    assert train("--model", "dpcn", "--data", other, "--resume", tuned, "--steps", 1, "--out", tuned) == 0
    again = load_checkpoint(tuned)["meta"]
    assert again["steps"] == 5 and again["earlier_runs"] == after["earlier_runs"] and len(again["stages"]) == 2


def test_init_from_on_the_same_dataset_lists_its_generate_command_once(data, tmp_path):
    ck, tuned, shipped = tmp_path / "ck.pt", tmp_path / "tuned.pt", tmp_path / "ship"
    shipped.mkdir()
    assert train("--model", "lbf", "--data", data, "--steps", 2, "--out", ck) == 0
    assert (
        train("--model", "lbf", "--data", data, "--init-from", ck, "--steps", 2, "--out", tuned, "--ship", shipped) == 0
    )
    card = (shipped / "lbf_small.md").read_text()
    block = card.split("```sh")[1].split("```")[0].strip().splitlines()
    assert [line.split()[0] for line in block] == [
        "#",
        "denoisebench",
        "denoisebench",
    ]  # synthetic data: no generate-dataset
    assert "--init-from" in block[2] and "1. run 1, steps 0–2" in card and "2. run 2, steps 2–4" in card
