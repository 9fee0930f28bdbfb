"""Synthetic frames (used by the hard-case suite, tests and benchmarks) and the lens map."""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.denoisers.lens_sampling import square_to_disk_concentric
from denoisebench.denoisers.synthetic import FAMILIES, synthetic_frame, synthetic_sequence


def test_concentric_map_matches_mitsuba():
    from denoisebench.mitsuba_runtime import load_mitsuba

    mi = load_mitsuba()
    square = np.random.default_rng(0).random((2000, 2))
    square[:3] = [[0.5, 0.5], [0.0, 0.0], [0.999, 0.25]]  # centre and corners
    theirs = mi.warp.square_to_uniform_disk_concentric(mi.Point2f(square[:, 0], square[:, 1]))
    ours = square_to_disk_concentric(square)
    np.testing.assert_allclose(ours, np.stack([np.array(theirs.x), np.array(theirs.y)], -1), atol=1e-6)
    assert np.all(np.linalg.norm(ours, axis=-1) <= 1.0 + 1e-12)


@pytest.mark.parametrize("family", FAMILIES)
def test_random_parameters_follow_the_effects(family):
    frame = synthetic_frame(family, 12, 10, 2, seed=1)
    assert frame.color.shape == (10, 12, 3) and frame.reference.shape == (10, 12, 3)
    assert ("lens" in frame.samples) == (family == "depth_of_field")
    assert ("time" in frame.samples) == (family == "motion_blur")
    assert frame.samples["pixel"].shape == (2, 10, 12, 2)
    np.testing.assert_allclose(frame.color, frame.samples["color"].mean(axis=0), rtol=1e-5, atol=1e-7)
    assert all(np.isfinite(a).all() for a in frame.buffers.values())


def test_noisy_mean_is_unbiased_against_the_reference():
    """The mean of many noisy frames converges to the reference (energy is not lost or added)."""
    many = synthetic_frame("shapes", 16, 16, 256, seed=3, samples=False, reference_samples=64)
    relative = abs(float(many.color.mean()) / float(many.reference.mean()) - 1.0)
    assert relative < 0.03


def test_frames_are_deterministic_and_sequences_pan():
    a = synthetic_frame("glossy", 10, 10, 2, seed=4)
    b = synthetic_frame("glossy", 10, 10, 2, seed=4)
    np.testing.assert_array_equal(a.color, b.color)
    sequence = synthetic_sequence("shapes", 16, 16, 2, frames=3, seed=5, pan=(2.0, 0.0))
    assert [f.index for f in sequence] == [0, 1, 2]
    assert np.all(sequence[1].buffers["motion"][..., 0] == 2.0)
    # a 2-pixel pan: frame 1's reference is frame 0's shifted left by two columns (same scene); edge
    # pixels differ by their 16-sample reference estimate, flat ones agree
    same = np.isclose(sequence[1].reference[:, :-2], sequence[0].reference[:, 2:], rtol=0.05, atol=0.01)
    assert same.mean() > 0.9
    unrelated = np.isclose(sequence[1].reference[:, :-2], sequence[0].reference[:, :-2], rtol=0.05, atol=0.01)
    assert unrelated.mean() < same.mean() - 0.1
