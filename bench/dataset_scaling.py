"""Cost per frame of every dataset stage at 100, 1 000 (and 10 000) frames: is each stage linear?

    .venv/bin/python bench/dataset_scaling.py            # 100 and 1 000 frames
    .venv/bin/python bench/dataset_scaling.py --full     # and 10 000 frames, with a resume after kill -9
    .venv/bin/python bench/dataset_scaling.py --ray      # generation on a local multi-node Ray cluster

Frames are tiny (8×8 px, 1 spp, a 1-spp reference, ``--ref-error 0``) so that rendering is
negligible and what is measured is the harness: writing and recording frames, scanning them on
resume, hashing them (the benchmark's verification), opening the dataset and reading every frame
record, assigning splits, ``run-benchmark`` (unit planning, per-frame scoring, the store), the
report and ``export --format oidn``. The frames are split over ``--scenes`` scenes of one family
(2 by default), so per-scene costs (authoring a stage, a Mitsuba scene) are the same at every
point. Each stage is timed at each point; the last column is the **ratio of the cost per frame**
between the largest and the smallest point (1.0: linear; the target is <= 1.3; a fixed cost
amortised over more frames shows as a ratio below 1). The peer of every figure is the same stage
at the smallest point, in the same run.

``--full`` adds the 10 000-frame point and a resume after ``kill -9``: a subprocess generates
that dataset again, is killed when half of its frames are recorded, and the same command resumes
it; the resumed dataset must equal the uninterrupted one (EXR bytes, manifest without timings).

``--ray`` generates ``--ray-frames`` frames (16×16 px, 16 spp: rendering is no longer negligible)
with the local executor and on a ``ray.cluster_utils.Cluster`` of 1 and 2 worker nodes (1 CPU
each, the head node has none), checks that the bytes equal the local run's, and prints each
run's frames per second and the **driver's own CPU time per frame** (``time.process_time`` of
this process: writing, hashing, recording, Ray's client threads) beside a worker's render time
per frame (stated bound: :data:`DRIVER_FRACTION`). On a 2-core machine two worker nodes and the driver share two cores: rendering
saturates the machine at 2 nodes.

Notes
-----
Dr.Jit compiles (or loads from its cache) the renderer's kernels the first time, and the first
benchmark and report import their libraries; a throw-away warm-up point (2 frames per scene, every
stage) pays for that before anything is timed. Generation is bound by ``fsync``: every EXR file
and its folder are synced (atomic writes) and every frame record is one durable SQLite commit, so
a frame costs a few fsyncs whatever the dataset's size. Timings are wall-clock seconds on a shared
machine: rerun when a ratio is near the target.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# FLIP (flip_evaluator) runs OpenMP threads: on a busy 2-core machine their spin-waits made one 8×8 FLIP call
# take 200 ms instead of 0.8 ms, so that the benchmark stage measured contention; one thread unless told.
os.environ.setdefault("OMP_NUM_THREADS", "1")

REPO = Path(__file__).resolve().parents[1]
FAMILY = "cornell"
#: The driver's own CPU time per frame stays below this fraction of a worker's render time per frame.
DRIVER_FRACTION = 0.5


def _request(out: Path, frames: int, scenes: int, size: int = 8, spp: int = 1):
    from denoisebench.generator.dataset_run import GenerateRequest

    return GenerateRequest(
        out=out,
        families=(FAMILY,),
        scenes=scenes,
        frames=frames,
        width=size,
        height=size,
        spp=(spp,),
        ref_spp=1,
        ref_error=None,
        seed=0,
    )


def _hashes(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in root.rglob("*.exr")}


def _same(a: Path, b: Path) -> bool:
    from denoisebench.dataset import layout, manifest_without_timings

    return _hashes(a) == _hashes(b) and manifest_without_timings(a / layout.MANIFEST_NAME) == manifest_without_timings(
        b / layout.MANIFEST_NAME
    )


def _timed(fn) -> float:
    started = time.perf_counter()
    fn()
    return time.perf_counter() - started


def measure_point(work: Path, total: int, scenes: int) -> dict[str, float]:
    """Seconds of every stage on a dataset of ``total`` frames (``scenes`` scenes)."""
    from denoisebench.benchmark.run import run_benchmark
    from denoisebench.benchmark.runner import BenchmarkConfig
    from denoisebench.cli import main
    from denoisebench.dataset import open_dataset
    from denoisebench.dataset.manifest import assign_splits
    from denoisebench.dataset.verify import run_files, verify_files
    from denoisebench.generator.dataset_run import generate_dataset
    from denoisebench.generator.executors import LocalExecutor
    from denoisebench.reports.build import write_report
    from denoisebench.results.store import ResultsStore

    out = work / f"ds{total}"
    request = _request(out, total // scenes, scenes)
    times: dict[str, float] = {}
    times["generate"] = _timed(lambda: generate_dataset(request, LocalExecutor(), progress=False, log=lambda _: None))
    times["resume scan"] = _timed(
        lambda: generate_dataset(request, LocalExecutor(), progress=False, log=lambda _: None)
    )

    def verify():
        ds = open_dataset(out)
        verify_files(ds, run_files(ds, ds.scenes, [1]), progress=False)

    times["verify (sha256)"] = _timed(verify)

    def read_records():
        ds = open_dataset(out)
        for scene in ds.scenes:
            for index in range(ds.scene(scene, renders=False).frame_count):
                assert ds.record(scene, 1, index) is not None and ds.record(scene, "reference", index) is not None

    times["open + every record"] = _timed(read_records)
    names = [f"scene_{i:06d}" for i in range(total)]  # splits are by scene: as many scenes as frames
    times["split assignment"] = _timed(lambda: assign_splits(names, 0, families={n: FAMILY for n in names}))
    db = work / f"bench{total}.sqlite"
    state = {}

    def benchmark():
        config = BenchmarkConfig(denoisers=["identity"], spp=[1], split="all", metrics=["relmse"])
        with ResultsStore(db) as store:
            state["run"] = run_benchmark(open_dataset(out), config, store, progress=False).run_id

    times["run-benchmark"] = _timed(benchmark)

    def report():
        with ResultsStore(db, readonly=True) as store:
            write_report(store, state["run"], open_dataset(out), work / f"report{total}")

    times["report"] = _timed(report)
    times["export oidn"] = _timed(
        lambda: main(
            ["export", str(out), str(work / f"oidn{total}"), "--format", "oidn", "--tile-size", "8", "--quiet"]
        )
    )
    return times


def kill_and_resume(work: Path, total: int, scenes: int) -> tuple[float, bool]:
    """Generate ``total`` frames in a subprocess, kill -9 it half-way, resume; (resume seconds, same bytes)."""
    from denoisebench.dataset import layout

    out = work / f"killed{total}"
    command = [
        sys.executable,
        "-m",
        "denoisebench.cli",
        "generate",
        "--out",
        str(out),
        "--families",
        FAMILY,
        "--scenes",
        str(scenes),
        "--frames",
        str(total // scenes),
        "--width",
        "8",
        "--height",
        "8",
        "--spp",
        "1",
        "--ref-spp",
        "1",
        "--ref-error",
        "0",
        "--seed",
        "0",
        "--quiet",
    ]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    index = out / layout.INDEX_NAME
    while proc.poll() is None:
        time.sleep(0.2)
        if index.is_file():
            try:
                db = sqlite3.connect(f"{index.as_uri()}?mode=ro", uri=True)
                count = db.execute("SELECT COUNT(*) FROM frames").fetchone()[0]
                db.close()
            except sqlite3.Error:
                continue
            if count >= total:  # half of the 2 records (noisy + reference) per frame
                proc.send_signal(signal.SIGKILL)
                break
    proc.wait()
    if proc.returncode != -signal.SIGKILL:
        raise SystemExit("the run finished before it could be killed")
    seconds = _timed(lambda: subprocess.run(command, env=env, check=True, stdout=subprocess.DEVNULL))
    return seconds, _same(out, work / f"ds{total}")


def ray_scaling(work: Path, frames: int) -> None:
    """Local executor vs a local Ray cluster of 1 and 2 worker nodes: throughput, driver CPU, bytes."""
    import ray
    from ray.cluster_utils import Cluster

    from denoisebench.generator.dataset_run import generate_dataset
    from denoisebench.generator.executors import LocalExecutor, RayExecutor

    def run(name: str, executor) -> tuple[float, float, float, int]:
        request = _request(work / name, frames, 1, size=16, spp=16)
        cpu, wall = time.process_time(), time.perf_counter()
        summary = generate_dataset(request, executor, progress=False, log=lambda _: None)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        return wall, cpu, summary.render_seconds, summary.frames

    generate_dataset(_request(work / "warm", 2, 1, size=16, spp=16), LocalExecutor(), progress=False, log=print)
    rows = [("local", *run("local", LocalExecutor()))]
    for nodes in (1, 2):
        cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0})
        for _ in range(nodes):
            cluster.add_node(num_cpus=1)
        ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False, configure_logging=False)
        try:
            executor = RayExecutor(address=cluster.address)
            run(f"warm_ray{nodes}", executor)  # workers start and compile their kernels
            rows.append((f"ray, {nodes} node(s)", *run(f"ray{nodes}", executor)))
        finally:
            ray.shutdown()
            cluster.shutdown()
        rows[-1] = (*rows[-1], _same(work / "local", work / f"ray{nodes}"))
    print(f"\ngeneration of {frames} frames (16x16 px, 16 spp, 1-spp reference), one scene")
    print(
        f"{'executor':<18} {'wall s':>8} {'frames/s':>9} {'render s/frame':>15} {'driver CPU s/frame':>19}  same bytes"
    )
    fractions = []
    for name, wall, cpu, render, count, *same in rows:
        ratio = cpu / render if render else float("nan")
        if same:
            fractions.append(ratio)
        print(
            f"{name:<18} {wall:8.2f} {count / wall:9.1f} {render / count:15.4f} {cpu / count:19.4f}"
            f"  {'yes' if not same or same[0] else 'NO'}  (driver / render: {ratio:.2f})"
        )
    print("(local: the driver renders too, so its CPU includes rendering)")
    print(
        f"Ray driver CPU per frame / worker render seconds per frame: at most {max(fractions):.2f} "
        f"(stated bound {DRIVER_FRACTION}): {'ok' if max(fractions) <= DRIVER_FRACTION else 'EXCEEDED'}"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--full", action="store_true", help="add the 10 000-frame point and a resume after kill -9")
    parser.add_argument("--scenes", type=int, default=2, help="scenes the frames are split over (default 2)")
    parser.add_argument("--ray", action="store_true", help="only the Ray cluster measurement")
    parser.add_argument("--ray-frames", type=int, default=120, help="frames of the Ray measurement (default 120)")
    parser.add_argument("--keep", action="store_true", help="keep the work folder")
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="denoisebench-scaling-"))
    try:
        if args.ray:
            ray_scaling(work, args.ray_frames)
            return 0
        measure_point(work, 2 * args.scenes, args.scenes)  # warm-up: kernels, imports, first-call costs
        points = [100, 1000] + ([10000] if args.full else [])
        results = {}
        for total in points:
            results[total] = measure_point(work, total, args.scenes)
            print(f"{total} frames: " + ", ".join(f"{k} {v:.2f} s" for k, v in results[total].items()), flush=True)
        small, large = points[0], points[-1]
        print(f"\nms per frame (8x8 px, 1 spp, 1-spp reference, {args.scenes} scenes of {FAMILY})")
        print(f"{'stage':<22}" + "".join(f"{p:>10}" for p in points) + f"{'ratio':>8}")
        for stage in results[small]:
            per = [1000 * results[p][stage] / p for p in points]
            print(f"{stage:<22}" + "".join(f"{v:10.3f}" for v in per) + f"{per[-1] / per[0]:8.2f}")
        if args.full:
            seconds, same = kill_and_resume(work, large, args.scenes)
            print(
                f"\nresume after kill -9 at half of {large} frames: {seconds:.1f} s, same bytes as uninterrupted: {same}"
            )
            if not same:
                return 1
        return 0
    finally:
        if args.keep:
            print(f"work folder: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    raise SystemExit(main())
