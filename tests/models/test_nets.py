"""DPCN, KPCN and the recurrent autoencoder: kernels, recurrence, sizes, stability, losses, checkpoints."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from denoisebench.models import pcn
from denoisebench.models.catalog import build_model, model_config
from denoisebench.models.checkpoint import CheckpointError, load_checkpoint, model_from_checkpoint, save_checkpoint
from denoisebench.models.losses import frame_weights, laplacian_of_gaussian, pcn_loss, rae_sequence_loss, relmse

MODELS = ("dpcn", "kpcn", "rae")
torch.set_num_threads(1)


def batch(n=2, h=16, w=16, seed=0, scale=1.0):
    g = torch.Generator().manual_seed(seed)
    color = scale * torch.rand(n, 3, h, w, generator=g)
    diffuse = 0.7 * color
    return {
        "color": color,
        "color_var": 0.01 * torch.rand(n, 3, h, w, generator=g),
        "diffuse": diffuse,
        "specular": color - diffuse,
        "albedo": torch.rand(n, 3, h, w, generator=g),
        "normal": torch.nn.functional.normalize(torch.randn(n, 3, h, w, generator=g), dim=1),
        "depth": 1.0 + torch.rand(n, 1, h, w, generator=g),
        "roughness": torch.rand(n, 1, h, w, generator=g),
        "reference": color.clone(),
        "reference_diffuse": diffuse.clone(),
        "reference_specular": (color - diffuse).clone(),
    }


def model(name, seed=0):
    torch.manual_seed(seed)
    return build_model(name, "small")


def loss_of(name, net, b, kind="log"):
    if name == "rae":
        net.reset()
        preds = [net(b)["color"], net(b)["color"]]
        net.reset()
        return rae_sequence_loss(preds, [b["reference"], b["reference"]], kind)["loss"]
    return pcn_loss(net(b), b, kind)["loss"]


# ------------------------------------------------------------------------------------------ KPCN


def test_kpcn_kernels_are_non_negative_and_sum_to_one():
    out = model("kpcn")(batch(h=13, w=11))
    kernels = out["kernels"]
    assert kernels.shape == (2, 2, 441, 13, 11)
    assert float(kernels.detach().min()) >= 0.0
    torch.testing.assert_close(kernels.detach().sum(dim=2), torch.ones(2, 2, 13, 11), atol=1e-5, rtol=0)


def test_softmax_kernels_never_overflow():
    logits = torch.tensor([1e30, -1e30, float("inf"), float("-inf"), float("nan"), 88.0, 1e4, 0.0])
    logits = logits.view(1, 8, 1, 1).repeat(1, 1, 2, 2)
    kernels = pcn.softmax_kernels(logits)
    assert torch.isfinite(kernels).all() and float(kernels.min()) >= 0.0
    torch.testing.assert_close(kernels.sum(dim=1), torch.ones(1, 2, 2))
    # And end to end on inputs spanning 1e-6..1e6 (and a firefly far beyond).
    b = batch(h=9, w=9, scale=1e6)
    b["color"][0, :, 4, 4] = 1e30
    out = model("kpcn")(b)
    assert torch.isfinite(out["kernels"]).all() and torch.isfinite(out["color"]).all()


def test_apply_kernels_matches_a_direct_loop_and_bands_agree(monkeypatch):
    rng = np.random.default_rng(3)
    noisy = rng.random((1, 2, 7, 6)).astype(np.float32)
    weights = rng.random((1, 9, 7, 6)).astype(np.float32)
    expected = np.zeros_like(noisy)
    padded = np.pad(noisy, ((0, 0), (0, 0), (1, 1), (1, 1)), mode="edge")  # numpy peer of replicate padding
    for y in range(7):
        for x in range(6):
            window = padded[0, :, y : y + 3, x : x + 3].reshape(2, 9)
            expected[0, :, y, x] = window @ weights[0, :, y, x]
    got = pcn.apply_kernels(torch.from_numpy(noisy), torch.from_numpy(weights), 3).numpy()  # shifted views
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)
    # the unfold path (taken while autograd records), whole and one row per band
    grad_weights = torch.from_numpy(weights).requires_grad_()
    unfolded = pcn.apply_kernels(torch.from_numpy(noisy), grad_weights, 3)
    unfolded.sum().backward()
    np.testing.assert_allclose(unfolded.detach().numpy(), got, rtol=1e-6, atol=1e-7)
    assert grad_weights.grad is not None and torch.isfinite(grad_weights.grad).all()
    monkeypatch.setattr(pcn, "UNFOLD_BYTES", 1)
    banded = pcn.apply_kernels(torch.from_numpy(noisy), torch.from_numpy(weights).requires_grad_(), 3).detach().numpy()
    np.testing.assert_allclose(banded, got, rtol=1e-6, atol=1e-7)


# ------------------------------------------------------------------------------------------ RAE


def test_rae_output_depends_on_previous_frame_until_reset():
    net = model("rae").eval()
    with torch.no_grad():  # the residual head starts at zero (see the next test): give it weights
        torch.nn.init.normal_(net.output.weight, std=0.1)
    first, second = batch(n=1, seed=1), batch(n=1, seed=2)
    with torch.no_grad():
        fresh = net(second)["color"]
        net(first)
        after_first = net(second)["color"]
        net.reset()
        after_reset = net(second)["color"]
    assert float((after_first - fresh).abs().max()) > 1e-6
    assert torch.equal(after_reset, fresh)


def test_residual_rae_starts_as_the_identity_and_keeps_colours():
    """The shipped configuration corrects the input's own log colour: untrained, it returns its
    input (a saturated green it never saw stays green); the direct form starts at grey."""
    y, x = torch.meshgrid(torch.linspace(0, 1, 12), torch.linspace(0, 1, 10), indexing="ij")
    b = batch(n=1, h=12, w=10)
    b["color"] = torch.stack([0.05 + 0.1 * x, 0.5 + y, 0.02 * torch.ones_like(x)])[None]
    assert model_config("rae", "small")["residual"] is True
    with torch.no_grad():
        out = model("rae").eval()(b)["color"]
        direct = build_model("rae", {**model_config("rae", "small"), "residual": False}).eval()(b)["color"]
    torch.testing.assert_close(out, b["color"], rtol=1e-5, atol=1e-6)
    assert float((direct - b["color"]).abs().max()) > 0.1


# ------------------------------------------------------------------------------------------ sizes, stability


@pytest.mark.parametrize("name", MODELS)
@pytest.mark.parametrize("size", [(1, 1), (3, 5), (17, 23)])
def test_any_image_size(name, size):
    net = model(name).eval()
    with torch.no_grad():
        out = net(batch(n=1, h=size[0], w=size[1]))["color"]
    assert out.shape == (1, 3, *size) and torch.isfinite(out).all()


def hard_batches():
    fire = batch(seed=4)
    fire["color"][:, :, 3, 5] = 1e6
    fire["diffuse"][:, :, 3, 5] = 1e6
    zero_albedo = batch(seed=5)
    zero_albedo["albedo"] = torch.zeros_like(zero_albedo["albedo"])
    black = {name: torch.zeros_like(value) for name, value in batch(seed=6).items()}
    nan = batch(seed=7)
    nan["color"][:, 0, 2, 2] = float("nan")
    nan["normal"][:, 1, 4, 4] = float("inf")
    return {"fireflies": fire, "zero_albedo": zero_albedo, "black": black, "nan_inf": nan}


@pytest.mark.parametrize("name", MODELS)
def test_loss_and_gradients_finite_on_hard_inputs(name):
    net = model(name)
    for kind in ("log", "relative"):
        for case, b in hard_batches().items():
            net.zero_grad()
            loss = loss_of(name, net, b, kind)
            assert torch.isfinite(loss), (name, case, kind)
            loss.backward()
            for param in net.parameters():
                assert torch.isfinite(param.grad).all(), (name, case, kind)


@pytest.mark.parametrize("name", MODELS)
def test_a_few_steps_lower_the_loss_on_a_tiny_batch(name):
    net = model(name)
    b = batch(n=2, h=16, w=16, seed=8)
    # A denoising task: a smooth reference, the noisy colour is it times mean-one noise.
    y, x = torch.meshgrid(torch.arange(16.0), torch.arange(16.0), indexing="ij")
    ref = (0.5 + 0.3 * torch.sin(0.4 * x) * torch.cos(0.3 * y)).expand(2, 3, 16, 16).contiguous()
    b.update(
        reference=ref, reference_diffuse=ref, reference_specular=torch.zeros_like(ref), albedo=torch.ones_like(ref)
    )
    b.update(color=ref * (0.5 + b["color"]), specular=torch.zeros_like(ref))
    b["diffuse"] = b["color"]
    if name == "rae":
        # The residual head starts as the identity, a few steps' gradient reaches only the head
        # and the identity is already near this toy task's optimum: start it too bright instead.
        with torch.no_grad():
            net.output.bias.fill_(0.3)
    if name == "dpcn":
        # The bounded output already gets this task's black specular lobe exactly (its noisy window
        # is black): start the diffuse branch too bright, so that there is something to learn.
        with torch.no_grad():
            net.diffuse[-1].bias.add_(0.3)
    optimizer = torch.optim.Adam(net.parameters(), lr={"dpcn": 5e-3, "kpcn": 5e-3, "rae": 5e-3}[name])
    losses = []
    for _ in range(5):
        optimizer.zero_grad()
        loss = loss_of(name, net, b)
        loss.backward()
        optimizer.step()
        losses.append(float(loss.detach()))
    with torch.no_grad():
        final = float(loss_of(name, net, b))
    assert final < 0.99 * losses[0], (losses, final)


@pytest.mark.parametrize("name", ("dpcn", "rae"))
def test_black_outputs_still_get_a_gradient_back_up(name):
    """Direct outputs below log 0 clamp to black; the clamp must not cut the gradient (a relative
    loss's first steps push dark pixels there, and a dead network then stays black for good)."""
    net = model(name)
    head = net.output if name == "rae" else net.diffuse[-1]
    with torch.no_grad():
        head.bias.fill_(-5.0)  # every pixel's log output well below 0: the image is black
        if name == "dpcn":
            net.specular[-1].bias.fill_(-5.0)
    b = batch(seed=3)
    b.update(albedo=torch.ones_like(b["color"]))
    with torch.no_grad():
        assert float(loss_of(name, net, b, "relative")) > 0
        before = net(b) if name != "rae" else (net.reset(), net(b))[1]
    assert float(before["color"].max()) == 0.0
    net.zero_grad()
    loss_of(name, net, b, "relative").backward()
    assert float(head.bias.grad.sum()) < 0  # descent raises the bias, i.e. brightens the image


# ------------------------------------------------------------------------------------------ losses


def test_frame_weights_rise_and_sum_to_one():
    weights = frame_weights(7)
    assert torch.all(weights[1:] > weights[:-1])
    assert float(weights.sum()) == pytest.approx(1.0)
    assert float(weights[0] / weights[-1]) < 0.1


def test_laplacian_of_gaussian_matches_the_metric_kernel():
    from denoisebench.metrics.ours.gradient import laplacian_of_gaussian as metric_log

    image = np.random.default_rng(1).random((40, 40, 3)).astype(np.float32)
    ours = laplacian_of_gaussian(torch.from_numpy(image).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()
    theirs = metric_log(image)
    # Away from the border, where the two paddings differ, the responses agree.
    np.testing.assert_allclose(ours[8:-8, 8:-8], theirs[8:-8, 8:-8], rtol=1e-4, atol=1e-5)


def test_relmse_matches_the_metric():
    from denoisebench.metrics.ours.spatial import relmse as metric_relmse

    rng = np.random.default_rng(2)
    pred, ref = rng.random((8, 8, 3)).astype(np.float32) * 5, rng.random((8, 8, 3)).astype(np.float32)
    ours = relmse(torch.from_numpy(pred), torch.from_numpy(ref))
    assert ours == pytest.approx(metric_relmse(pred, ref), rel=1e-6)


# ------------------------------------------------------------------------------------------ checkpoints


@pytest.mark.parametrize("name", MODELS)
def test_checkpoint_round_trip_gives_identical_outputs(name, tmp_path):
    net = model(name, seed=11).eval()
    b = batch(n=1, h=12, w=12, seed=9)
    path = save_checkpoint(tmp_path / "m.pt", name, model_config(name, "small"), net, {"steps": 3})
    payload = load_checkpoint(path, expect_model=name)
    assert payload["meta"]["steps"] == 3
    again = model_from_checkpoint(payload).eval()
    with torch.no_grad():
        assert torch.equal(net(b)["color"], again(b)["color"])


def test_checkpoints_load_safely(tmp_path):
    class Evil:
        def __reduce__(self):
            return (print, ("pwned",))

    torch.save({"format": "denoisebench-checkpoint", "model": "kpcn", "x": Evil()}, tmp_path / "evil.pt")
    with pytest.raises(CheckpointError, match="not a loadable checkpoint"):
        load_checkpoint(tmp_path / "evil.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a zip")
    with pytest.raises(CheckpointError):
        load_checkpoint(tmp_path / "junk.pt")
    net = model("dpcn")
    save_checkpoint(tmp_path / "d.pt", "dpcn", pcn.DPCN_CONFIGS["small"], net, {})
    with pytest.raises(CheckpointError, match="not 'kpcn'"):
        load_checkpoint(tmp_path / "d.pt", expect_model="kpcn")


# ------------------------------------------------------------------------------------------ exposure, fireflies


def test_clamp_isolated_matches_the_oidn_wrapper():
    from denoisebench.baselines.oidn import FIREFLY_FACTOR
    from denoisebench.baselines.oidn import clamp_isolated as numpy_clamp
    from denoisebench.models.features import FIREFLY_FACTOR as OURS
    from denoisebench.models.features import clamp_isolated

    assert OURS == FIREFLY_FACTOR
    image = np.random.default_rng(5).random((11, 13, 3)).astype(np.float32)
    image[4, 6, 1] = 1e6
    image[0, 0, 0] = 5e3  # a corner: edges replicate
    expected = numpy_clamp(image, FIREFLY_FACTOR)
    got = clamp_isolated(torch.from_numpy(image).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(got, expected, rtol=1e-6)
    assert got[4, 6, 1] < 20


@pytest.mark.parametrize("name", MODELS)
def test_output_scales_with_exposure_and_black_stays_black(name):
    net = model(name).eval()
    b = batch(n=1, h=12, w=12, seed=12)
    with torch.no_grad():
        base = net(b)["color"]
        for k in (1e-6, 1e6):
            if name == "rae":
                net.reset()
            scaled = dict(
                b,
                color=k * b["color"],
                diffuse=k * b["diffuse"],
                specular=k * b["specular"],
                color_var=k * k * b["color_var"],
            )
            torch.testing.assert_close(net(scaled)["color"], k * base, rtol=1e-3, atol=0)
        if name == "rae":
            net.reset()
        black = net({key: torch.zeros_like(v) for key, v in b.items()})["color"]
    assert torch.equal(black, torch.zeros_like(black))


def test_softmax_kernels_inference_path_equals_the_autograd_path():
    """Under no_grad the clean-up and softmax run in place: same kernels, NaN/±Inf/huge logits included."""
    logits = torch.randn(2, 9, 5, 4) * 30.0
    logits[0, 3, 1, 1] = float("nan")
    logits[0, :, 2, 2] = float("inf")
    logits[1, 4, 0, 0] = float("-inf")
    logits[1, :, 3, 3] = 1e30
    tracked = pcn.softmax_kernels(logits.clone().requires_grad_()).detach()
    with torch.no_grad():
        in_place = pcn.softmax_kernels(logits.clone())
    assert torch.isfinite(in_place).all() and (in_place >= 0).all()
    torch.testing.assert_close(in_place, tracked, rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(in_place.sum(dim=1), torch.ones(2, 5, 4), rtol=1e-5, atol=1e-6)


def test_bounded_dpcn_stays_within_its_noisy_window():
    """``bound_output`` (the small and paper configurations): a DPCN head pushed to predict e^40 gives,
    unbounded, radiance at the 1e8 output clamp (what the failed full-transport runs did on a few pixels
    per frame); bounded, no pixel exceeds the brightest noisy value of its 21×21 window (albedo 1, so
    remodulation does not scale it), and a black specular lobe stays black."""
    b = batch(n=1, h=24, w=24, seed=5)
    b.update(albedo=torch.ones_like(b["color"]), specular=torch.zeros_like(b["color"]))
    b["diffuse"] = b["color"]
    outputs = {}
    for bound in (False, True):
        net = build_model("dpcn", {**model_config("dpcn", "small"), "bound_output": bound}).eval()
        with torch.no_grad():
            for branch in (net.diffuse, net.specular):
                branch[-1].bias.fill_(40.0)
            outputs[bound] = net(b)
    assert float(outputs[False]["color"].max()) > 1e6
    bounded = outputs[True]
    assert torch.isfinite(bounded["color"]).all()
    assert float(bounded["specular"].abs().max()) == 0.0
    assert float(bounded["color"].max()) <= float(b["color"].max()) * (1 + 1e-3)


def test_bounded_dpcn_passes_gradient_where_the_cap_binds():
    """Straight through: a head stuck far above the cap still learns to come down (a plain minimum gives
    zero gradient there, and such a head stays stuck), while the forward value is capped as at inference."""
    b = batch(n=1, h=16, w=16, seed=6)
    b["reference"] = b["color"] * 0.5
    net = build_model("dpcn", model_config("dpcn", "small"))
    with torch.no_grad():
        for branch in (net.diffuse, net.specular):
            branch[-1].bias.fill_(40.0)
    out = net(b)
    with torch.no_grad():
        capped = net.eval()(b)
    torch.testing.assert_close(out["color"], capped["color"])
    loss = pcn_loss(out, b, "exposure")["loss"]
    loss.backward()
    bias_grad = float(net.diffuse[-1].bias.grad.sum() + net.specular[-1].bias.grad.sum())
    assert math.isfinite(bias_grad) and bias_grad > 0  # descent lowers the head's output


def test_dpcn_log_offset_output_keeps_relative_precision_near_black():
    """``log_offset`` ε: the DPCN head reads as log(x + ε) of the normalised lobe, not log(1 + x). The same
    head error of 0.1 moves a pixel at 1% of the exposure by ~10% in log(x + ε) (ε = 0.01), by ~1000% in
    log(1 + x) (where it is an absolute error of 0.1); decoding is exact where the head is right, black
    stays black under the bound, and an untrained head starts at the exposure (normalised 1)."""
    b = batch(n=1, h=24, w=24, seed=8)
    b.update(albedo=torch.ones_like(b["color"]), specular=torch.zeros_like(b["color"]))
    b["diffuse"] = b["color"]
    net = build_model("dpcn", {**model_config("dpcn", "small"), "log_offset": 0.01}).eval()
    x = torch.tensor([0.0, 0.01, 1.0, 50.0])
    head = torch.log(x + 0.01)
    torch.testing.assert_close(net._from_offset_log(head), x, rtol=1e-5, atol=1e-7)
    dark = torch.tensor([0.01])
    offset_error = net._from_offset_log(torch.log(dark + 0.01) + 0.1) / dark - 1
    log1p_error = torch.expm1(torch.log1p(dark) + 0.1) / dark - 1
    assert 0.15 < float(offset_error) < 0.25 and float(log1p_error) > 10
    with torch.no_grad():
        out = net(b)
        scale = out["exposure"]
    assert float(out["specular"].abs().max()) == 0.0 and torch.isfinite(out["color"]).all()
    # untrained: the head's bias is log(1 + ε), i.e. normalised radiance 1 (the exposure)
    fresh = build_model("dpcn", {**model_config("dpcn", "small"), "log_offset": 0.01})
    assert float(fresh.diffuse[-1].bias.detach()[0]) == pytest.approx(math.log(1.01))
    with pytest.raises(ValueError, match="log_offset"):
        build_model("dpcn", {**model_config("dpcn", "small"), "log_offset": -1.0})
    assert float(scale.flatten()[0]) > 0


def _pixel_moments(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel mean and variance of the mean (unbiased sample variance ÷ n), as the renderer writes them."""
    n = samples.shape[0]
    return samples.mean(axis=0), samples.var(axis=0, ddof=1) / n


def test_partly_background_finds_silhouettes_and_not_texture_or_depth_edges():
    from denoisebench.models.features import covered_fraction, partly_background

    # four samples per pixel; a sample that misses every surface reads albedo 0 and depth 0
    surface_albedo, surface_depth = np.array([0.49, 0.05, 0.05]), 9.7
    pixels = {
        "silhouette": ([surface_albedo, 0 * surface_albedo, 0 * surface_albedo, 0 * surface_albedo], [9.7, 0, 0, 0]),
        "texture edge": ([[0.8] * 3, [0.8] * 3, [0.1] * 3, [0.1] * 3], [4.0, 4.0, 4.0, 4.0]),
        "depth edge": ([[0.5] * 3] * 4, [1.0, 1.0, 10.0, 10.0]),
        "black material before the background": ([[0.0] * 3] * 4, [3.0, 0.0, 0.0, 0.0]),
        "surface": ([surface_albedo] * 4, [surface_depth, surface_depth + 0.01, surface_depth - 0.01, surface_depth]),
    }
    albedo, depth = np.array([p[0] for p in pixels.values()], float), np.array([p[1] for p in pixels.values()], float)
    a_mean, a_var = _pixel_moments(np.moveaxis(albedo, 1, 0))  # samples first: 4 × P × 3
    d_mean, d_var = _pixel_moments(depth.T[..., None])

    def image(values):  # P × C → 1 × C × 1 × P
        return torch.tensor(values, dtype=torch.float32).T[None, :, None, :]

    buffers = {
        "albedo": image(a_mean),
        "albedo_var": image(a_var),
        "depth": image(d_mean),
        "depth_var": image(d_var),
        "spp": torch.full((1, 1, 1, 1), 4.0),
    }
    # the two-valued silhouette's coverage is exact: one sample in four hit the wall
    cover = covered_fraction(buffers["depth"], buffers["depth_var"], buffers["spp"])
    assert cover[0, 0, 0, 0].item() == pytest.approx(0.25, abs=1e-6)
    found = partly_background(buffers)[0, 0, 0].tolist()
    assert dict(zip(pixels, found)) == {
        "silhouette": True,
        "texture edge": False,
        "depth edge": False,
        "black material before the background": False,  # no albedo: a dark pixel, its own class
        "surface": False,
    }
    # one sample: no variance, no evidence; no spp: the rule is off
    assert not partly_background({**buffers, "spp": torch.ones(1, 1, 1, 1)}).any()
    assert partly_background({k: v for k, v in buffers.items() if k != "spp"}) is None
