"""Runner: failure containment, output checks, input sanitising, timing, sequences."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy import ndimage

from denoisebench.dataset.frame import Frame
from denoisebench.denoisers.registry import load_denoiser
from denoisebench.denoisers.runner import (
    STATUS_FAILED,
    STATUS_OK,
    check_output,
    run_denoisers,
    run_frame,
    run_sequence,
    sanitize_array,
    sanitize_frame,
)
from denoisebench.denoisers.synthetic import synthetic_frame, synthetic_sequence


class Raises:
    name = "raises"

    def denoise(self, frame):
        raise RuntimeError("plugin bug\nwith a second line")


class ReturnsNaN:
    name = "nan"

    def denoise(self, frame):
        out = np.array(frame.color, dtype=np.float32)
        out[0, 0, 0] = np.nan
        out[1, 1, 1] = np.inf
        return out


class WrongShape:
    name = "wrong_shape"

    def denoise(self, frame):
        return np.zeros((frame.height + 1, frame.width, 3), np.float32)


class WrongDtype:
    name = "wrong_dtype"

    def denoise(self, frame):
        return np.asarray(frame.color, dtype=np.float64)


class NotAnArray:
    name = "list"

    def denoise(self, frame):
        return frame.color.tolist()


class Writes:
    """Tries to modify its input in place (must be refused) and to read the reference."""

    name = "writes"

    def denoise(self, frame):
        assert frame.reference is None
        frame.buffers["color"][0, 0, 0] = 123.0  # raises: inputs are read-only views
        return np.array(frame.color, np.float32)


class Sleeps:
    name = "sleeps"

    def denoise(self, frame):
        time.sleep(0.05)
        return np.array(frame.color, np.float32)


@pytest.fixture(scope="module")
def sequences():
    return [synthetic_sequence("shapes", 16, 12, 2, frames=2, seed=s) for s in (1, 2)]


def test_failures_are_contained_and_the_others_results_are_intact(sequences):
    good = {"identity": load_denoiser("identity"), "cross_bilateral": load_denoiser("cross_bilateral_fast")}
    bad = {d.name: d for d in (Raises(), ReturnsNaN(), WrongShape(), WrongDtype(), NotAnArray(), Writes())}
    mixed = {"identity": good["identity"], **bad, "cross_bilateral": good["cross_bilateral"]}
    alone = run_denoisers(good, sequences)
    results = run_denoisers(mixed, sequences)
    expected_errors = {
        "raises": "raised RuntimeError: plugin bug",
        "nan": "non-finite values (1 NaN, 1 Inf)",
        "wrong_shape": "shape (13, 16, 3)",
        "wrong_dtype": "dtype float64",
        "list": "not a numpy array",
        "writes": "read-only",
    }
    for label, fragment in expected_errors.items():
        records = results[label]
        assert len(records) == 4 and all(r.status == STATUS_FAILED for r in records)
        assert all(fragment in r.error and "\n" not in r.error for r in records), records[0].error
        assert all(r.output is None for r in records)
    for label in good:
        assert [r.status for r in results[label]] == [STATUS_OK] * 4
        for with_bad, without in zip(results[label], alone[label]):
            np.testing.assert_array_equal(with_bad.output, without.output)
    # the input frames were not modified by the plugin that tried
    assert sequences[0][0].color[0, 0, 0] != 123.0


def test_missing_needs_fail_without_a_call():
    calls = []

    class NeedsSamples:
        name = "needs_samples"
        needs = frozenset({"samples", "albedo"})

        def denoise(self, frame):
            calls.append(1)
            return np.array(frame.color, np.float32)

    frame = Frame(buffers={"color": np.ones((4, 5, 3), np.float32)})
    result = run_frame(NeedsSamples(), frame)
    assert result.status == STATUS_FAILED and result.seconds is None and not calls
    assert "albedo, samples" in result.error


def test_timing_covers_the_call_only():
    frame = synthetic_frame("shapes", 8, 8, 2, samples=False)
    result = run_frame(Sleeps(), frame)
    assert result.ok and result.seconds >= 0.05


@pytest.mark.parametrize(
    "output, reason",
    [
        (np.zeros((4, 5, 3), np.float32), None),
        (np.zeros((4, 5, 4), np.float32), "shape"),
        (np.zeros((4, 5, 3), np.float16), "dtype"),
        (np.full((4, 5, 3), -np.inf, np.float32), "non-finite"),
        (None, "not a numpy array"),
    ],
)
def test_check_output(output, reason):
    got = check_output(output, 4, 5)
    assert (got is None) if reason is None else (reason in got)


def test_sanitize_matches_a_nan_median_filter_peer():
    rng = np.random.default_rng(3)
    array = rng.random((9, 11, 3)).astype(np.float32)
    bad = rng.random(array.shape) < 0.15
    array[bad] = np.where(rng.random(np.count_nonzero(bad)) < 0.5, np.nan, np.inf)
    clean, count = sanitize_array(array)
    assert count == np.count_nonzero(bad) and np.isfinite(clean).all()
    # peer: scipy's generic_filter with nanmedian over the 3×3 window, outside the image = NaN
    for channel in range(3):
        data = np.where(np.isfinite(array[..., channel]), array[..., channel], np.nan).astype(np.float64)
        peer = ndimage.generic_filter(data, np.nanmedian, size=3, mode="constant", cval=np.nan)
        peer = np.where(np.isfinite(peer), peer, 0.0)
        mask = bad[..., channel]
        np.testing.assert_allclose(clean[..., channel][mask], peer[mask], rtol=1e-6)
        np.testing.assert_array_equal(clean[..., channel][~mask], array[..., channel][~mask])


def test_sanitize_all_bad_neighbourhood_becomes_zero_and_finite_input_is_untouched():
    array = np.full((3, 3, 1), np.nan, np.float32)
    clean, count = sanitize_array(array)
    assert count == 9 and np.all(clean == 0.0)
    finite = np.ones((2, 2, 3), np.float32)
    same, count = sanitize_array(finite)
    assert count == 0 and same is finite


def test_sanitize_frame_counts_buffers_and_samples_and_withholds_reference():
    frame = synthetic_frame("depth_of_field", 10, 8, 3, seed=4)
    frame.buffers["albedo"] = frame.buffers["albedo"].copy()
    frame.buffers["albedo"][2, 3] = np.nan
    samples = dict(frame.samples)
    samples["lens"] = samples["lens"].copy()
    samples["lens"][1, 2, 2, 0] = np.inf
    frame.samples = samples
    safe, counts = sanitize_frame(frame)
    assert counts == {"albedo": 3, "samples.lens": 1}
    assert safe.reference is None and frame.reference is not None
    assert all(not a.flags.writeable for a in safe.buffers.values())
    assert all(not a.flags.writeable for a in safe.samples.values())
    assert np.isfinite(safe.buffers["albedo"]).all() and np.isfinite(safe.samples["lens"]).all()
    # identity does not need per-sample data: it gets none, so only the buffers' values count
    result = run_frame(load_denoiser("identity"), frame)
    assert result.ok and result.sanitized_total == 3
    assert sanitize_frame(frame, samples=False)[0].samples is None


def test_sequences_reset_first_and_a_failing_reset_fails_the_sequence():
    events = []

    class Temporal:
        name = "temporal"
        temporal = True

        def reset(self):
            events.append("reset")

        def denoise(self, frame):
            events.append(frame.index)
            return np.array(frame.color, np.float32)

    sequence = synthetic_sequence("shapes", 8, 8, 2, frames=3, seed=5)
    results = run_sequence(Temporal(), sequence)
    assert events == ["reset", 0, 1, 2] and all(r.ok for r in results)

    class BadReset(Temporal):
        def reset(self):
            raise ValueError("no state")

    results = run_sequence(BadReset(), sequence)
    assert [r.status for r in results] == [STATUS_FAILED] * 3 and "reset() raised ValueError" in results[0].error


def test_one_frame_sequence_of_a_plain_list():
    frame = synthetic_frame("shapes", 5, 7, 1, samples=False)
    results = run_sequence(load_denoiser("identity"), [frame])
    assert len(results) == 1 and results[0].ok
    np.testing.assert_array_equal(results[0].output, frame.color)
