"""``denoisebench export --format noisebase``, read by the ``noisebase`` package's own loaders.

Peer: ``noisebase`` 1.1.1 (installed ``--no-deps``): ``TrainingSampleLoader_v1`` reads a sequence
zip, ``TestSampleLoader_v1`` per-frame zips, and their tensors, after Noisebase's documented
transforms (RGBE decoding, the motion it derives from world positions and the camera matrices,
log depth), equal ours. The motion check is the strong one: it holds only if our camera arrays and
projection conventions are exactly Noisebase's.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

pytest.importorskip("zarr")
loaders = pytest.importorskip("noisebase.loaders.torch")
compression = pytest.importorskip("noisebase.compression")

from denoisebench.cli import main  # noqa: E402
from denoisebench.dataset import open_dataset  # noqa: E402
from denoisebench.dataset.export import noisebase as nbx  # noqa: E402
from denoisebench.errors import UserInputError  # noqa: E402
from tests.support.paths import REPO  # noqa: E402

SPP = 4
BUFFERS = ["color", "reference", "w_position", "w_normal", "w_motion", "motion", "depth", "diffuse"]


@pytest.fixture(scope="module")
def rendered(tmp_path_factory, mi):
    out = tmp_path_factory.mktemp("nb") / "ds"
    args = ["generate", "--out", str(out), "--families", "cornell", "--frames", "3", "--width", "24"]
    args += ["--height", "16", "--spp", f"1,{SPP}", "--ref-spp", "16", "--ref-error", "0", "--samples", "--quiet"]
    assert main(args) == 0
    return out


def _export(rendered, out, *extra):
    assert main(["export", str(rendered), str(out), "--format", "noisebase", "--quiet", *extra]) == 0
    return json.loads((out / "denoisebench_export.json").read_text())


def _rgbe_bound(ours):
    # half a level of the pixel's exponent, which is < 2× its brightest channel (exposure span / 256 ≪ ln 2)
    return ours.max(axis=0, keepdims=True) * 2 / 510 + 1e-6


def _check_frame(batch, frame, ours_cam_pos):
    samples = frame.samples
    c = np.transpose(samples["color"], (3, 1, 2, 0))
    color = batch["color"][0].numpy()
    assert np.all(np.abs(color - c) <= _rgbe_bound(c))
    np.testing.assert_array_equal(batch["reference"][0].numpy(), frame.reference.transpose(2, 0, 1))
    position = np.transpose(samples["position"], (3, 1, 2, 0))
    if "w_position" in batch:
        np.testing.assert_array_equal(batch["w_position"][0].numpy(), position)
        np.testing.assert_allclose(
            batch["w_normal"][0].numpy(), np.transpose(samples["normal"], (3, 1, 2, 0)), atol=1e-3
        )
        np.testing.assert_allclose(
            batch["diffuse"][0].numpy(), np.transpose(samples["albedo"], (3, 1, 2, 0)), atol=1e-3
        )
        assert not batch["w_motion"].numpy().any()
        distance = np.linalg.norm(position - ours_cam_pos[:, None, None, None], axis=0, keepdims=True)
        np.testing.assert_allclose(batch["depth"][0].numpy(), np.log(1 + 1 / distance), rtol=1e-5)
    # Noisebase's motion: (row, column) pixels from now to the previous frame, per sample
    motion = batch["motion"][0].numpy().mean(axis=-1)
    ours = frame.buffers["motion"]
    np.testing.assert_allclose(motion[0], ours[..., 1], atol=1e-3)
    np.testing.assert_allclose(motion[1], ours[..., 0], atol=1e-3)


def test_training_loader_reads_a_sequence_equal_to_ours(rendered, tmp_path):
    out = tmp_path / "train"
    summary = _export(rendered, out)
    ds = open_dataset(rendered)
    (split,) = summary["src"]
    src = summary["src"][split]
    assert src["frames_per_sequence"] == 3 and src["samples"] == SPP and src["rendering_height"] == 16
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loader = loaders.TrainingSampleLoader_v1(
            src=src,
            stage="val",  # a one-sequence dataset is all validation (their split keeps >= batch_size)
            seed=0,
            val_split=0.0,
            shuffle=False,
            batch_size=1,
            drop_last=False,
            num_workers=0,
            flip_rotate=False,
            buffers=BUFFERS,
            samples=SPP,
            data_path=str(out),
        )
        batches = list(loader)
    scene = ds.scenes[0]
    assert len(batches) == 3
    moved = 0.0
    for index, batch in enumerate(batches):
        frame = ds.frame(scene, SPP, index)
        pose = np.array(ds.scene(scene).record["renders"][f"spp{SPP:04d}"][f"{index:04d}"]["camera_pose"])
        np.testing.assert_allclose(batch["camera_position"][0].numpy(), pose[:3, 3], atol=1e-6)
        _check_frame(batch, frame, pose[:3, 3])
        moved = max(moved, float(np.abs(frame.buffers["motion"]).max()))
    assert moved > 0.5  # the camera moves: the motion check above is not 0 == 0


def _loader_workers_at_most_one(monkeypatch):
    """Noisebase's test loader asks torch for 8 loader workers (for 3 frames here): each is a fork of this pytest
    process and starts with its resident pages. One worker still reads every frame through the worker path."""
    import torch.utils.data

    class AtMostOneWorker(torch.utils.data.DataLoader):
        def __init__(self, *args, **kwargs):
            kwargs["num_workers"] = min(kwargs.get("num_workers", 0), 1)
            super().__init__(*args, **kwargs)

    monkeypatch.setattr(torch.utils.data, "DataLoader", AtMostOneWorker)


def test_test_loader_reads_padded_frames_equal_to_ours(rendered, tmp_path, monkeypatch):
    _loader_workers_at_most_one(monkeypatch)
    out = tmp_path / "test"
    summary = _export(rendered, out, "--layout", "test", "--spp", "1")
    ds = open_dataset(rendered)
    (split,) = summary["src"]
    src = summary["src"][split]
    assert src["rendering_height"] == 16 + 2 * nbx.TEST_PAD and src["samples"] == 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        loader = loaders.TestSampleLoader_v1(
            src=src,
            buffers=["color", "reference", "motion"],
            samples=1,
            data_path=str(out),
            save_dir=str(tmp_path / "pred"),
            output="{sequence_name}/frame{index:04d}.png",
        )
        sequences = list(loader)
        assert [s.sequence["name"] for s in sequences] == ds.scenes
        frames = list(sequences[0].frames)
        sequences[0].join()
    assert len(frames) == 3
    for index, batch in enumerate(frames):
        _check_frame(batch, ds.frame(ds.scenes[0], 1, index), None)


@pytest.mark.filterwarnings("ignore:invalid value encountered in cast")  # their encoder, on black samples
def test_rgbe_decodes_with_noisebase_within_half_a_level():
    rng = np.random.default_rng(5)
    color = np.exp(rng.normal(0, 3, (3, 9, 7, 5))).astype(np.float32)
    color[:, 0, 0, 0] = 0.0  # a black sample
    color[1, 1, 1, 1] = 0.0  # one black channel
    color[:, 2, 2, 2] = 5e4  # a firefly
    packed, exposure = nbx.encode_rgbe(color)
    assert packed.dtype == np.uint8 and packed.shape == (4, 9, 7, 5)
    decoded = compression.decompress_RGBE(packed, exposure)
    np.testing.assert_array_equal(decoded, nbx.decode_rgbe(packed, exposure))
    assert np.all(np.abs(decoded - color) <= _rgbe_bound(color))
    assert decoded[:, 0, 0, 0].tolist() == [0, 0, 0] and decoded[1, 1, 1, 1] == 0
    # Noisebase's own (dithered) encoder is no closer than ours
    np.random.seed(0)  # their dither draws from numpy's global generator
    theirs = compression.decompress_RGBE(*compression.compress_RGBE(color))
    assert np.abs(decoded - color).mean() <= np.abs(theirs - color).mean()
    black, black_exposure = nbx.encode_rgbe(np.zeros((3, 2, 2, 1), np.float32))
    assert not black.any() and not compression.decompress_RGBE(black, black_exposure).any()


def test_moving_objects_are_refused(rendered):
    ds = open_dataset(rendered)
    scene = ds.scenes[0]
    frame = ds.frame(scene, SPP, 1)
    record = ds.scene(scene).record["renders"][f"spp{SPP:04d}"]
    fov = ds.scene(scene).camera["fov_x_deg"]
    cams = [nbx.camera_arrays(record[f"{i:04d}"]["camera_pose"], fov, 24, 16) for i in (0, 1)]
    args = (scene, 1, frame.samples["position"])
    nbx.check_static_geometry(*args, frame.buffers["motion"], cams[1], cams[0], 24, 16)  # static: accepted
    shifted = frame.buffers["motion"].copy()
    shifted[4:8, 4:8, 0] += 1.5  # part of the image moves on its own
    with pytest.raises(UserInputError, match="not the camera's alone"):
        nbx.check_static_geometry(*args, shifted, cams[1], cams[0], 24, 16)
    # background samples (position 0 by our convention) are left out through the hit mask
    missed = frame.samples["position"].copy()
    missed[:, 2:6, 10:16] = 0.0
    with pytest.raises(UserInputError):
        nbx.check_static_geometry(scene, 1, missed, frame.buffers["motion"], cams[1], cams[0], 24, 16)
    hit = np.ones((16, 24), bool)
    hit[2:6, 10:16] = False
    nbx.check_static_geometry(scene, 1, missed, frame.buffers["motion"], cams[1], cams[0], 24, 16, hit)


def test_bad_input_is_one_line_exit_2(rendered, tmp_path, capsys):
    from denoisebench.dataset.synthetic import make_synthetic_dataset

    plain = make_synthetic_dataset(tmp_path / "plain", scenes=1, frames=2)
    for source, extra, message in (
        (plain, [], "no per-sample data"),
        (rendered, ["--spp", "3"], "not --spp 3"),
        (rendered, ["--scenes", "cornell_000,nope"], "--scenes: no scene nope"),
    ):
        out = tmp_path / "never"
        assert main(["export", str(source), str(out), "--format", "noisebase", "--quiet", *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert message in err and "\n" not in err
        assert not out.exists()


def test_peer_packages_are_the_pinned_ones_and_torch_stays():
    import importlib.metadata
    import re

    import torch

    root = REPO
    assert torch.__version__.split("+")[0] == "2.13.0"
    for file, names in (
        ("requirements-nodeps.txt", ("noisebase",)),
        ("requirements.txt", ("zarr", "numcodecs", "hydra-core", "OpenImageIO")),
    ):
        text = (root / file).read_text()
        for name in names:
            pin = re.search(rf"^{re.escape(name)}==(\S+)", text, re.M)
            assert pin, (file, name)
            assert importlib.metadata.version(name) == pin.group(1), name
