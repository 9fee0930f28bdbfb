"""The hard-case suite: its frames hold what they claim, every built-in passes, bad denoisers fail."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from denoisebench.denoisers import hard_cases
from denoisebench.denoisers.hard_cases import CASES, check_denoiser, energy_reason, robust_mean, run_case
from denoisebench.denoisers.registry import BUILTINS, load_denoiser


@pytest.fixture(scope="module")
def frames():
    return {case.name: case.make() for case in CASES}


def test_case_frames_hold_what_they_claim(frames):
    fireflies = frames["fireflies"][0]
    peaks = fireflies.samples["color"].max(axis=(0, 3))
    assert np.count_nonzero(peaks >= 1e5) == 6 and peaks.max() <= 1e6
    np.testing.assert_allclose(fireflies.color, fireflies.samples["color"].mean(axis=0), rtol=1e-5)
    black = frames["black_frame"][0]
    assert all(not np.any(a) for a in black.buffers.values()) and all(not np.any(a) for a in black.samples.values())
    assert not np.any(frames["zero_albedo"][0].buffers["albedo"])
    ramp = frames["dynamic_range"][0].color
    positive = ramp[ramp > 0]
    assert positive.min() < 1e-5 and positive.max() > 1e5
    dirty = frames["nan_inf"][0]
    for name in ("color", "albedo", "normal", "depth"):
        for array in (dirty.buffers[name], dirty.samples[name]):
            assert np.isnan(array).any() and np.isposinf(array).any() and np.isneginf(array).any()
    constant = frames["constant_features"][0]
    assert all(
        not np.ptp(constant.buffers[name], axis=(0, 1)).any()
        for name in ("albedo", "normal", "depth", "position", "roughness")
    )
    assert frames["one_spp"][0].spp == 1 and frames["one_spp"][0].samples["color"].shape[0] == 1
    assert (frames["odd_size"][0].height, frames["odd_size"][0].width) == (45, 67)
    assert (frames["tiny"][0].height, frames["tiny"][0].width) == (3, 3)
    assert len(frames["one_frame_sequence"]) == 1


def test_cases_are_reproducible():
    first, second = CASES[0].make()[0], CASES[0].make()[0]
    np.testing.assert_array_equal(first.color, second.color)


#: the classical baselines and peers (the learned models' built-ins are tested with their weights)
BASELINES = sorted(name for name, (target, _) in BUILTINS.items() if target.startswith("denoisebench.baselines."))


def test_baselines_are_all_there():
    assert set(BASELINES) >= {
        "identity",
        "cross_bilateral",
        "cross_bilateral_fast",
        "cross_bilateral_high",
        "rpf",
        "nlmeans",
        "oidn",
    }


@pytest.mark.parametrize("name", BASELINES)
def test_every_baseline_passes_every_case(name):
    outcomes = check_denoiser(load_denoiser(name))
    failed = [(o.case, o.reason) for o in outcomes if not o.passed]
    assert not failed
    nan_case = next(o for o in outcomes if o.case == "nan_inf")
    assert nan_case.sanitized > 0  # the runner replaced and counted them


class Negative:
    name = "negative"

    def denoise(self, frame):
        return (np.asarray(frame.color) - 1.0).astype(np.float32)


class Darkens:
    name = "darkens"

    def denoise(self, frame):
        return (np.asarray(frame.color) * 0.01).astype(np.float32)


class SpreadsFireflies:
    """A 9×9 box blur: keeps the mean, but smears each 1e5 firefly over 81 pixels."""

    name = "box9"

    def denoise(self, frame):
        return ndimage.uniform_filter(np.asarray(frame.color, np.float32), size=(9, 9, 1), mode="nearest")


class TinyFails:
    name = "tiny_fails"

    def denoise(self, frame):
        if frame.width < 5:
            raise ValueError("image too small")
        return np.array(frame.color, np.float32)


@pytest.mark.parametrize(
    "denoiser, case, fragment",
    [
        (Negative(), "one_spp", "negative output"),
        (Darkens(), "one_spp", "robust mean"),
        (SpreadsFireflies(), "fireflies", "robust mean"),
        (TinyFails(), "tiny", "raised ValueError: image too small"),
    ],
)
def test_bad_denoisers_fail_with_a_reason(denoiser, case, fragment):
    outcome = run_case(denoiser, hard_cases.hard_cases([case])[0])
    assert not outcome.passed and fragment in outcome.reason


def test_a_failing_case_does_not_stop_the_others():
    outcomes = check_denoiser(TinyFails())
    assert [o.case for o in outcomes] == [c.name for c in CASES]
    assert [o.case for o in outcomes if not o.passed] == ["tiny"]


def test_energy_rule():
    rng = np.random.default_rng(0)
    image = rng.random((16, 16, 3)).astype(np.float32)
    assert energy_reason(image, image) is None
    assert energy_reason(image * 3.9, image) is None and energy_reason(image * 4.1, image) is not None
    assert energy_reason(image / 3.9, image) is None and energy_reason(image / 4.1, image) is not None
    # a few huge outliers in the input do not set the scale
    spiky = image.copy()
    spiky[0, 0] = 1e6
    assert robust_mean(spiky) == pytest.approx(robust_mean(image), rel=0.05)
    black = np.zeros_like(image)
    assert energy_reason(black, black) is None and "black" in energy_reason(black + 1e-3, black)


def test_unknown_case_name():
    with pytest.raises(ValueError, match="unknown hard case"):
        hard_cases.hard_cases(["fireflies", "bogus"])
