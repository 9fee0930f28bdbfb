"""``--executor ray``: measure the sequences of a run as Ray tasks, one task per (scene, spp).

Each task opens the dataset itself, constructs its denoisers from their specs (instances do not
travel between processes) and returns its units; the driver writes them to the store, one
transaction per unit, as they arrive (:func:`ray.wait`), so a kill keeps everything finished.

Notes
-----
* Ray is imported inside :func:`run_ray` only: it takes seconds to import and to start.
* Without a running cluster ``ray.init()`` starts a local one with one worker per core. Denoise
  times are then measured while other tasks share the machine: on a small machine prefer the
  local executor for timings that will be compared.
* Only ``noisy`` and denoisers that loaded in the driver are sent; a denoiser that fails to load
  in a worker fails its units with that error (and those of the sampler pairs it is in).
* The plan travels as :func:`light_plan`: the same plan with every denoiser's instance left
  behind, every other field (``trained_scenes``, the sampler pairs) kept.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from denoisebench.benchmark.runner import BenchmarkConfig, RunPlan, measure_group, pending_groups
from denoisebench.dataset import Dataset, open_dataset
from denoisebench.denoisers import isolation as isolation_mod
from denoisebench.results.names import NOISY
from denoisebench.results.records import UnitRecord
from denoisebench.results.store import ResultsStore

# Lazy imports: Ray (optional, 0.4 s) only when a run uses the Ray executor.


def light_plan(plan: RunPlan) -> RunPlan:
    """``plan`` without its denoiser instances (they stay in the driver; tasks load their own)."""
    return replace(plan, denoisers=[replace(d, instance=None) for d in plan.denoisers])


def needed_denoisers(plan: RunPlan, labels: list[str]) -> set[str]:
    """Labels of the denoisers a task measuring ``labels`` must load: those among them, and the
    denoiser of every sampler pair among them."""
    pairs = {p.label: p.denoiser for p in plan.samplers}
    return {label for label in labels if label not in pairs} | {pairs[label] for label in labels if pairs.get(label)}


def _measure_remote(
    root: str,
    plan: RunPlan,
    options: dict,
    scene: str,
    spp: int,
    labels: list[str],
    isolation: str = "plugins",
    limits=None,
) -> list[UnitRecord]:

    instances: dict[str, object] = {}
    errors: dict[str, str] = {}
    needed = needed_denoisers(plan, labels)
    for d in plan.denoisers:
        if d.label in needed and d.label != NOISY:
            try:
                # plugins in worker processes of their own here too (a Ray task is no sandbox)
                instances[d.label] = isolation_mod.load(
                    d.spec, options.get(d.spec, {}), policy=isolation, limits=limits
                )
            except Exception as exc:  # noqa: BLE001 - recorded as the units' failure
                errors[d.label] = f"load in worker: {exc}"
    pairs = {p.label: p.denoiser for p in plan.samplers}
    failed = {label: errors.get(pairs.get(label, label)) for label in labels if errors.get(pairs.get(label, label))}
    units = list(
        measure_group(
            open_dataset(root), plan, scene, spp=spp, labels=[l for l in labels if l not in failed], instances=instances
        )
    )
    for label, error in failed.items():
        units.append(UnitRecord(denoiser=label, scene=scene, spp=spp, status="failed", error=error, frames=[]))
    return units


def run_ray(
    dataset: Dataset,
    plan: RunPlan,
    store: ResultsStore,
    config: BenchmarkConfig,
    on_unit: Callable[[UnitRecord, bool], None],
) -> None:
    import ray

    if not ray.is_initialized():
        ray.init(include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    light = light_plan(plan)  # instances stay in the driver
    task = ray.remote(_measure_remote)
    root = str(dataset.root.resolve())
    pending = [
        task.remote(root, light, config.options, scene, spp, labels, config.isolation, config.limits())
        for scene, spp, labels in pending_groups(plan, store.done_units(plan.run_id))
    ]
    while pending:
        ready, pending = ray.wait(pending, num_returns=1)
        for unit in ray.get(ready[0]):
            on_unit(unit, store.write_unit(plan.run_id, unit))
