"""Samplers rendered live on a dataset's own scene through the progressive renderer (16×16 px)."""

from __future__ import annotations

import numpy as np
import pytest

from denoisebench.cli import main
from denoisebench.dataset import open_dataset
from denoisebench.sampling.live import LiveScene, live_seed, run_live
from denoisebench.sampling.protocol import Budget
from denoisebench.sampling.registry import BUILTINS, load_sampler
from tests.support.paths import REPO

SIZE = 16
EXAMPLE = REPO / "examples/denoisebench-example-sampler/src/denoisebench_example_sampler/__init__.py"


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    out = tmp_path_factory.mktemp("live") / "ds"
    args = ["--families", "cornell", "--scenes", "1", "--frames", "1", "--width", str(SIZE), "--height", str(SIZE)]
    assert main(["generate", "--out", str(out), *args, "--spp", "4", "--ref-spp", "64", "--seed", "5", "--quiet"]) == 0
    data = open_dataset(out)
    scene = data.scenes[0]
    return data, scene, LiveScene.from_dataset(data, scene)


def test_live_frames_take_the_datasets_stage_plan_and_size_with_a_seed_of_their_own(live):
    data, scene, frames = live
    record = data.scene(scene, renders=False).record
    assert (frames.width, frames.height) == (SIZE, SIZE) and frames.plan.to_dict() == record["plan"]
    assert live_seed(record["render_seed"]) != record["render_seed"]
    one = run_live(load_sampler("uniform"), frames, 0, Budget(spp=4))
    two = run_live(load_sampler("uniform"), frames, 0, Budget(spp=4))
    np.testing.assert_array_equal(one.buffers["color"], two.buffers["color"])  # common random numbers
    stored = data.frame(scene, 4, 0).buffers["color"]
    assert not np.array_equal(one.buffers["color"], stored)  # not the stored input's samples
    reference = data.reference(scene, 0)[0]["color"]
    for image in (one.buffers["color"], stored):  # both unbiased estimates of the same image
        assert abs(image.mean() - reference.mean()) < 0.15 * reference.mean()
    assert {"color", "diffuse", "specular", *record["plan"]["features"]} <= set(one.buffers)


@pytest.mark.parametrize("name", sorted(BUILTINS))
def test_every_builtin_spends_its_budget_on_the_live_frame(live, name):
    _, _, frames = live
    result = run_live(load_sampler(name), frames, 0, Budget(spp=8))
    assert result.error is None, result.error
    assert 0.99 * result.budget_samples <= result.samples <= result.budget_samples
    assert result.pixels_without_samples == 0 and result.render_seconds > 0
    assert np.isfinite(result.buffers["color"]).all() and result.buffers["color"].shape == (SIZE, SIZE, 3)
    np.testing.assert_array_equal(sum(r.counts for r in result.rounds), result.spp)


def test_an_unknown_scene_is_one_line_bad_input(live):
    from denoisebench.errors import UserInputError

    data, _, _ = live
    with pytest.raises(UserInputError):
        LiveScene.from_dataset(data, "no_such_scene")


def test_the_benchmark_measures_sampler_denoiser_pairs_live(live, tmp_path):
    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.results.store import ResultsStore

    data, scene, _ = live
    plugin = f"{EXAMPLE}:PixelVariance"  # a file plugin: it runs in a worker of its own
    samplers = ["uniform", "hachisuka2008", plugin]
    config = BenchmarkConfig(
        denoisers=["identity"], spp=[4], split="all", metrics=["relmse"], samplers=samplers, verify=False
    )
    with ResultsStore(tmp_path / "r.sqlite") as store:
        plan = run_benchmark(data, config, store, progress=False)
        units = {u.denoiser: u for u in store.units(plan.run_id)}
        kinds = {d.label: d.kind for d in store.denoisers(plan.run_id)}
        frames = {f.denoiser: f for f in store.frames(plan.run_id)}
    pairs = {"uniform", "uniform+identity", "hachisuka2008", "hachisuka2008+identity", plugin, f"{plugin}+identity"}
    assert set(units) == {"noisy", "identity"} | pairs and config.as_dict()["samplers"] == samplers
    assert all(units[label].status == "ok" for label in units) and {kinds[p] for p in pairs} == {"sampler"}
    # identity returns its input: a pair with it scores as the sampler alone; the live image is not the stored one
    assert frames["uniform+identity"].metrics["relmse"] == pytest.approx(frames["uniform"].metrics["relmse"])
    assert frames["uniform"].metrics["relmse"] != pytest.approx(frames["noisy"].metrics["relmse"], rel=1e-6)
    assert frames["hachisuka2008"].render_seconds > 0


def test_the_benchmark_refuses_an_unknown_sampler_before_any_work(live, tmp_path):
    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.results.store import ResultsStore
    from denoisebench.sampling.registry import UnknownSamplerError

    data, _, _ = live
    with ResultsStore(tmp_path / "r.sqlite") as store:
        with pytest.raises(UnknownSamplerError):
            config = BenchmarkConfig(denoisers=["identity"], spp=[4], split="all", samplers=["nope"])
            run_benchmark(data, config, store, progress=False)
        assert not store.runs()
