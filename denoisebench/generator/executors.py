"""Where frame jobs run: in this process (local) or spread over a Ray cluster.

Both executors take the same :class:`~denoisebench.generator.frame_jobs.FrameJob` list and yield one
outcome per job, a :class:`~denoisebench.generator.frame_jobs.RenderedJob` or a :class:`JobFailure`,
as the jobs finish; the caller writes results with the one dataset writer it owns. A failing job
never stops the others. An interrupt (SIGINT, SIGTERM: :mod:`denoisebench.interrupts`) stops them
all and is never a job's failure.

* :class:`LocalExecutor` renders the jobs one after another; each render uses every core through
  Dr.Jit's own thread pool, which beats several processes fighting over the same cores.
* :class:`RayExecutor` sends each job to a Ray task (``ray.init(address=...)``, or a local
  cluster when no address is given). The stage files travel with the job (one ``ray.put`` per
  scene), so workers need the denoisebench package but no shared file system; only the driver
  writes to ``OUT``. Each task asks Ray for ``cpus_per_task`` CPUs and limits Dr.Jit to as many
  threads, so that Ray's CPU accounting matches the threads actually used.

Notes:
    Results do not depend on the executor: a render's pixels are a function of the job alone (not
    of Dr.Jit's thread count or of which process renders it), and the writer sorts the manifest's
    keys, so the order in which jobs finish does not change a byte. ``test_generate_dataset``
    checks this against a real local Ray cluster.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

from denoisebench.errors import UserInputError, one_line
from denoisebench.generator.dataset_scenes import SceneSpec, read_stage_files
from denoisebench.generator.frame_jobs import FrameJob, RenderedJob, render_job
from denoisebench.interrupts import raise_if_requested
from denoisebench.mitsuba_runtime import load_mitsuba

# Lazy imports: Dr.Jit (after mitsuba_runtime has picked Mitsuba's variant) and Ray (an optional
# executor, 0.4 s) are imported inside the functions that use them.

EXECUTORS = ("local", "ray")


@dataclass
class JobFailure:
    """A job that raised: its scene, frame and a one-line reason."""

    scene: str
    frame: int
    message: str


def _run_guarded(job: FrameJob, stage_files=None, threads: int | None = None) -> RenderedJob | JobFailure:
    try:
        if threads:
            load_mitsuba()  # sets DRJIT_LIBLLVM_PATH before drjit's first import
            import drjit as dr

            dr.set_thread_count(int(threads))
        return render_job(job, stage_files)
    except Exception as error:  # one bad job must not take the others down
        raise_if_requested()  # Dr.Jit hands a KeyboardInterrupt back as RuntimeError: not the job's failure
        return JobFailure(job.scene, job.frame, one_line(error))


class LocalExecutor:
    """Run jobs in this process, in order."""

    name = "local"

    def run(self, jobs: Iterable[FrameJob], scenes: Mapping[str, SceneSpec]) -> Iterator[RenderedJob | JobFailure]:
        for job in jobs:
            outcome = _run_guarded(job)
            raise_if_requested()  # an interrupt Dr.Jit swallowed: the job's result is not kept
            yield outcome

    def close(self) -> None:
        pass


class RayExecutor:
    """Run jobs as Ray tasks on the cluster at ``address`` (None: start a local one).

    ``num_cpus`` sizes a local cluster (ignored with an address); ``cpus_per_task`` is both the
    CPUs each task reserves and the Dr.Jit threads it renders with.
    """

    name = "ray"

    def __init__(self, address: str | None = None, num_cpus: int | None = None, cpus_per_task: int = 1):
        try:
            import ray
        except ImportError:  # pragma: no cover - ray is pinned in requirements.txt
            raise UserInputError("--executor ray needs the 'ray' package (pip install ray)") from None
        if cpus_per_task < 1:
            raise UserInputError(f"--ray-cpus-per-task must be >= 1 (got {cpus_per_task})")
        self._ray = ray
        self._started = False
        if not ray.is_initialized():
            kwargs = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
            try:
                if address:
                    ray.init(address=address, **kwargs)
                else:
                    ray.init(num_cpus=num_cpus, **kwargs)
            except (ConnectionError, ValueError, RuntimeError) as error:
                raise UserInputError(
                    f"cannot start or reach a Ray cluster at {address or 'local'}: {one_line(error)}"
                ) from None
            self._started = True
        self.cpus_per_task = int(cpus_per_task)
        self._remote = ray.remote(num_cpus=self.cpus_per_task, max_retries=1)(_run_guarded)

    def run(self, jobs: Iterable[FrameJob], scenes: Mapping[str, SceneSpec]) -> Iterator[RenderedJob | JobFailure]:
        ray = self._ray
        jobs = list(jobs)
        total_cpus = int(ray.cluster_resources().get("CPU", 1))
        in_flight_limit = max(2, 2 * total_cpus // self.cpus_per_task)
        stage_refs: dict[str, object] = {}
        pending: dict[object, FrameJob] = {}
        queue = iter(jobs)

        def submit_next() -> bool:
            job = next(queue, None)
            if job is None:
                return False
            if job.stage_key not in stage_refs:
                stage_refs[job.stage_key] = ray.put(read_stage_files(scenes[job.scene]))
            ref = self._remote.remote(job, stage_refs[job.stage_key], self.cpus_per_task)
            pending[ref] = job
            return True

        while len(pending) < in_flight_limit and submit_next():
            pass
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            ref = done[0]
            job = pending.pop(ref)
            try:
                yield ray.get(ref)
            except Exception as error:  # a worker died or the task could not run
                yield JobFailure(job.scene, job.frame, one_line(error))
            submit_next()

    def close(self) -> None:
        if self._started:
            self._ray.shutdown()
            self._started = False


def make_executor(name: str, address: str | None = None, cpus_per_task: int = 1, num_cpus: int | None = None):
    """The executor called ``name`` (``local`` or ``ray``)."""
    if name == "local":
        if address:
            raise UserInputError("--ray-address only applies to --executor ray")
        return LocalExecutor()
    if name == "ray":
        return RayExecutor(address=address, num_cpus=num_cpus, cpus_per_task=cpus_per_task)
    raise UserInputError(f"unknown executor {name!r}; choose one of {', '.join(EXECUTORS)}")
