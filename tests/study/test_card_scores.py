"""`train --ship --third-party`: the model card's third-party section, from the benchmark's own scores."""

from __future__ import annotations

import json

import pytest

from denoisebench.cli import main
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.study.card_scores import verdict


def test_verdict_words_follow_the_paired_interval():
    assert verdict({"value": 0.8, "low": 0.7, "high": 0.95}) == "beats"
    assert verdict({"value": 0.9, "low": 0.7, "high": 1.05}) == "ties"
    assert verdict({"value": 1.2, "low": 1.01, "high": 1.4}) == "loses to"
    assert verdict({"value": None, "low": None, "high": None}) == "cannot be compared with"


def test_ship_with_third_party_puts_their_scores_in_the_card(tmp_path, capsys):
    data = make_synthetic_dataset(tmp_path / "data", scenes=5, frames=2, height=16, width=16, spp=(2,))
    tp = make_synthetic_dataset(tmp_path / "tp", scenes=3, frames=2, height=16, width=16, spp=(1, 4), seed=7)
    ck, ship = tmp_path / "ck.pt", tmp_path / "ship"
    ship.mkdir()
    common = ["train", "--model", "kpcn", "--data", str(data), "--batch-size", "2", "--crop", "8", "--quiet"]
    common += ["--steps", "2", "--out", str(ck)]

    # refused before anything trains: no --ship to put the scores in, a folder that is no dataset, a scene twice
    assert main([*common, "--third-party", str(tp)]) == 2
    assert "--ship" in capsys.readouterr().err
    assert main([*common, "--ship", str(ship), "--third-party", str(tmp_path / "nope")]) == 2
    assert main([*common, "--ship", str(ship), "--third-party", str(tp), "--third-party", str(tp)]) == 2
    assert "synthetic_000 is also in" in capsys.readouterr().err
    assert not ck.exists()

    assert main([*common, "--ship", str(ship), "--third-party", str(tp)]) == 0
    card = (ship / "kpcn_small.md").read_text()
    assert card.index("## Held-out scenes") < card.index("## Third-party scenes") < card.index("## Limits")
    section = card.split("## Third-party scenes")[1].split("## Limits")[0]
    record = json.loads((tmp_path / "third_party_runs" / "kpcn_small.third_party.json").read_text())
    assert not (ship / "third_party_runs").exists()  # the runs stay beside the checkpoint, not with the weights
    assert record["spp"] == [1, 4] and len(record["kept"]) >= 1
    assert record["datasets"][0]["scenes"] == ["synthetic_000", "synthetic_001", "synthetic_002"]

    rows = {
        line.split("|")[1].strip(): line
        for line in section.splitlines()
        if line.startswith("| ") and not line.startswith("| denoiser")
    }
    assert set(rows) == {"kpcn", "noisy", "cross_bilateral", "oidn"}
    for label, line in rows.items():
        cells = [c.strip() for c in line.split("|")[2:-1]]
        expected = [
            record["scores"][str(spp)][label][metric]["value"] for metric in ("relmse_robust", "flip") for spp in (1, 4)
        ]
        assert [float(c.split(" [")[0]) for c in cells] == pytest.approx(expected, rel=1e-2)
    # relmse_robust is each scene's score ÷ the noisy input's: the input reads 1
    assert all(record["scores"][s]["noisy"]["relmse_robust"]["value"] == pytest.approx(1.0) for s in ("1", "4"))

    for spp in (1, 4):
        line = next(line for line in section.splitlines() if line.startswith(f"* {spp} spp, kpcn "))
        assert "against the noisy input:" in line and "against cross_bilateral:" in line
        words = [w for w in ("beats it", "ties it", "loses to it") if w in line]
        assert len(words) >= 1 and line.count(" by relmse_robust (") == 2 and line.count(" by flip (") == 2
