"""Adaptive references: round statistics, the floor estimate, the stopping rule (no rendering here).

Rounds are synthetic: per-pixel samples drawn with numpy, summarised as the renderer summarises a
render (mean and variance of the mean per pixel), so every merged statistic has an exact peer
computed from the concatenated samples. The estimator is checked over many draws against the true
variance of the mean, including a heavy-tailed (firefly) distribution.
"""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.generator.render.reference import (
    MAX_ROUNDS,
    MIN_ROUNDS,
    RoundMerger,
    floor_of,
    render_adaptive,
    round_schedule,
    round_seed,
)


def summarise(samples: np.ndarray) -> dict:
    """What the renderer returns for samples S×H×W×3: the mean and the variance of the mean (0 at 1 spp)."""
    n = samples.shape[0]
    var = samples.var(axis=0, ddof=1) / n if n > 1 else np.zeros(samples.shape[1:])
    return {"color": samples.mean(axis=0), "color_var": var}


def test_merged_statistics_equal_those_of_the_concatenated_samples():
    rng = np.random.default_rng(0)
    rounds = [rng.gamma(0.5, 2.0, size=(8, 5, 6, 3)) for _ in range(5)]
    merger = RoundMerger(8)
    for r in rounds:
        merger.add(summarise(r))
    everything = np.concatenate(rounds)
    assert merger.spp == 40 and merger.rounds == 5
    np.testing.assert_allclose(merger.mean(), everything.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(merger.pooled_var(), everything.var(axis=0, ddof=1) / 40, rtol=1e-10)
    means = np.stack([r.mean(axis=0) for r in rounds])
    np.testing.assert_allclose(merger.batch_var(), means.var(axis=0, ddof=1) / 5, rtol=1e-10)
    out = merger.buffers()
    assert out["color"].dtype == np.float32 and set(out) == {"color", "color_var", "color_half"}
    robust, pooled = merger.floors()
    assert pooled == pytest.approx(floor_of(merger.mean(), merger.pooled_var()))
    assert robust == max(pooled, floor_of(merger.mean(), merger.batch_var()))


def test_one_sample_rounds_use_the_spread_of_the_rounds():
    """At 1 spp per round the renderer reports no variance; the pooled estimate is then the batch one."""
    rng = np.random.default_rng(1)
    rounds = rng.normal(1.0, 0.3, size=(16, 1, 4, 4, 3))
    merger = RoundMerger(1)
    for r in rounds:
        merger.add(summarise(r))
    np.testing.assert_allclose(merger.pooled_var(), rounds[:, 0].var(axis=0, ddof=1) / 16, rtol=1e-10)
    np.testing.assert_allclose(merger.pooled_var(), merger.batch_var(), rtol=1e-10)


@pytest.mark.parametrize("kind", ["gaussian", "fireflies"])
def test_floor_estimate_is_unbiased_and_conservative_over_many_draws(kind):
    """Over 300 independent references the estimate's average matches the true floor (the variance of
    the mean against the true image, a known number here) within its standard error; with fireflies
    (a 1-in-200 sample 300x brighter) the robust estimate is never below the pooled one and its average
    is not below the truth by more than noise."""
    rng = np.random.default_rng(2 if kind == "gaussian" else 3)
    round_spp, k, shape = 16, MIN_ROUNDS, (8, 8, 3)
    if kind == "gaussian":
        mu, sigma2 = 0.5, 0.04
        draw = lambda size: rng.normal(mu, np.sqrt(sigma2), size)  # noqa: E731
    else:
        p, big, base = 1 / 200, 300.0, 0.2
        mu = base + p * big
        sigma2 = p * (1 - p) * big**2
        draw = lambda size: base + big * (rng.random(size) < p)  # noqa: E731
    n = round_spp * k
    # With the denominator at the true mean: the floor a perfect denoiser scores in expectation.
    truth = sigma2 / n / (mu**2 + 0.01)
    robust, pooled = [], []
    for _ in range(300):
        merger = RoundMerger(round_spp)
        for _ in range(k):
            merger.add(summarise(draw((round_spp, *shape))))
        mean = np.full(shape, mu)
        robust.append(max(floor_of(mean, merger.pooled_var()), floor_of(mean, merger.batch_var())))
        pooled.append(floor_of(mean, merger.pooled_var()))
    robust, pooled = np.array(robust), np.array(pooled)
    assert np.all(robust >= pooled)
    se = pooled.std(ddof=1) / np.sqrt(len(pooled))
    assert abs(pooled.mean() - truth) < 4 * se, (pooled.mean(), truth, se)
    assert robust.mean() > truth - 4 * se


def test_render_adaptive_stops_at_the_target_or_the_cap_and_names_it():
    rng_seed = 5

    def make_round(sigma):
        def render_round(index, round_spp):
            rng = np.random.default_rng([rng_seed, index])  # fresh, deterministic per round
            return summarise(rng.normal(1.0, sigma, size=(round_spp, 6, 6, 3))), 0.5, 0.1

        return render_round

    # Noise sigma 1 at N spp has a floor ≈ 1 / (N · 1.01): a target of 1e-3 needs ~990 spp.
    easy = render_adaptive(make_round(1.0), cap=4096, ref_error=1e-3)
    assert not easy.record["stopped_at_cap"] and easy.record["floor"] <= 1e-3
    round_spp, max_rounds = round_schedule(4096)
    assert easy.spp % round_spp == 0 and MIN_ROUNDS * round_spp <= easy.spp <= 1536
    assert easy.seconds == pytest.approx(0.5 * easy.record["rounds"]) and easy.compile_seconds == pytest.approx(
        0.1 * easy.record["rounds"]
    )
    again = render_adaptive(make_round(1.0), cap=4096, ref_error=1e-3)
    assert again.record == easy.record
    assert all(np.array_equal(again.buffers[k], easy.buffers[k]) for k in easy.buffers)

    hard = render_adaptive(make_round(1.0), cap=256, ref_error=1e-4)
    assert hard.record["stopped_at_cap"] and hard.spp == 256 and hard.record["rounds"] == MAX_ROUNDS
    assert hard.record["floor"] > 1e-4
    single = render_adaptive(make_round(1.0), cap=1, ref_error=1.0)  # 1 spp: no variance, no floor
    assert single.spp == 1 and single.record["floor"] is None and single.record["stopped_at_cap"]
    with pytest.raises(ValueError, match="ref_error"):
        render_adaptive(make_round(1.0), cap=256, ref_error=0.0)


def test_round_schedule_and_seeds():
    assert round_schedule(4096) == (4096 // MAX_ROUNDS, MAX_ROUNDS)
    assert round_schedule(1000) == (15, MAX_ROUNDS)  # the cap rounded down to whole rounds: 960
    assert round_schedule(5) == (1, 5)
    with pytest.raises(ValueError):
        round_schedule(0)
    seeds = {round_seed(7, f, k) for f in range(4) for k in range(MAX_ROUNDS)}
    assert len(seeds) == 4 * MAX_ROUNDS and all(0 <= s < 2**32 for s in seeds)
    assert round_seed(7, 1, 2) == round_seed(7, 1, 2) != round_seed(8, 1, 2)


def test_a_floor_estimate_still_rising_does_not_stop_the_loop():
    """spp × floor growing with the rounds (bright paths still being found) is not trusted to stop on.
    Steady: each round's variance the same, the floor falls as 1/rounds and the loop stops once it is
    <= the target. Rising: round k's variance ∝ sqrt(k + 1), so the floor falls only as 1/sqrt(rounds)
    (growth sqrt(2) ≈ 1.41): the target is met after ~28 rounds, but the loop runs to the cap."""
    from denoisebench.generator.render.reference import GROWTH_WARNING, floor_growth

    a = 1e-3

    def make_round(rising):
        def render_round(index, round_spp):
            per_round_var = a * (np.sqrt(index + 1) if rising else 1.0)  # variance of this round's mean
            return {"color": np.ones((4, 4, 3)), "color_var": np.full((4, 4, 3), per_round_var)}, 0.1, 0.0

        return render_round

    steady = render_adaptive(make_round(False), cap=1024, ref_error=a / 8)
    assert 2 * MIN_ROUNDS <= steady.record["rounds"] <= 10 and steady.record["floor_growth"] == pytest.approx(
        1.0, abs=0.05
    )
    rising = render_adaptive(make_round(True), cap=1024, ref_error=a / 8)
    assert rising.record["rounds"] == MAX_ROUNDS and rising.record["floor_growth"] > GROWTH_WARNING
    assert rising.record["floor"] <= a / 8  # met long before the cap, but never trusted
    assert floor_growth([1.0]) is None and floor_growth([0.5, 0.25]) == pytest.approx(1.0)
