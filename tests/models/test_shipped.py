"""The shipped small weights and their wrappers: small files, safe loading, model cards, the
hard-case suite (what check-plugin runs), tiling, and the recurrent state through the runner."""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch

from denoisebench.denoisers.hard_cases import check_denoiser
from denoisebench.denoisers.protocol import describe
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.runner import run_sequence
from denoisebench.denoisers.synthetic import synthetic_frame, synthetic_sequence
from denoisebench.models.checkpoint import load_checkpoint
from denoisebench.models.denoisers import WEIGHTS_DIR, shipped_weights

MODELS = ("dpcn", "kpcn", "rae", "lbf")
torch.set_num_threads(1)


@pytest.mark.parametrize("name", MODELS)
def test_weights_are_small_safe_and_documented(name):
    path = shipped_weights(name)
    assert path.stat().st_size < 2 * 2**20
    payload = load_checkpoint(path, expect_model=name)  # torch.load(weights_only=True)
    assert "optimizer" not in payload and payload["config_name"] == "small"
    meta = payload["meta"]
    assert meta["steps"] > 0 and len(meta["dataset_hash"]) == 64
    assert 0 < meta["validation"]["relmse"] < float("inf") and meta["validation"]["frames"] > 0
    card = (WEIGHTS_DIR / f"{name}_small.md").read_text()
    assert "denoisebench train" in card and "generate-dataset" in card
    assert meta["dataset_hash"] in card


#: (model, peer) pairs whose shipped small weights do not (yet) beat the peer on the held-out
#: scenes: the issue asks for a win; strict xfail turns green into a failure once they do.
#: lbf: the MLP-driven cross-bilateral filter, 16000 CPU steps on 40 scenes of 64 px (4000, then 6000
#: at lr 3e-4 and 6000 at 1e-4: val 0.0592 -> 0.0544 -> 0.0532, below cross_bilateral's 0.0574 on val),
#: is level with the hand-tuned cross_bilateral on the held-out scenes (0.0639 vs 0.0634, ratio 1.007,
#: CI 0.63–1.71): better at 2 and 4 spp (0.082 / 0.052 vs 0.091 / 0.059), worse at 8 (0.057 vs 0.040).
NOT_YET_BEATEN: set[tuple[str, str]] = {("lbf", "cross_bilateral")}


@pytest.mark.parametrize(
    "name, peer",
    [
        pytest.param(m, p, marks=pytest.mark.xfail((m, p) in NOT_YET_BEATEN, reason="not yet beaten", strict=True))
        for m in MODELS
        for p in ("identity", "cross_bilateral")
    ],
)
def test_card_reports_a_win_on_held_out_scenes(name, peer):
    card = (WEIGHTS_DIR / f"{name}_small.md").read_text()
    found = re.search(
        rf"against {peer}: relMSE ([0-9.]+) vs ([0-9.]+), ratio ([0-9.]+) \(([0-9.]+)% (lower|HIGHER)\)", card
    )
    assert found, f"no margin over {peer} in the card"
    ours, theirs, ratio = float(found.group(1)), float(found.group(2)), float(found.group(3))
    assert abs(ratio - ours / theirs) <= 6e-4 + 1e-3 * ratio  # the card prints 3 decimals
    assert found.group(5) == "lower" and ours < theirs


@pytest.mark.parametrize("name", MODELS)
def test_registry_builtin_and_hard_case_suite(name):
    denoiser = load_denoiser(name)
    info = describe(denoiser)
    assert info.name == name and info.temporal == (name == "rae")
    failures = [f"{r.case}: {r.reason}" for r in check_denoiser(denoiser) if not r.passed]
    assert not failures, failures


def test_tiled_pcn_matches_whole_frame():
    frame = synthetic_frame("glossy", width=45, height=38, spp=4, seed=3, samples=False)
    whole = load_denoiser("kpcn", tile=128).denoise(frame)
    tiled = load_denoiser("kpcn", tile=16).denoise(frame)
    np.testing.assert_allclose(tiled, whole, rtol=1e-4, atol=1e-6)


def test_rae_wrapper_carries_state_between_frames_and_resets():
    sequence = synthetic_sequence("shapes", width=24, height=24, spp=4, frames=2, seed=4)
    denoiser = load_denoiser("rae")
    in_order = run_sequence(denoiser, sequence)  # reset, frame 0, frame 1
    alone = run_sequence(denoiser, [sequence[1]])  # reset, frame 1 only
    assert all(r.ok for r in in_order + alone)
    assert np.abs(in_order[1].output - alone[0].output).max() > 1e-6
    again = run_sequence(denoiser, [sequence[1]])
    np.testing.assert_array_equal(again[0].output, alone[0].output)


def _half_black(frame, *, right_diffuse: float, right_specular: float):
    """The frame made a lit grey floor (albedo 0.4, noisy) on the left half and, on the right half,
    pixels of no albedo: a black glossy material (diffuse 0) or a background (diffuse constant)."""
    rng = np.random.default_rng(7)
    b = frame.buffers
    h, w = b["color"].shape[:2]
    right = np.zeros((h, w, 1), bool)
    right[:, w // 2 :] = True
    floor = 0.6 * rng.gamma(4.0, 0.25, (h, w, 3)).astype(np.float32)
    spec = right_specular * rng.gamma(4.0, 0.25, (h, w, 3)).astype(np.float32)
    b["albedo"] = np.where(right, 0.0, 0.4).astype(np.float32) * np.ones((h, w, 3), np.float32)
    b["diffuse"] = np.where(right, right_diffuse, floor).astype(np.float32)
    b["specular"] = np.where(right, spec, 0.0).astype(np.float32)
    b["color"] = b["diffuse"] + b["specular"]
    return right[..., 0]


@pytest.mark.parametrize("name", ["kpcn", "dpcn"])
def test_pixels_of_no_albedo_get_no_irradiance_from_lit_neighbours(name):
    # Mitsuba's bsdf_roughplastic_ggx (a black rough-plastic sphere on a grey floor): the shipped kpcn
    # painted the floor's demodulated irradiance onto the sphere at 15x the reference (relMSE 0.38 vs
    # the 4-spp input's 0.19) before pixels of no albedo were left out of the demodulated domain
    frame = synthetic_frame("glossy", width=48, height=32, spp=4, seed=3, samples=False)
    right = _half_black(frame, right_diffuse=0.0, right_specular=0.05)
    out = np.asarray(load_denoiser(name).denoise(frame))[..., :3]
    assert np.isfinite(out).all()
    # a black material's diffuse is 0: what is left is its specular (mean 0.05), near the floor too
    assert out[right].mean() < 0.1 and np.quantile(out[right], 0.99) < 0.25
    # a background (constant radiance 0.8 where nothing is hit) keeps its value beside the floor
    frame = synthetic_frame("glossy", width=48, height=32, spp=4, seed=3, samples=False)
    right = _half_black(frame, right_diffuse=0.8, right_specular=0.0)
    out = np.asarray(load_denoiser(name).denoise(frame))[..., :3]
    # (dpcn's direct specular head adds up to 0.17 of specular where there is none: its own bias)
    assert np.abs(out[right] - 0.8).max() < (0.08 if name == "kpcn" else 0.25)


def test_a_partly_covered_silhouette_does_not_paint_its_quotient_on_the_wall():
    # usd-wg's ambulance and Mitsuba's two-sided Cornell box at 64 px: a wall of low green and blue
    # albedo before a white background. A silhouette pixel the wall half covers has half its albedo
    # and half the background's radiance, so its demodulated green is ~6x the wall's, and the kernel
    # taps that reached it painted the wall (the worst pixels: 4.6 where the reference is 0.70)
    frame = synthetic_frame("glossy", width=48, height=32, spp=4, seed=3, samples=False)
    rng = np.random.default_rng(3)
    b = frame.buffers
    h, w = b["color"].shape[:2]
    wall = np.array([0.7, 0.15, 0.15], np.float32)
    albedo = np.zeros((h, w, 3), np.float32)
    albedo[:, : w // 2] = wall
    albedo[:, w // 2] = 0.5 * wall
    noise = rng.gamma(4.0, 0.25, (h, w, 3)).astype(np.float32)
    diffuse = np.where(albedo[..., :1] > 0, albedo * noise, 0.8).astype(np.float32)
    diffuse[:, w // 2] = 0.5 * wall * noise[:, w // 2] + 0.4
    b.update(albedo=albedo, diffuse=diffuse, specular=np.zeros_like(diffuse), color=diffuse.copy())
    out = np.asarray(load_denoiser("kpcn").denoise(frame))[..., :3]
    assert np.isfinite(out).all()
    # the wall's green and blue stay near their 0.15 beside the silhouette (whose own is 0.44)
    assert np.quantile(out[:, w // 2 - 3 : w // 2, 1:], 0.95) < 0.25
    assert np.abs(out[:, w // 2 + 1 :] - 0.8).max() < 0.08  # the background keeps its value


def _silhouette_frame(seed: int, cover: int):
    """A red wall (left) before a white background (right), rendered as four samples per pixel: a
    sample that misses the wall reads albedo 0, depth 0 and radiance 1. The column between them has
    ``cover`` of its four samples on the wall. Returns the frame (its buffers the samples' means and
    variances of the mean, as the renderer writes them) and the reference."""
    frame = synthetic_frame("glossy", width=48, height=32, spp=4, seed=seed, samples=False)
    rng = np.random.default_rng(seed)
    h, w = frame.buffers["color"].shape[:2]
    wall = np.array([0.49, 0.05, 0.05], np.float32)  # the two-sided Cornell box's red wall
    hit = np.zeros((4, h, w, 1), bool)
    hit[:, :, : w // 2] = True
    hit[:cover, :, w // 2] = True
    albedo = np.where(hit, wall, 0.0)
    radiance = np.where(hit, wall * rng.gamma(4.0, 0.25, (4, h, w, 1)), 1.0)
    depth = np.where(hit, 9.7 + 0.01 * rng.standard_normal((4, h, w, 1)), 0.0)

    def moments(samples):
        return samples.mean(0).astype(np.float32), (samples.var(0, ddof=1) / 4).astype(np.float32)

    b = frame.buffers
    b["albedo"], b["albedo_var"] = moments(albedo)
    b["depth"], b["depth_var"] = moments(depth)
    b["diffuse"], b["diffuse_var"] = moments(radiance)
    b["color"], b["color_var"] = b["diffuse"].copy(), b["diffuse_var"].copy()
    b["specular"], b["specular_var"] = np.zeros_like(b["color"]), np.zeros_like(b["color"])
    covered = hit.mean(0)
    return frame, (covered * wall + (1.0 - covered)).astype(np.float32)


def test_kpcn_filters_silhouettes_before_the_background_in_their_own_class():
    # Mitsuba's two-sided Cornell box at 4 spp: pixels the red wall covers by a quarter have albedo
    # 0.12 (above ALBEDO_TRUSTED) and the background's radiance, so their demodulated red is 7x the
    # wall's and the taps that reached it painted the wall (2.11 where the reference is 0.51).
    # features.partly_background finds them from the albedo's and depth's variances and the frame's
    # spp; without spp (the rule off) the same weights read the old way.
    from denoisebench.models.features import frame_tensors, to_image

    kpcn = load_denoiser("kpcn")
    ratios = []
    for seed in range(4):
        for cover in (1, 2):
            frame, ref = _silhouette_frame(seed, cover)
            w = ref.shape[1]
            new = np.asarray(kpcn.denoise(frame))
            with torch.no_grad():
                old = to_image(kpcn._run({k: v for k, v in frame_tensors(frame).items() if k != "spp"}))
            assert np.isfinite(new).all() and np.abs(new[:, w // 2 + 1 :] - 1.0).max() < 0.01  # background kept
            beside = slice(w // 2 - 3, w // 2)  # the wall's three columns next to the silhouette
            error = [float(((o - ref) ** 2 / (ref**2 + 0.01))[:, beside].mean()) for o in (new, old)]
            ratios.append(error[0] / error[1])
    assert max(ratios) < 0.9 and float(np.mean(ratios)) < 0.8, ratios


def test_kpcn_card_scores_third_party_scenes_and_words_them_by_their_intervals():
    # written by `train --ship --third-party` (study/card_scores.py): the words follow the paired intervals
    from denoisebench.study.card_scores import verdict

    card = (WEIGHTS_DIR / "kpcn_small.md").read_text()
    section = card.split("## Third-party scenes")[1].split("## Limits")[0]
    rows = [
        line.split("|")[1].strip() for line in section.splitlines() if line.startswith("| ") and "denoiser" not in line
    ]
    assert rows == ["kpcn", "noisy", "cross_bilateral", "oidn"]
    said = re.findall(r"(beats it|ties it|loses to it) by (\w+) \(([0-9.]+) \[([0-9.]+), ([0-9.]+)\]", section)
    assert len(said) == 3 * 2 * 2  # 1/4/16 spp × (noisy input, cross_bilateral) × (relmse_robust, flip)
    for words, _, value, low, high in said:
        assert float(low) <= float(value) <= float(high)
        expected = verdict({"value": float(value), "low": float(low), "high": float(high)})
        assert words == {"beats": "beats it", "ties": "ties it", "loses to": "loses to it"}[expected]
