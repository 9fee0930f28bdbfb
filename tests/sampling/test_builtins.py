"""The built-in samplers on synthetic frames where the right allocation is known, and the convergence check."""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.sampling import synthetic
from denoisebench.sampling.allocation import luminance, luminance_var
from denoisebench.sampling.checks import convergence_check, format_check
from denoisebench.sampling.ci_stop import ConfidenceStop
from denoisebench.sampling.dual_buffer import DualBuffer
from denoisebench.sampling.harness import run_sampler
from denoisebench.sampling.protocol import Budget
from denoisebench.sampling.registry import BUILTINS, load_sampler
from denoisebench.sampling.schedule import uniform

ADAPTIVE = ("ci_stop", "dual_buffer", "hachisuka2008")


@pytest.mark.parametrize("name", ADAPTIVE)
def test_samples_go_to_the_noisy_half(name):
    frame = synthetic.noisy_half(32, 16, quiet=0.05, loud=1.0)
    result = run_sampler(load_sampler(name), frame, Budget(spp=16))
    quiet, loud = result.spp[:, :16].mean(), result.spp[:, 16:].mean()
    assert loud > 3 * quiet and result.pixels_without_samples == 0


def test_uniform_is_uniform_even_on_the_noisy_half():
    result = run_sampler(load_sampler("uniform"), synthetic.noisy_half(32, 16), Budget(spp=16))
    assert (result.spp == 16).all() and len(result.rounds) == 1


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_a_noise_free_constant_image_gets_uniform_samples(name):
    result = run_sampler(load_sampler(name), synthetic.constant(16, 16), Budget(spp=12))
    assert result.spp.max() - result.spp.min() <= 1 and result.samples == 12 * 256


@pytest.mark.parametrize("name", ADAPTIVE)
def test_a_uniformly_noisy_constant_image_gets_nearly_uniform_samples(name):
    result = run_sampler(load_sampler(name), synthetic.constant(32, 16, noise=0.5, seed=4), Budget(spp=16))
    spread = result.spp.std() / result.spp.mean()
    assert spread < 0.3 and result.spp[:, :16].mean() == pytest.approx(result.spp[:, 16:].mean(), rel=0.15)


@pytest.mark.parametrize("name", sorted(BUILTINS))
@pytest.mark.parametrize("spp", [2.5, 8, 16])
def test_every_builtin_spends_its_budget_within_one_percent(name, spp):
    frame = synthetic.check_frame(24, 20, seed=1)
    result = run_sampler(load_sampler(name), frame, Budget(spp=spp))
    assert result.error is None and result.samples <= result.budget_samples
    assert result.samples >= 0.99 * result.budget_samples, result.summary()
    assert result.pixels_without_samples == 0


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_every_builtin_is_deterministic(name):
    runs = [run_sampler(load_sampler(name), synthetic.check_frame(24, 16, seed=7), Budget(spp=10)) for _ in range(2)]
    np.testing.assert_array_equal(runs[0].spp, runs[1].spp)
    np.testing.assert_array_equal(runs[0].buffers["color"], runs[1].buffers["color"])
    assert [r.granted for r in runs[0].rounds] == [r.granted for r in runs[1].rounds]


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_every_builtin_converges_to_the_truth(name):
    outcome = convergence_check(lambda: load_sampler(name), name=name)
    assert outcome.passed, format_check(outcome)
    assert [b.spent for b in outcome.budgets] == pytest.approx([1.0, 1.0, 1.0], abs=0.01)


class LowStopper:
    """Biased on purpose: after 4 spp, stops every pixel whose mean came out below the image's median."""

    name = "low_stopper"

    def sample(self, budget, rounds):
        result = rounds.render(uniform(rounds, 4 * rounds.pixels))
        lum = luminance(result.buffers) / synthetic.check_frame(rounds.width, rounds.height).truth.mean(axis=2)
        keep = lum >= np.median(lum)
        while rounds.remaining_samples() > 0 and not rounds.cut:
            rounds.render(np.where(keep, max(rounds.remaining_samples() // int(keep.sum()), 1), 0))


class ColumnSkipper:
    """Never samples the first column."""

    name = "column_skipper"

    def sample(self, budget, rounds):
        weights = np.ones((rounds.height, rounds.width))
        weights[:, 0] = 0
        from denoisebench.sampling.allocation import allocate

        rounds.render(allocate(weights, rounds.remaining_samples()))


def test_the_convergence_check_catches_a_biased_sampler_and_skipped_pixels():
    biased = convergence_check(LowStopper, name="low_stopper")
    assert not biased.passed and any("relative bias" in reason for reason in biased.reasons)
    skipping = convergence_check(ColumnSkipper, name="column_skipper")
    assert not skipping.passed and any("without a sample" in reason for reason in skipping.reasons)
    assert "FAIL" in format_check(skipping)


def test_pixels_left_without_samples_are_counted():
    result = run_sampler(load_sampler("uniform"), synthetic.constant(8, 8), Budget(spp=0.5))
    assert result.pixels_without_samples == 32 and result.summary()["pixels_without_samples"] == 32


def test_ci_stop_is_mitsubas_rule_and_without_spend_all_stops_early():
    sampler = ConfidenceStop(max_error=0.05, p_value=0.05, spend_all=False)
    assert sampler.quantile == pytest.approx(1.959964, abs=1e-6)
    frame = synthetic.noisy_half(16, 8, quiet=0.01, loud=1.0)
    result = run_sampler(sampler, frame, Budget(spp=128))
    assert result.stopped == "sampler" and result.samples < result.budget_samples
    assert (result.spp[:, :8] == 4).all()  # 1 % noise per sample: converged after the first block
    assert (result.spp[:, 8:] == 4 * 32).sum() > 0.5 * 64  # the loud half runs to Mitsuba's 32× cap
    buffers = {"color": np.full((1, 3, 3), 1.0), "color_var": np.array([[[0.02**2] * 3, [0.03**2] * 3, [0.1] * 3]])}
    open_ = sampler.open_pixels(buffers, np.full((1, 3), 8), 0.05, cap=100)
    assert open_.tolist() == [[False, True, True]]  # half widths 0.039, 0.059, 0.62 against 0.05


def test_dual_buffer_error_map_estimates_the_variance_of_the_mean():
    sampler = DualBuffer(initial_spp=8, rounds=1, filter_radius=2)
    frame = synthetic.constant(32, 32, noise=0.7, seed=2)
    captured = {}
    original = sampler.error_map

    def spy(state):
        captured["var"], captured["lum2"] = original(state)
        captured["counts"] = state["a_n"] * 2
        return captured["var"], captured["lum2"]

    sampler.error_map = spy
    run_sampler(sampler, frame, Budget(spp=16))
    expected = (0.5 * 0.7) ** 2 / captured["counts"]
    assert captured["var"].mean() / expected.mean() == pytest.approx(1.0, abs=0.1)
    assert captured["lum2"].mean() == pytest.approx(0.25 + expected.mean(), rel=0.05)  # E[m²] = L² + var


def test_hachisuka_tree_partitions_the_image_and_refines_the_noisy_half():
    sampler = load_sampler("hachisuka2008")
    frame = synthetic.noisy_half(32, 16, quiet=0.02, loud=1.0)
    run_sampler(sampler, frame, Budget(spp=16))
    cover = np.zeros((16, 32), dtype=int)
    for y0, y1, x0, x1 in sampler.leaves.tolist():
        cover[y0:y1, x0:x1] += 1
    assert (cover == 1).all()
    loud = sum(1 for leaf in sampler.leaves if leaf[2] >= 16)
    assert loud > 2 * (len(sampler.leaves) - loud)


def test_luminance_helpers_read_color():
    buffers = {"color": np.ones((2, 2, 3)), "color_var": np.full((2, 2, 3), 4.0)}
    assert luminance(buffers) == pytest.approx(np.ones((2, 2)))
    assert luminance_var(buffers) == pytest.approx(np.full((2, 2), 4.0))


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_every_builtin_keeps_to_a_seconds_budget(name):
    from denoisebench.sampling.synthetic import RoundBuffers

    class Costed:  # rounds cost 10 µs per sample, reported exactly; the clock stands still (no decision time)
        def __init__(self, frame):
            self.frame, self.width, self.height = frame, frame.width, frame.height

        def render_round(self, counts):
            out = self.frame.render_round(counts)
            return RoundBuffers(out.buffers, out.counts, float(counts.sum()) * 1e-5, out.samples)

    result = run_sampler(
        load_sampler(name), Costed(synthetic.noisy_half(16, 16)), Budget(seconds=0.1), clock=lambda: 0.0
    )
    assert result.error is None and result.budget_samples is None
    assert 0.95 * 0.1 <= result.seconds <= 0.1 + 1e-9, result.summary()
    assert result.rounds[0].granted <= 256 and result.pixels_without_samples == 0  # the probe: <= 1 spp
    if name != "uniform":
        assert result.spp[:, 8:].mean() > 2 * result.spp[:, :8].mean()  # still adaptive under a time budget
