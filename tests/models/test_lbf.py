"""LBF (Kalantari et al. 2015): the cross-bilateral filter against direct computations, its
stability guarantees, end-to-end gradients into the MLP, and training through `denoisebench train`."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from torch.nn import functional as F

from denoisebench.cli import main
from denoisebench.dataset.frame import Frame
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.synthetic import synthetic_frame
from denoisebench.metrics.ours.spatial import relmse
from denoisebench.models import lbf
from denoisebench.models.catalog import build_model
from denoisebench.models.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint
from denoisebench.models.features import normalize_radiance
from denoisebench.models.lbf import spread_variance
from denoisebench.models.losses import relmse_loss

torch.set_num_threads(1)


def batch(n=2, h=12, w=14, seed=0, scale=1.0):
    g = torch.Generator().manual_seed(seed)
    return {
        "color": scale * torch.rand(n, 3, h, w, generator=g),
        "color_var": 0.01 * torch.rand(n, 3, h, w, generator=g),
        "albedo": torch.rand(n, 3, h, w, generator=g),
        "normal": F.normalize(torch.randn(n, 3, h, w, generator=g), dim=1),
        "depth": 1.0 + torch.rand(n, 1, h, w, generator=g),
    }


def direct_filter(primary, precisions, radius):
    """The lecture's d_ij summed pixel by pixel (float64), to check the vectorised filter against."""
    p = {k: v.double() for k, v in primary.items()}
    prec = precisions.double()
    n, _, h, w = p["color"].shape
    out = torch.zeros_like(p["color"])
    clamp = lambda v, hi: min(max(v, 0), hi - 1)  # noqa: E731 - replicated borders
    for b in range(n):
        for y in range(h):
            for x in range(w):
                num, den = torch.zeros(3, dtype=torch.float64), 0.0
                for dy in range(-radius, radius + 1):
                    for dx in range(-radius, radius + 1):
                        yy, xx = clamp(y + dy, h), clamp(x + dx, w)
                        dc = ((p["log_color"][b, :, y, x] - p["log_color"][b, :, yy, xx]) ** 2).sum()
                        dc = dc / (
                            lbf.COLOR_VAR_EPS + p["log_color_var"][b, 0, y, x] + p["log_color_var"][b, 0, yy, xx]
                        )
                        e = prec[b, 0, y, x] * (dy * dy + dx * dx) + prec[b, 1, y, x] * dc
                        for k, name in enumerate(lbf.FEATURES):
                            e = e + prec[b, 2 + k, y, x] * ((p[name][b, :, y, x] - p[name][b, :, yy, xx]) ** 2).sum()
                        weight = math.exp(-float(e))
                        num += weight * p["color"][b, :, yy, xx]
                        den += weight
                out[b, :, y, x] = num / den
    return out


def test_filter_matches_the_formula_pixel_by_pixel():
    buffers, _ = normalize_radiance(batch(n=1, h=6, w=7, seed=1))
    primary = lbf.primary_features(buffers)
    g = torch.Generator().manual_seed(2)
    precisions = 2.0 * torch.rand(1, 2 + len(lbf.FEATURES), 6, 7, generator=g)
    ours = lbf.filter_image(primary, precisions, radius=2)
    np.testing.assert_allclose(
        ours.double().numpy(), direct_filter(primary, precisions, 2).numpy(), rtol=1e-5, atol=1e-6
    )


def test_limits_identity_and_box_filter():
    buffers, _ = normalize_radiance(batch(n=1, h=9, w=10, seed=3))
    primary = lbf.primary_features(buffers)
    shape = (1, 2 + len(lbf.FEATURES), 9, 10)
    # huge spatial precision: only the centre pixel keeps weight → the input itself
    sharp = torch.zeros(shape)
    sharp[:, 0] = 1e4
    torch.testing.assert_close(lbf.filter_image(primary, sharp, 2), primary["color"])
    # zero precisions: every weight 1 → the 5×5 box mean over replicated borders
    box = F.avg_pool2d(F.pad(primary["color"], (2, 2, 2, 2), mode="replicate"), 5, stride=1)
    torch.testing.assert_close(lbf.filter_image(primary, torch.zeros(shape), 2), box, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("size", [(1, 1), (2, 3), (13, 17)])
def test_any_size_convex_output_and_positive_bandwidths(size):
    torch.manual_seed(0)
    net = build_model("lbf", "small").eval()
    b = batch(n=1, h=size[0], w=size[1], seed=4, scale=5.0)
    with torch.no_grad():
        out = net(b)["color"]
        bandwidths = net.bandwidths(b)
    assert out.shape == (1, 3, *size) and torch.isfinite(out).all()
    assert torch.isfinite(bandwidths).all() and (bandwidths > 0).all()
    # a convex combination of the (firefly-clamped) inputs: never beyond their range
    assert float(out.min()) >= 0.0 and float(out.max()) <= float(b["color"].max()) * (1 + 1e-5)


def test_hard_inputs_give_finite_outputs_losses_and_gradients():
    torch.manual_seed(0)
    net = build_model("lbf", "small")
    fire = batch(seed=5)
    fire["color"][:, :, 3, 5] = 1e6
    nan = batch(seed=6)
    nan["color"][:, 0, 2, 2] = float("nan")
    nan["normal"][:, 1, 4, 4] = float("inf")
    nan["depth"][:, 0, 1, 1] = float("-inf")
    black = {k: torch.zeros_like(v) for k, v in batch(seed=7).items()}
    tiny = batch(seed=8, scale=1e-6)
    huge = batch(seed=9, scale=1e6)
    for case, b in {"fireflies": fire, "nan_inf": nan, "black": black, "tiny": tiny, "huge": huge}.items():
        net.zero_grad()
        out = net(b)["color"]
        assert torch.isfinite(out).all(), case
        loss = relmse_loss(out, torch.nan_to_num(b["color"], nan=0.0, posinf=0.0, neginf=0.0))
        assert torch.isfinite(loss), case
        loss.backward()
        for param in net.parameters():
            assert torch.isfinite(param.grad).all(), case
    with torch.no_grad():
        assert float(net(black)["color"].abs().max()) == 0.0  # black stays exactly black


def test_training_end_to_end_reaches_the_mlp_and_lowers_the_loss():
    """The filter is differentiable: the MLP's first layer gets gradient, and Adam steps on a
    denoising toy task (smooth reference, multiplicative noise) lower the relative MSE."""
    torch.manual_seed(0)
    net = build_model("lbf", "small")
    y, x = torch.meshgrid(torch.arange(24.0), torch.arange(24.0), indexing="ij")
    ref = (0.5 + 0.3 * torch.sin(0.3 * x) * torch.cos(0.25 * y)).expand(2, 3, 24, 24).contiguous()
    b = batch(n=2, h=24, w=24, seed=10)
    b["color"] = ref * (0.25 + 1.5 * b["color"])
    b["color_var"] = torch.full_like(ref, 0.05)
    b["albedo"] = torch.ones_like(ref)
    optimizer = torch.optim.Adam(net.parameters(), lr=0.05)
    losses = []
    for step in range(8):
        optimizer.zero_grad()
        loss = relmse_loss(net(b)["color"], ref)
        loss.backward()
        if step == 0:
            assert float(net.mlp[0].weight.grad.abs().sum()) > 0.0
        optimizer.step()
        losses.append(float(loss.detach()))
    assert losses[-1] < 0.9 * losses[0], losses


def test_checkpoint_round_trip(tmp_path):
    torch.manual_seed(1)
    net = build_model("lbf", "small").eval()
    path = save_checkpoint(tmp_path / "lbf.pt", "lbf", lbf.CONFIGS["small"], net, {"steps": 0})
    again = model_from_checkpoint(load_checkpoint(path, expect_model="lbf")).eval()
    b = batch(n=1, seed=11)
    with torch.no_grad():
        torch.testing.assert_close(again(b)["color"], net(b)["color"], rtol=0, atol=0)


def test_paper_configuration_builds_with_its_window():
    net = build_model("lbf", "paper")
    assert net.radius == 27 and net.mlp[0].in_channels == lbf.input_channels(lbf.CONFIGS["paper"]["blocks"])


def test_train_lbf_uses_the_relmse_recipe(tmp_path):
    data = make_synthetic_dataset(tmp_path / "data", scenes=4, frames=1, height=16, width=16, spp=(2,))
    out = tmp_path / "lbf.pt"
    assert (
        main(
            [
                "train",
                "--model",
                "lbf",
                "--data",
                str(data),
                "--steps",
                "3",
                "--out",
                str(out),
                "--batch-size",
                "2",
                "--crop",
                "12",
                "--quiet",
            ]
        )
        == 0
    )
    meta = load_checkpoint(out, expect_model="lbf")["meta"]
    assert meta["loss"] == "relmse" and meta["steps"] == 3 and meta["stages"][0]["loss"] == "relmse"
    assert 0.0 < meta["validation"]["relmse"] < float("inf")


def test_var_median_variant_is_finite_and_uses_the_median_variance():
    torch.manual_seed(0)
    plain = build_model("lbf", {"radius": 2, "hidden": [4], "blocks": [3]}).eval()
    torch.manual_seed(0)
    median = build_model("lbf", {"radius": 2, "hidden": [4], "blocks": [3], "var_median": True}).eval()
    b = batch(n=1, h=9, w=9, seed=12)
    b["color_var"][:, :, 4, 4] = 1e6  # one wild variance estimate: the median ignores it
    with torch.no_grad():
        out_plain, out_median = plain(b)["color"], median(b)["color"]
    assert torch.isfinite(out_median).all()
    assert not torch.equal(out_plain, out_median)


def test_demodulate_variant_keeps_texture_and_black():
    """Demodulated, a flat irradiance under a checker albedo filters to the checker itself."""
    torch.manual_seed(0)
    net = build_model("lbf", {"radius": 2, "hidden": [4], "blocks": [3], "demodulate": True}).eval()
    with torch.no_grad():
        net.mlp[-1].weight.zero_()
        net.mlp[-1].bias.fill_(-30.0)  # softplus ≈ 0: a plain 5×5 box filter
    checker = 0.2 + 0.6 * ((torch.arange(8)[:, None] + torch.arange(8)[None]) % 2).float()
    albedo = checker.expand(1, 3, 8, 8).contiguous()
    b = {"color": albedo * 2.0, "albedo": albedo, "color_var": torch.zeros(1, 3, 8, 8)}
    from denoisebench.models.features import ALBEDO_EPS

    factor = albedo + ALBEDO_EPS  # what the filter divides by and multiplies back
    irradiance = F.avg_pool2d(F.pad(b["color"] / factor, (2, 2, 2, 2), mode="replicate"), 5, stride=1)
    with torch.no_grad():
        out = net(b)["color"]
        torch.testing.assert_close(out, irradiance * factor, rtol=1e-4, atol=1e-6)
        assert float((out - b["color"]).abs().max()) < 0.02 * float(b["color"].max())  # the checker survives
        black = {k: torch.zeros_like(v) for k, v in b.items()}
        assert float(net(black)["color"].abs().max()) == 0.0


def test_inference_path_equals_the_differentiable_path():
    buffers, _ = normalize_radiance(batch(n=2, h=10, w=11, seed=13))
    primary = lbf.primary_features(buffers)
    g = torch.Generator().manual_seed(14)
    precisions = 3.0 * torch.rand(2, 2 + len(lbf.FEATURES), 10, 11, generator=g)
    with torch.no_grad():
        fast = lbf.filter_image(primary, precisions, 3)
    slow = lbf.filter_image(primary, precisions.clone().requires_grad_(True), 3)
    torch.testing.assert_close(fast, slow.detach(), rtol=1e-6, atol=1e-7)


def test_spread_variance_estimates_noise_and_ignores_a_firefly():
    """The 1-spp stand-in for ``color_var``: on flat Gaussian noise of σ 0.1 it reads the variance
    within 30% (measured 0.0088 against 0.01: the deviation from a 3×3 median is not quite the
    noise); a 1000× firefly does not raise its neighbours' estimate above 2× that."""
    g = torch.Generator().manual_seed(0)
    flat = 0.5 + 0.1 * torch.randn(1, 3, 64, 64, generator=g)
    level = float(spread_variance(flat).mean())
    assert 0.007 < level < 0.013
    spiked = flat.clone()
    spiked[0, :, 32, 32] = 1000.0
    assert float(spread_variance(spiked)[0, :, 30:35, 30:35].max()) < 2.0 * 0.013


def test_lbf_at_one_spp_estimates_the_variance_it_is_not_given():
    """At 1 spp ``color_var`` is all zero; the shipped lbf then reads a spatial estimate. Against the
    same frame with a negligible variance (what the MLP saw before: "noise-free"), it must filter far
    more: below 0.2× the input's relMSE and below the noise-free reading."""
    frame = synthetic_frame("textured", 48, 48, 1, seed=3, samples=False)
    assert not np.any(frame.buffers["color_var"] > 0)
    denoiser = load_denoiser("lbf")
    estimated = relmse(denoiser.denoise(frame), frame.reference)
    told_noise_free = Frame(
        buffers={**frame.buffers, "color_var": np.full_like(frame.buffers["color_var"], 1e-12)},
        spp=1,
        scene=frame.scene,
        index=frame.index,
        reference=frame.reference,
    )
    trusting = relmse(denoiser.denoise(told_noise_free), frame.reference)
    assert estimated < 0.2 * relmse(frame.color, frame.reference)
    assert estimated < trusting
