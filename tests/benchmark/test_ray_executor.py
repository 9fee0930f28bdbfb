"""`run_benchmark(executor="ray")`: the same units and scores as the local executor, plugins isolated.

The Ray executor rebuilds every denoiser inside its tasks (instances never travel), so this checks
that a built-in, an isolated plugin and a plugin that ends its process give in Ray exactly what
they give locally: identical metric values, and the exiting plugin recorded as failed with its
reason while the run finishes.
"""

from __future__ import annotations

import textwrap

import pytest

from denoisebench.benchmark.run import run_benchmark
from denoisebench.benchmark.runner import BenchmarkConfig
from denoisebench.dataset import open_dataset
from denoisebench.dataset.synthetic import make_synthetic_dataset
from denoisebench.results.store import ResultsStore

PLUGIN = textwrap.dedent(
    """
    import os
    import numpy as np

    class Copy:
        name = "copy"
        needs = frozenset({"color"})
        temporal = False
        def reset(self):
            pass
        def denoise(self, frame):
            return np.asarray(frame.buffers["color"], np.float32) * np.float32(0.5)

    class Exits(Copy):
        name = "exits"
        def denoise(self, frame):
            os._exit(3)
    """
)


def _scores(store: ResultsStore, run_id: str) -> tuple[dict, dict]:
    units = {(u.denoiser, u.scene, u.spp): u.status for u in store.units(run_id)}
    values = {
        (f.denoiser, f.scene, f.spp, f.frame, name): value
        for f in store.frames(run_id)
        for name, value in f.metrics.items()
    }
    return units, values


@pytest.mark.slow
def test_ray_executor_scores_like_local_and_contains_an_exiting_plugin(tmp_path):
    ray = pytest.importorskip("ray")
    plugin = tmp_path / "plug.py"
    plugin.write_text(PLUGIN)
    data = open_dataset(make_synthetic_dataset(tmp_path / "ds", scenes=2, frames=2, height=16, width=16, spp=(2,)))
    config = BenchmarkConfig(
        denoisers=["identity", "cross_bilateral_fast", f"{plugin}:Copy", f"{plugin}:Exits"],
        spp=[2],
        metrics=["relmse", "ssim"],
        split="all",
    )
    results = {}
    ray.init(address="local", num_cpus=2, include_dashboard=False, log_to_driver=False, configure_logging=False)
    try:
        for executor in ("local", "ray"):
            with ResultsStore(tmp_path / f"{executor}.sqlite") as store:
                plan = run_benchmark(data, config, store, executor=executor, progress=False)
                results[executor] = _scores(store, plan.run_id)
    finally:
        ray.shutdown()  # other tests start Ray themselves
    local_units, local_values = results["local"]
    ray_units, ray_values = results["ray"]
    assert ray_units == local_units
    assert {label for label, _, _ in ray_units} == {"noisy", "identity", "cross_bilateral_fast", "copy", "exits"}
    assert {status for (label, _, _), status in ray_units.items() if label == "exits"} == {"failed"}
    assert {status for (label, _, _), status in ray_units.items() if label != "exits"} == {"ok"}
    assert ray_values.keys() == local_values.keys() and ray_values
    for key, value in local_values.items():
        assert ray_values[key] == pytest.approx(value, rel=1e-6, abs=1e-12), key
