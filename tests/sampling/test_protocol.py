"""The sampling harness: budgets enforced and recorded, requests checked, the synthetic frame, the registry."""

from __future__ import annotations

import time
from importlib.metadata import EntryPoint

import numpy as np
import pytest

from denoisebench.errors import UserInputError
from denoisebench.sampling import registry
from denoisebench.sampling.allocation import allocate, luminance_var, round_sums
from denoisebench.sampling.harness import run_sampler
from denoisebench.sampling.protocol import Budget
from denoisebench.sampling.synthetic import RoundBuffers, SyntheticProgressiveFrame, constant, noisy_half


class Greedy:
    """Asks for ``factor`` times the budget in one round, then once more."""

    name = "greedy"

    def __init__(self, factor=2.0, weights=None):
        self.factor, self.weights, self.second_error = factor, weights, None

    def sample(self, budget, rounds):
        weights = np.ones((rounds.height, rounds.width)) if self.weights is None else self.weights
        self.request = allocate(weights, int(self.factor * budget.total_samples(rounds.pixels)))
        rounds.render(self.request)
        assert rounds.cut and rounds.exhausted and rounds.remaining_samples() == 0
        rounds.render(np.ones((rounds.height, rounds.width), dtype=int))


class Scripted:
    """Renders the given requests in turn, optionally sleeping between them."""

    name = "scripted"

    def __init__(self, *requests, pause=0.0):
        self.requests, self.pause = requests, pause

    def sample(self, budget, rounds):
        for request in self.requests:
            time.sleep(self.pause)
            rounds.render(request)
        time.sleep(self.pause)


class Costed:
    """A frame whose rounds cost ``per_sample`` seconds each (reported, not spent)."""

    def __init__(self, frame, per_sample):
        self.frame, self.per_sample = frame, per_sample
        self.width, self.height = frame.width, frame.height

    def render_round(self, counts):
        result = self.frame.render_round(counts)
        return RoundBuffers(result.buffers, result.counts, float(counts.sum()) * self.per_sample, result.samples)


def test_allocate_is_exact_proportional_and_never_above_a_request_it_cuts():
    rng = np.random.default_rng(3)
    for _ in range(50):
        request = rng.integers(0, 9, size=(7, 5))
        total = int(request.sum())
        for keep in (1, total // 3, total - 1, total):
            granted = allocate(request, keep)
            assert granted.sum() == keep and (granted >= 0).all()
            assert (granted <= request).all()
            assert (np.abs(granted - request * keep / total) < 1 + 1e-9).all()
    spread = allocate(np.zeros((3, 4)), 14)  # no weight anywhere: uniform
    assert spread.sum() == 14 and set(spread.ravel()) == {1, 2}
    weights = rng.random((6, 6))
    assert np.array_equal(allocate(weights, 100), allocate(weights.copy(), 100))


def test_round_sums_recovers_what_a_round_added():
    frame = constant(4, 3, noise=0.5)
    first = frame.render_round(np.full((3, 4), 2))
    mean1 = first.buffers["color"].astype(np.float64)
    second = frame.render_round(np.arange(12).reshape(3, 4) % 3 + 1)
    added = round_sums(mean1, first.counts, second.buffers["color"], second.counts)
    total = second.buffers["color"].astype(np.float64) * second.counts[..., None]
    np.testing.assert_allclose(added + mean1 * 2, total, rtol=1e-5)


def test_budget_must_be_one_positive_number():
    for kwargs in ({}, {"spp": 4, "seconds": 1.0}, {"spp": 0}, {"seconds": -1.0}, {"spp": float("nan")}):
        with pytest.raises(UserInputError):
            Budget(**kwargs)
    assert Budget(spp=8).total_samples(100) == 800 and Budget(seconds=2).total_samples(100) is None


def test_a_sampler_asking_for_more_is_cut_to_the_budget_and_told_so():
    frame = noisy_half(16, 8)
    weights = np.linspace(1, 5, 128).reshape(8, 16)
    sampler = Greedy(2.5, weights)
    result = run_sampler(sampler, frame, Budget(spp=6))
    assert result.samples == 6 * 128 == result.budget_samples
    assert result.stopped == "budget" and result.cut and result.error is None
    assert len(result.rounds) == 1 and result.rounds[0].requested == sampler.request.sum()
    assert (result.spp <= sampler.request).all()
    np.testing.assert_array_equal(result.rounds[0].counts, result.spp)
    np.testing.assert_array_equal(result.buffers["color"], frame._buffers()["color"])


@pytest.mark.parametrize(
    "request_map, message",
    [
        (np.ones((3, 3), dtype=int), "map"),
        (-np.ones((4, 4), dtype=int), "non-negative"),
        (np.full((4, 4), 1.5), "whole numbers"),
        (np.zeros((4, 4), dtype=int), "no samples"),
        (np.full((4, 4), np.nan), "whole numbers"),
    ],
)
def test_malformed_requests_are_refused_and_recorded(request_map, message):
    result = run_sampler(Scripted(np.ones((4, 4), dtype=int), request_map), constant(4, 4), Budget(spp=8))
    assert result.stopped == "error" and message in result.error
    assert result.samples == 16 and len(result.rounds) == 1


def test_rounds_are_recorded_with_their_decision_time():
    first, second = np.full((4, 4), 2), np.eye(4, dtype=int) * 3
    result = run_sampler(Scripted(first, second, pause=0.02), constant(4, 4, noise=0.2), Budget(spp=8))
    assert result.stopped == "sampler" and result.samples == 32 + 12
    assert [r.granted for r in result.rounds] == [32, 12] and not result.cut
    np.testing.assert_array_equal(result.spp, first + second)
    assert all(r.decision_seconds >= 0.02 for r in result.rounds) and result.final_decision_seconds >= 0.02
    assert result.seconds == pytest.approx(result.render_seconds + result.decision_seconds)
    summary = result.summary()
    assert summary["samples"] == 44 and len(summary["rounds"]) == 2 and summary["pixels_without_samples"] == 0


def test_the_sampler_sees_read_only_buffers_and_cannot_change_the_result():
    class Vandal:
        def sample(self, budget, rounds):
            latest = rounds.render(np.full((rounds.height, rounds.width), 4))
            latest.buffers["color"][:] = 0.0

    result = run_sampler(Vandal(), constant(4, 4), Budget(spp=4))
    assert result.stopped == "error" and "read-only" in result.error
    assert np.all(result.buffers["color"] == 0.5) and result.sampler == "unnamed"


def test_a_seconds_budget_counts_render_and_decision_time():
    ticks = iter(np.arange(0, 100, 0.01))  # each clock read advances 10 ms of "decision"
    frame = Costed(constant(16, 16, noise=0.3), per_sample=1e-4)
    result = run_sampler(registry.load_sampler("uniform"), frame, Budget(seconds=1.0), clock=lambda: next(ticks))
    assert result.rounds[0].granted == 256  # the probe: one sample per pixel
    assert result.seconds <= 1.0 + 0.02 and result.seconds >= 0.95
    assert result.decision_seconds > 0 and result.samples < 10_000  # decision time took its share


def test_no_rounds_leave_every_pixel_without_a_sample():
    class Idle:
        def sample(self, budget, rounds):
            pass

    result = run_sampler(Idle(), constant(5, 3), Budget(spp=2))
    assert result.pixels_without_samples == 15 and result.stopped == "sampler" and result.samples == 0


def test_synthetic_frame_is_unbiased_deterministic_and_its_variance_is_right():
    truth = np.random.default_rng(0).uniform(0.1, 2.0, size=(48, 48, 3))
    noise = np.full((48, 48), 0.8)
    frames = [SyntheticProgressiveFrame(truth, noise, seed=5) for _ in range(2)]
    counts = np.full((48, 48), 8)
    a, b = (f.render_round(counts) for f in frames)
    np.testing.assert_array_equal(a.buffers["color"], b.buffers["color"])
    c = frames[0].render_round(counts)
    assert not np.array_equal(c.buffers["color"], a.buffers["color"])  # a new round draws new samples
    expected = frames[0].expected_var(c.counts)
    deviation = (c.buffers["color"] - truth) / np.sqrt(expected)
    assert abs(deviation.mean()) < 4 / np.sqrt(48 * 48)  # 4 SE; grey noise: the three channels move together
    assert c.buffers["color_var"].mean() / expected.mean() == pytest.approx(1.0, abs=0.1)
    np.testing.assert_allclose(c.buffers["diffuse"] + c.buffers["specular"], c.buffers["color"], rtol=1e-5)
    lum_truth = truth @ [0.212671, 0.715160, 0.072169]
    expected_lum_var = lum_truth**2 * noise**2 / c.counts  # grey noise: the upper bound is the variance
    assert luminance_var(c.buffers).mean() / expected_lum_var.mean() == pytest.approx(1.0, abs=0.1)


def test_registry_finds_builtins_entry_points_module_attr_and_files(tmp_path, monkeypatch):
    assert set(registry.BUILTINS) == {"uniform", "ci_stop", "dual_buffer", "hachisuka2008", "mdas"}
    for name in registry.BUILTINS:
        assert registry.load_sampler(name).name == name
    assert registry.load_sampler("ci_stop", max_error=0.1).max_error == 0.1
    with pytest.raises(registry.SamplerLoadError, match="no option 'radius'"):
        registry.load_sampler("ci_stop", radius=3)
    with pytest.raises(registry.UnknownSamplerError, match="known: uniform"):
        registry.load_sampler("nope")
    assert registry.load_sampler("denoisebench.sampling.uniform:Uniform").name == "uniform"
    plugin = tmp_path / "mine.py"
    plugin.write_text("class Mine:\n    def sample(self, budget, rounds):\n        pass\nready = Mine()\nnot_one = 3\n")
    assert registry.load_sampler(f"{plugin}:Mine").name == f"{plugin}:Mine"
    assert registry.load_sampler(f"{plugin}:ready") is not None
    with pytest.raises(registry.SamplerLoadError, match="ready instance"):
        registry.load_sampler(f"{plugin}:ready", x=1)
    with pytest.raises(registry.SamplerLoadError, match="not a sampler"):
        registry.load_sampler(f"{plugin}:not_one")
    with pytest.raises(registry.UnknownSamplerError, match="no such sampler file"):
        registry.load_sampler("missing.py:X")
    point = EntryPoint("plugged", "denoisebench.sampling.hachisuka:Hachisuka2008", registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "_entry_points", lambda: {"plugged": point, "uniform": point})
    assert registry.load_sampler("plugged", rounds=2).rounds == 2
    assert registry.load_sampler("uniform").name == "uniform"  # a built-in wins over an entry point
    assert "plugged" in registry.available_samplers()


def test_synthetic_frame_matches_the_renderers_conventions_for_empty_pixels_and_samples():
    frame = SyntheticProgressiveFrame(np.full((2, 3, 3), 0.4), np.full((2, 3), 0.5), keep_samples=True)
    counts = np.array([[0, 1, 3], [2, 0, 1]])
    result = frame.render_round(counts)
    var = result.buffers["color_var"][..., 0]
    assert np.isinf(var[counts == 0]).all() and (var[counts == 1] == 0).all() and (var[counts > 1] > 0).all()
    assert (result.buffers["color"][counts == 0] == 0).all()
    samples = result.samples["color"]
    assert samples.shape == (3, 2, 3, 3)
    assert ((samples[..., 0] > 0).sum(axis=0) == counts).all()  # row j < count holds a sample, zeros after
    np.testing.assert_allclose(
        samples.sum(axis=0) / np.maximum(counts, 1)[..., None], result.buffers["color"], rtol=1e-5
    )
