"""Plugin samplers in a worker process: same results as in-process, exits, hangs and bad requests contained."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from denoisebench.plugins import Limits
from denoisebench.sampling import synthetic
from denoisebench.sampling.harness import run_sampler
from denoisebench.sampling.isolation import IsolatedSampler, isolated, load
from denoisebench.sampling.protocol import Budget
from denoisebench.sampling.registry import SamplerLoadError, UnknownSamplerError

PLUGINS = '''
import os, time
import numpy as np
from denoisebench.sampling.allocation import allocate, luminance_var

class Variance:
    name = "variance"
    def sample(self, budget, rounds):
        latest = rounds.render(np.full((rounds.height, rounds.width), 2))
        while rounds.remaining_samples() > 0 and not rounds.cut:
            weights = np.sqrt(luminance_var(latest.buffers) * rounds.counts)
            latest = rounds.render(allocate(weights, min(rounds.remaining_samples(), rounds.pixels * 3)))

class Greedy:
    def sample(self, budget, rounds):
        rounds.render(np.full((rounds.height, rounds.width), 1000))
        rounds.render(np.ones((rounds.height, rounds.width), dtype=int))

class Exits:
    def sample(self, budget, rounds):
        rounds.render(np.ones((rounds.height, rounds.width), dtype=int))
        os._exit(3)

class Hangs:
    def sample(self, budget, rounds):
        rounds.render(np.ones((rounds.height, rounds.width), dtype=int))
        time.sleep(60)

class WrongShape:
    def sample(self, budget, rounds):
        rounds.render(np.ones((3, 3), dtype=int))

class Broken:
    def __init__(self):
        raise RuntimeError("no such device")
'''


@pytest.fixture(scope="module")
def plugins(tmp_path_factory):
    path = tmp_path_factory.mktemp("samplers") / "plugins.py"
    path.write_text(textwrap.dedent(PLUGINS))
    return lambda name: f"{path}:{name}"


def test_an_isolated_sampler_gives_what_it_gives_in_process(plugins):
    assert isolated(plugins("Variance")) and not isolated("hachisuka2008") and isolated("uniform", "all")
    runs = [
        run_sampler(load(plugins("Variance"), policy=policy), synthetic.noisy_half(16, 8), Budget(spp=9))
        for policy in ("plugins", "none")
    ]
    assert runs[0].sampler == runs[1].sampler == "variance" and runs[0].error is None
    np.testing.assert_array_equal(runs[0].spp, runs[1].spp)
    np.testing.assert_array_equal(runs[0].buffers["color"], runs[1].buffers["color"])
    assert [r.granted for r in runs[0].rounds] == [r.granted for r in runs[1].rounds]


def test_a_greedy_isolated_sampler_is_cut_and_told(plugins):
    result = run_sampler(load(plugins("Greedy")), synthetic.constant(8, 8), Budget(spp=5))
    assert result.stopped == "budget" and result.samples == 5 * 64 and result.cut and result.error is None


def test_an_exit_fails_the_run_with_its_status_and_the_next_run_gets_a_fresh_worker(plugins):
    sampler = load(plugins("Exits"))
    for _ in range(2):
        result = run_sampler(sampler, synthetic.constant(8, 8), Budget(spp=4))
        assert result.stopped == "error" and "exited with status 3" in result.error
        assert result.samples == 64 and len(result.rounds) == 1  # what it rendered is kept


def test_a_hang_is_killed_at_the_time_limit_and_the_sampler_disabled(plugins):
    # the sandbox and numpy load well within the limit
    sampler = IsolatedSampler(plugins("Hangs"), limits=Limits(time_limit=3))
    first = run_sampler(sampler, synthetic.constant(8, 8), Budget(spp=4))
    assert first.stopped == "error" and "time limit" in first.error and first.samples == 64
    second = run_sampler(sampler, synthetic.constant(8, 8), Budget(spp=4))
    assert "disabled" in second.error and second.samples == 0


def test_bad_requests_and_load_failures_are_one_line(plugins):
    result = run_sampler(load(plugins("WrongShape")), synthetic.constant(8, 8), Budget(spp=4))
    assert result.stopped == "error" and "8×8" in result.error and result.samples == 0
    with pytest.raises(SamplerLoadError, match="no such device"):
        load(plugins("Broken"))
    with pytest.raises(UnknownSamplerError):
        load("no_such_module_here:Sampler")
