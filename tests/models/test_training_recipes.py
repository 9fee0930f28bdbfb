"""Training where the hardware is and as the papers train: --device, --threads, learning-rate
schedules, --val-every, loss recipes, the PCN configurations, the DPCN-vs-KPCN bench, bootstrap
intervals on cards, and splits stratified by family."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest
import torch

from denoisebench.cli import main
from denoisebench.dataset.manifest import assign_splits
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.models import pcn
from denoisebench.models.catalog import build_model
from denoisebench.models.checkpoint import load_checkpoint
from denoisebench.models.losses import pcn_loss, spatial_l1
from denoisebench.models.training_options import lr_factor, max_threads, resolve_device
from tests.support.paths import REPO

SMALL = ["--batch-size", "2", "--crop", "12", "--quiet"]
ROOT = REPO
torch.set_num_threads(1)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return make_synthetic_dataset(
        tmp_path_factory.mktemp("syn") / "data", scenes=4, frames=2, height=16, width=16, spp=(2,)
    )


# ------------------------------------------------------------------------------------------ device, threads


def test_device_auto_follows_torch_and_cuda_without_a_gpu_is_bad_input(data, tmp_path, capsys):
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert resolve_device("auto").type == expected and resolve_device("cpu").type == "cpu"
    out = tmp_path / "d.pt"
    assert (
        main(
            [
                "train",
                "--model",
                "dpcn",
                "--data",
                str(data),
                "--steps",
                "1",
                "--out",
                str(out),
                "--device",
                "cpu",
                *SMALL,
            ]
        )
        == 0
    )
    meta = load_checkpoint(out)["meta"]
    assert meta["devices"] == ["cpu"] and meta["stages"][0]["device"] == "cpu"
    if not torch.cuda.is_available():
        capsys.readouterr()
        assert (
            main(
                [
                    "train",
                    "--model",
                    "dpcn",
                    "--data",
                    str(data),
                    "--steps",
                    "1",
                    "--out",
                    str(out),
                    "--device",
                    "cuda",
                    *SMALL,
                ]
            )
            == 2
        )
        err = capsys.readouterr().err.strip()
        assert "no CUDA device" in err and len(err.splitlines()) == 1


def test_threads_up_to_the_core_count(data, tmp_path, capsys):
    out = tmp_path / "t.pt"
    capsys.readouterr()
    assert (
        main(
            [
                "train",
                "--model",
                "dpcn",
                "--data",
                str(data),
                "--steps",
                "1",
                "--out",
                str(out),
                "--threads",
                str(max_threads() + 1),
                *SMALL,
            ]
        )
        == 2
    )
    assert "core count" in capsys.readouterr().err
    assert (
        main(
            [
                "train",
                "--model",
                "dpcn",
                "--data",
                str(data),
                "--steps",
                "1",
                "--out",
                str(out),
                "--threads",
                str(max_threads()),
                *SMALL,
            ]
        )
        == 0
    )
    assert load_checkpoint(out)["meta"]["threads"] == [max_threads()]


# ------------------------------------------------------------------------------------------ schedule, val-every, stages


def test_lr_schedules():
    assert [lr_factor("constant", s, 100) for s in (0, 50, 99)] == [1.0, 1.0, 1.0]
    cosine = [lr_factor("cosine", s, 100) for s in range(101)]
    assert cosine[0] == 1.0 and math.isclose(cosine[100], 0.01) and math.isclose(cosine[50], 0.505)
    assert all(a >= b for a, b in zip(cosine, cosine[1:]))
    assert [lr_factor("step", s, 100) for s in (0, 49, 50, 74, 75, 99)] == [1.0, 1.0, 0.1, 0.1, 0.01, 0.01]


def test_val_every_schedule_and_stages_are_recorded(data, tmp_path):
    out = tmp_path / "k.pt"
    assert (
        main(
            [
                "train",
                "--model",
                "kpcn",
                "--data",
                str(data),
                "--steps",
                "4",
                "--out",
                str(out),
                "--val-every",
                "2",
                "--lr-schedule",
                "cosine",
                "--lr",
                "0.002",
                *SMALL,
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "train",
                "--model",
                "kpcn",
                "--data",
                str(data),
                "--steps",
                "2",
                "--out",
                str(out),
                "--resume",
                str(out),
                "--lr",
                "0.0005",
                *SMALL,
            ]
        )
        == 0
    )
    meta = load_checkpoint(out)["meta"]
    assert [s for s, _ in meta["validation_history"]] == [2]  # the end of each command validates into "validation"
    stages = meta["stages"]
    assert [(s["from_step"], s["steps"], s["lr"], s["lr_schedule"]) for s in stages] == [
        (0, 4, 0.002, "cosine"),
        (4, 2, 0.0005, "constant"),
    ]
    assert "--lr-schedule cosine" in meta["commands"][0] and "--val-every 2" in meta["commands"][0]


# ------------------------------------------------------------------------------------------ paper recipes


def test_dpcn_and_kpcn_share_every_configuration():
    assert pcn.DPCN_CONFIGS == pcn.KPCN_CONFIGS
    assert pcn.receptive_field(pcn.DPCN_CONFIGS["small"]) == 21 == pcn.DPCN_CONFIGS["small"]["kernel_size"]
    assert pcn.receptive_field(pcn.PAPER_CONFIG) == 37  # 9 layers of 5×5: radius 18
    for name in pcn.DPCN_CONFIGS:
        d, k = build_model("dpcn", name), build_model("kpcn", name)
        assert [m.weight.shape[:1] + m.weight.shape[2:] for m in d.diffuse if isinstance(m, torch.nn.Conv2d)][:-1] == [
            m.weight.shape[:1] + m.weight.shape[2:] for m in k.diffuse if isinstance(m, torch.nn.Conv2d)
        ][:-1]


def test_paper_configuration_is_xavier_initialised():
    torch.manual_seed(0)
    net = build_model("dpcn", "paper")
    convs = [m for m in net.diffuse if isinstance(m, torch.nn.Conv2d)]
    for conv in convs[:-1]:
        fan_in = conv.in_channels * conv.kernel_size[0] * conv.kernel_size[1]
        fan_out = conv.out_channels * conv.kernel_size[0] * conv.kernel_size[1]
        bound = math.sqrt(6.0 / (fan_in + fan_out))
        w = conv.weight.detach()
        assert float(w.abs().max()) <= bound and float(w.abs().max()) > 0.95 * bound  # uniform(±bound)
        assert math.isclose(float(w.std()), bound / math.sqrt(3.0), rel_tol=0.05)
        assert float(conv.bias.detach().abs().max()) == 0.0


def test_lobes_loss_is_the_two_branch_l1_without_a_colour_term():
    g = torch.Generator().manual_seed(0)
    b = {name: torch.rand(1, 3, 8, 8, generator=g) for name in ("reference", "reference_diffuse", "reference_specular")}
    out = {name: torch.rand(1, 3, 8, 8, generator=g) for name in ("color", "diffuse", "specular")}
    parts = pcn_loss(out, b, "lobes")
    expected = spatial_l1(out["diffuse"], b["reference_diffuse"]) + spatial_l1(out["specular"], b["reference_specular"])
    torch.testing.assert_close(parts["loss"], expected)
    assert "color" not in parts
    no_lobes = pcn_loss(out, {"reference": b["reference"]}, "lobes")  # user data without the split
    torch.testing.assert_close(no_lobes["loss"], spatial_l1(out["color"], b["reference"]))


@pytest.mark.parametrize("mode", ["dpcn", "kpcn"])
def test_exposure_loss_is_scale_invariant_where_the_log_loss_is_not(mode):
    """The same scene 1000x darker: the PCN's output scales with it (it normalises its input), the
    exposure loss stays put, the plain log loss (almost linear below 1) drops by orders of magnitude."""
    g = torch.Generator().manual_seed(3)
    torch.manual_seed(0)
    net = build_model(mode, "small")
    batch = {
        name: torch.rand(2, 3, 12, 12, generator=g) * 2.0
        for name in ("color", "diffuse", "specular", "reference", "reference_diffuse", "reference_specular")
    }
    batch["albedo"] = torch.rand(2, 3, 12, 12, generator=g)
    dark = {name: value * 1e-3 if name != "albedo" else value for name, value in batch.items()}
    with torch.no_grad():
        bright_out, dark_out = net(batch), net(dark)
    torch.testing.assert_close(dark_out["color"], bright_out["color"] * 1e-3, rtol=1e-4, atol=1e-9)
    exposure = [float(pcn_loss(o, b, "exposure")["loss"]) for o, b in ((bright_out, batch), (dark_out, dark))]
    log = [float(pcn_loss(o, b, "log")["loss"]) for o, b in ((bright_out, batch), (dark_out, dark))]
    assert exposure[0] > 0.01 and math.isclose(exposure[0], exposure[1], rel_tol=1e-3)
    assert log[1] < 0.01 * log[0]
    black = {name: torch.zeros_like(value) for name, value in batch.items()}
    black["reference"] = torch.full_like(batch["reference"], 0.5)
    with torch.no_grad():
        black_out = net(black)
    value = float(pcn_loss(black_out, black, "exposure")["loss"])  # black input: compared unscaled, no 1e30
    assert math.isclose(value, float(pcn_loss(black_out, black, "log")["loss"]), rel_tol=1e-6) and value < 1.0


def test_exposure_loss_trains_dpcn_through_the_cli(data, tmp_path, capsys):
    out = tmp_path / "e.pt"
    assert (
        main(
            [
                "train",
                "--model",
                "dpcn",
                "--data",
                str(data),
                "--steps",
                "2",
                "--out",
                str(out),
                "--loss",
                "exposure",
                *SMALL,
            ]
        )
        == 0
    )
    meta = load_checkpoint(out)["meta"]
    assert meta["loss"] == "exposure" and meta["skipped_steps"] == 0 and math.isfinite(meta["last_loss"])
    capsys.readouterr()
    assert (
        main(
            [
                "train",
                "--model",
                "lbf",
                "--data",
                str(data),
                "--steps",
                "1",
                "--out",
                str(out),
                "--loss",
                "exposure",
                *SMALL,
            ]
        )
        == 2
    )
    assert "unknown loss" in capsys.readouterr().err


def test_lobes_loss_trains_through_the_cli_and_is_refused_for_rae(data, tmp_path, capsys):
    out = tmp_path / "p.pt"
    assert (
        main(
            [
                "train",
                "--model",
                "kpcn",
                "--data",
                str(data),
                "--steps",
                "1",
                "--out",
                str(out),
                "--loss",
                "lobes",
                *SMALL,
            ]
        )
        == 0
    )
    assert load_checkpoint(out)["meta"]["loss"] == "lobes"
    capsys.readouterr()
    assert (
        main(
            [
                "train",
                "--model",
                "rae",
                "--data",
                str(data),
                "--steps",
                "1",
                "--out",
                str(out),
                "--loss",
                "lobes",
                *SMALL,
            ]
        )
        == 2
    )
    assert "unknown loss" in capsys.readouterr().err


def test_shipped_checkpoints_keep_their_own_shape():
    """dpcn_small.pt predates the shared configuration: it records (and rebuilds) its own shape."""
    from denoisebench.models.denoisers import shipped_weights

    payload = load_checkpoint(shipped_weights("dpcn"))
    assert payload["config"] == {"layers": 5, "channels": 24, "kernel": 3, "kernel_size": 21}


# ------------------------------------------------------------------------------------------ the convergence bench


def test_pcn_convergence_bench_runs_a_few_steps(data, tmp_path):
    spec = importlib.util.spec_from_file_location("pcn_convergence", ROOT / "bench" / "pcn_convergence.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    out = tmp_path / "curves"
    assert (
        bench.main(
            [
                "--data",
                str(data),
                "--out",
                str(out),
                "--steps",
                "4",
                "--val-every",
                "2",
                "--batch-size",
                "2",
                "--crop",
                "12",
                "--val-frames",
                "1",
                "--quiet",
            ]
        )
        == 0
    )
    import json

    result = json.loads((out / "curves.json").read_text())
    for model in ("dpcn", "kpcn"):
        run = result["runs"][model]
        assert [s for s, _ in run["validation_history"]] == [2, 4]
        assert all(0 < v < float("inf") for _, v in run["validation_history"])
    assert result["steps_to_target"]["dpcn"] in (2, 4)  # DPCN reaches its own best by definition
    assert result["steps_to_loss_target"]["dpcn"] is not None and result["loss_target"] > 0
    assert (out / "curves.png").stat().st_size > 1000
    assert bench.steps_to_reach([[2, 0.5], [4, 0.2]], 0.3) == 4 and bench.steps_to_reach([[2, 0.5]], 0.1) is None


# ------------------------------------------------------------------------------------------ cards: bootstrap


def test_bootstrap_over_scenes_is_paired_deterministic_and_covers_the_mean():
    from denoisebench.analysis.aggregate import bootstrap_over_scenes

    rng = np.random.default_rng(1)
    scenes = [f"s{i}" for i in range(8) for _ in range(3)]
    base = rng.uniform(0.1, 1.0, len(scenes))
    scores = {"ours": list(0.5 * base), "peer": list(base)}
    intervals, ratios = bootstrap_over_scenes(scores, scenes, "ours", ["peer"], resamples=500)
    again = bootstrap_over_scenes(scores, scenes, "ours", ["peer"], resamples=500)
    assert (intervals, ratios) == again
    for name, values in scores.items():
        lo, hi = intervals[name]
        assert lo < np.mean(values) < hi
    # paired resampling: ours is exactly half of peer in every draw, so the ratio has no spread
    assert ratios["peer"][0] == pytest.approx(0.5) and ratios["peer"][1] == pytest.approx(0.5)


# ------------------------------------------------------------------------------------------ splits


def test_splits_stratified_by_family():
    families = {"cornell": 3, "dim_room": 5, "glass_env": 10, "tiny": 2, "solo": 1}
    names = [f"{family}_{i:03d}" for family, count in families.items() for i in range(count)]
    family_of = {name: name.rsplit("_", 1)[0] for name in names}
    for seed in range(6):
        splits = assign_splits(names, seed, families=family_of)
        assert sorted(sum(splits.values(), [])) == sorted(names)  # a partition
        for family, count in families.items():
            if count >= 3:
                for split in ("train", "val", "test"):
                    assert any(family_of[n] == family for n in splits[split]), (seed, family, split)
        glass = {s: sum(family_of[n] == "glass_env" for n in v) for s, v in splits.items()}
        assert glass == {"train": 6, "val": 2, "test": 2}  # 10 × 0.15 = 1.5 rounds half up to 2
        assert splits == assign_splits(list(reversed(names)), seed, families=family_of)  # order-free


def test_without_large_families_the_split_is_unchanged():
    names = ["a_000", "a_001", "b_000", "c_000", "c_001"]
    families = {n: n.split("_")[0] for n in names}
    for seed in range(4):
        assert assign_splits(names, seed, families=families) == assign_splits(names, seed)


# ------------------------------------------------------------------------------------------ RAE paper recipe


def _pinhole(h=20, w=30, seed=0):
    """A pinhole view of random depths: (position 1×3×H×W, depth 1×1×H×W, rows right/down/forward)."""
    g = torch.Generator().manual_seed(seed)
    q = torch.linalg.qr(torch.randn(3, 3, generator=g, dtype=torch.float64))[0]
    if torch.det(q) < 0:
        q[:, 0] *= -1
    origin = torch.tensor([1.0, -2.0, 30.0], dtype=torch.float64)
    t = math.tan(math.radians(25))
    ys, xs = torch.meshgrid(torch.arange(h) + 0.5, torch.arange(w) + 0.5, indexing="ij")
    u, v = (xs - w / 2) / (w / 2) * t, (ys - h / 2) / (w / 2) * t
    z = 2.0 + 3.0 * torch.rand(h, w, generator=g, dtype=torch.float64)
    rays = u[None] * q[0, :, None, None] + v[None] * q[1, :, None, None] + q[2, :, None, None]
    position = origin[:, None, None] + z[None] * rays
    z[0, :5] = 0.0  # misses: depth and position 0
    position[:, 0, :5] = 0.0
    return position[None].float(), z[None, None].float(), q.float()


def test_camera_axes_are_recovered_from_position_and_depth_also_on_flipped_crops():
    from denoisebench.models.features import camera_axes

    position, depth, axes = _pinhole()
    torch.testing.assert_close(camera_axes(position, depth)[0], axes, atol=1e-4, rtol=0)
    crop = camera_axes(position[..., 3:15, 4:20].flip(-1), depth[..., 3:15, 4:20].flip(-1))[0]
    torch.testing.assert_close(crop, torch.stack([-axes[0], axes[1], axes[2]]), atol=1e-4, rtol=0)  # x follows the flip
    assert float(camera_axes(torch.zeros(1, 3, 4, 4), torch.zeros(1, 1, 4, 4)).abs().max()) == 0.0  # all misses


def test_rae_paper_configuration_has_seven_inputs_view_normals_and_demodulation():
    from denoisebench.models.features import view_normals

    net = build_model("rae", "paper")
    assert net.encoders[0][0].in_channels == 7 and net.demodulate and net.view_normals
    position, depth, axes = _pinhole(seed=1)
    normal = torch.nn.functional.normalize(torch.randn(1, 3, 20, 30), dim=1)
    vn = view_normals({"position": position, "depth": depth, "normal": normal}, normal)
    torch.testing.assert_close(vn, torch.einsum("kc,nchw->nkhw", axes[:2], normal), atol=1e-4, rtol=0)


def test_play_backward_reverses_about_half_the_windows(data):
    from denoisebench.dataset.torch_dataset import SequenceCropDataset

    forward = SequenceCropDataset(data, "train", 2, frames=2, crop=8, seed=3)
    both = SequenceCropDataset(data, "train", 2, frames=2, crop=8, seed=3, play_backward=True)
    reversed_count = 0
    for epoch in range(6):
        forward.set_epoch(epoch)
        both.set_epoch(epoch)
        for i in range(len(forward)):
            a, b = forward[i]["color"], both[i]["color"]
            if torch.equal(a, b):
                continue
            torch.testing.assert_close(b, a.flip(0), rtol=0, atol=0)  # same crop, frames reversed
            reversed_count += 1
    total = 6 * len(forward)
    assert 0.2 * total <= reversed_count <= 0.8 * total


def test_rae_paper_recipe_trains_with_its_crop_cap_and_backward_play(data, tmp_path):
    out = tmp_path / "rae.pt"
    assert (
        main(
            [
                "train",
                "--model",
                "rae",
                "--data",
                str(data),
                "--config",
                "paper",
                "--steps",
                "1",
                "--out",
                str(out),
                "--batch-size",
                "1",
                "--quiet",
            ]
        )
        == 0
    )
    meta = load_checkpoint(out)["meta"]
    assert meta["crop"] == 16  # the recipe's 128 px, capped by the 16 px scenes
    assert meta["play_backward"] is True and "--crop" not in meta["commands"][0]


def test_rae_sequence_exposure_is_held_until_reset_and_skips_black_frames():
    torch.manual_seed(0)
    net = build_model("rae", {"levels": [4, 6], "bottleneck": 8, "sequence_exposure": True, "residual": True}).eval()
    g = torch.Generator().manual_seed(1)
    frame = {"color": torch.rand(1, 3, 8, 8, generator=g)}
    black = {"color": torch.zeros(1, 3, 8, 8)}
    with torch.no_grad():
        net.reset()
        net(black)
        assert float(net._exposure) == 0.0
        net(frame)  # the first lit frame sets it
        first = float(net._exposure)
        assert first > 0
        net({"color": 10.0 * frame["color"]})  # a brighter frame does not move it
        assert float(net._exposure) == first
        net.reset()
        net({"color": 10.0 * frame["color"]})
        assert float(net._exposure) == pytest.approx(10.0 * first, rel=1e-5)


def test_log_depth_var_follows_the_depth_transform():
    from denoisebench.models.features import feature_stack

    depth = torch.full((1, 1, 4, 4), 9.0)
    buffers = {"depth": depth, "depth_var": torch.full((1, 1, 4, 4), 2.0)}
    like = torch.zeros(1, 3, 4, 4)
    raw = feature_stack(buffers, like)[:, -1]
    logged = feature_stack(buffers, like, log_depth_var=True)[:, -1]
    torch.testing.assert_close(raw, torch.log1p(torch.full((1, 4, 4), 2.0)))
    torch.testing.assert_close(logged, torch.log1p(torch.full((1, 4, 4), 2.0 / 100.0)))  # var / (1 + d)²
    assert (
        pcn.DPCN_CONFIGS["small"]["log_depth_var"]
        and not build_model("kpcn", {**pcn.SMALL_CONFIG, "log_depth_var": False}).log_depth_var
    )


def test_peers_option_checks_its_names(data, tmp_path, capsys):
    out = tmp_path / "x.pt"
    capsys.readouterr()
    assert (
        main(
            [
                "train",
                "--model",
                "lbf",
                "--data",
                str(data),
                "--steps",
                "0",
                "--out",
                str(out),
                "--evaluate",
                "--peers",
                "lbf",
                *SMALL,
            ]
        )
        == 2
    )
    assert "--peers" in capsys.readouterr().err


def test_loader_workers_give_the_same_weights_as_the_main_process(data, tmp_path):
    """Crops are drawn per (epoch, item), not per process: 2 loader workers train bit for bit alike."""
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    common = ["train", "--model", "dpcn", "--data", str(data), "--steps", "5", "--device", "cpu", *SMALL]
    assert main([*common, "--out", str(a), "--workers", "0"]) == 0
    assert main([*common, "--out", str(b), "--workers", "2"]) == 0
    sa, sb = load_checkpoint(a)["state_dict"], load_checkpoint(b)["state_dict"]
    for name, tensor in sa.items():
        assert torch.equal(tensor, sb[name]), name
