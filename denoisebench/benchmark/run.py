"""Run a benchmark: prepare the run, measure its missing units with an executor, finish it.

The one entry point of a benchmark (``run-benchmark``, ``denoisebench benchmark``, tests). It sits
above both executors, :func:`denoisebench.benchmark.runner.run_local` and
:func:`denoisebench.benchmark.ray_executor.run_ray`, so that neither of them imports the other's
module (the runner measures units; the Ray executor distributes the runner's groups).
"""

from __future__ import annotations

import sys

from tqdm import tqdm

from denoisebench.benchmark.ray_executor import run_ray
from denoisebench.benchmark.runner import BenchmarkConfig, RunPlan, prepare_run, run_local
from denoisebench.dataset import Dataset
from denoisebench.errors import UserInputError
from denoisebench.results.records import UnitRecord
from denoisebench.results.store import ResultsStore

#: Executors ``run_benchmark`` accepts.
EXECUTORS = ("local", "ray")


def run_benchmark(
    dataset: Dataset,
    config: BenchmarkConfig,
    store: ResultsStore,
    *,
    executor: str = "local",
    progress: bool = True,
) -> RunPlan:
    """Measure every missing unit of the run ``config`` describes; return its plan (with run_id)."""
    plan = prepare_run(dataset, config, store, progress=progress)
    for label, scenes in plan.trained_on().items():
        shown = ", ".join(scenes[:6]) + (f" and {len(scenes) - 6} more" if len(scenes) > 6 else "")
        print(
            f"warning: {label} was trained on {len(scenes)} of this run's {len(plan.scenes)} scene(s) ({shown}): "
            "its scores there are not held-out (the report marks them)",
            file=sys.stderr,
        )
    done = len(store.done_units(plan.run_id))
    bar = tqdm(
        total=plan.total_units,
        initial=min(done, plan.total_units),
        desc="benchmark: denoisers × sequences",
        unit="seq",
        file=sys.stderr,
        disable=not progress,
    )

    def on_unit(unit: UnitRecord, written: bool) -> None:
        bar.update(1)
        if unit.status != "ok" and written:
            bar.write(
                f"warning: {unit.denoiser} failed on {unit.scene} at {unit.spp} spp: {unit.error}", file=sys.stderr
            )

    try:
        if executor == "local":
            run_local(dataset, plan, store, on_unit=on_unit)
        elif executor == "ray":
            run_ray(dataset, plan, store, config=config, on_unit=on_unit)
        else:
            raise UserInputError(f"unknown executor {executor!r}; use one of {', '.join(EXECUTORS)}")
    finally:
        bar.close()
    if not plan.missing(store.done_units(plan.run_id)):
        store.finish_run(plan.run_id)
    return plan
