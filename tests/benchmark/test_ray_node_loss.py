"""Lost Ray nodes: a worker node killed mid-run changes no byte and loses no unit.

A local multi-node cluster (``ray.cluster_utils.Cluster``: a head without CPUs and two worker nodes
of one CPU, each its own raylet and workers) runs ``generate-dataset --executor ray`` and
``run-benchmark --executor ray``; a thread kills a worker node (``remove_node(...,
allow_graceful=False)``: its raylet and workers are killed) as soon as the first result is written.

What Ray retries, and what denoisebench retries
-----------------------------------------------
* **Ray** re-runs a task whose worker process or node died (a system failure), up to the task's
  ``max_retries``: 1 for a frame job (:class:`~denoisebench.generator.executors.RayExecutor`), Ray's
  default 3 for a benchmark group (:mod:`denoisebench.benchmark.ray_executor`). A finished task's
  result that was lost with its node before the driver fetched it is rebuilt the same way (lineage
  reconstruction, within the same budget). Ray does not retry a task that raised (a render error).
* **denoisebench** retries nothing inside a run; it makes a re-run safe. Only the driver writes:
  a frame's files atomically and its manifest record after them, a benchmark unit in one SQLite
  transaction, each result once as it arrives, so a retried task cannot write twice. A frame job
  that fails after Ray's retries is reported (the dataset is left incomplete, exit 1); a benchmark
  group that fails after them stops the run. Running the same command again renders only the
  missing frames (same bytes: a render is a function of its job) and measures only the units
  without a row.
"""

from __future__ import annotations

import hashlib
import threading
import time
from pathlib import Path

import pytest

from denoisebench import cli
from denoisebench.dataset.synthetic import make_synthetic_dataset

ray = pytest.importorskip("ray")

GENERATE = "--families cornell --scenes 1 --frames 4 --width 16 --height 16 --spp 1,4 --ref-spp 16 --ref-error 0"


@pytest.fixture(scope="module")
def cluster():
    from ray.cluster_utils import Cluster

    if ray.is_initialized():
        ray.shutdown()  # another test's local cluster
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "include_dashboard": False})
    for _ in range(2):
        cluster.add_node(num_cpus=1)
    cluster.wait_for_nodes()
    ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False, logging_level="ERROR")
    try:
        yield cluster
    finally:
        ray.shutdown()
        cluster.shutdown()


class NodeKiller(threading.Thread):
    """Kills ``node`` once ``progress()`` is positive; keeps what progress was at that moment."""

    def __init__(self, cluster, node, progress):
        super().__init__(daemon=True)
        self.cluster, self.node, self.progress = cluster, node, progress
        self.at: int | None = None
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            done = self.progress()
            if done > 0:
                self.cluster.remove_node(self.node, allow_graceful=False)
                self.at = done
                return
            time.sleep(0.05)


def _worker_nodes(cluster) -> list:
    return [node for node in cluster.list_all_nodes() if node is not cluster.head_node]


def _exr_hashes(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*.exr"))}


def test_generation_survives_a_lost_node_with_the_same_bytes(cluster, tmp_path):
    out, peer = tmp_path / "ray", tmp_path / "local"
    total = 4 * 3  # frames x (two rungs + reference)
    killer = NodeKiller(
        cluster, _worker_nodes(cluster)[0], lambda: len(list(out.rglob("*.exr"))) if out.exists() else 0
    )
    killer.start()
    try:
        assert cli.main(["generate", "--out", str(out), *GENERATE.split(), "--executor", "ray", "--quiet"]) == 0
    finally:
        killer.stop.set()
        killer.join()
    assert killer.at is not None and killer.at < total, killer.at  # the node died mid-run
    assert cli.main(["generate", "--out", str(peer), *GENERATE.split(), "--quiet"]) == 0
    ours = _exr_hashes(out)
    assert len(ours) == total and ours == _exr_hashes(peer)


def test_benchmark_survives_a_lost_node_with_every_unit_once(cluster, tmp_path):
    import sqlite3

    fresh = cluster.add_node(num_cpus=1)  # the generation test took one away
    cluster.wait_for_nodes()
    data = make_synthetic_dataset(tmp_path / "ds", scenes=3, frames=2, height=16, width=16, spp=(1, 4))
    db = tmp_path / "r.sqlite"
    denoisers = ["identity", "cross_bilateral", "nlmeans"]

    def stored() -> int:
        if not db.exists():
            return 0
        try:
            with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1) as conn:
                return int(conn.execute("SELECT COUNT(*) FROM units").fetchone()[0])
        except sqlite3.Error:
            return 0

    killer = NodeKiller(cluster, fresh, stored)
    killer.start()
    argv = ["benchmark", "--data", str(data), "--db", str(db), "--no-report", "--split", "all"]
    argv += ["--metrics", "relmse", "--denoisers", ",".join(denoisers), "--executor", "ray", "--time-size", "none"]
    try:
        assert cli.main(argv) == 0
    finally:
        killer.stop.set()
        killer.join()
    expected = 3 * 2 * (len(denoisers) + 1)  # scenes x spp x (denoisers + the noisy input)
    assert killer.at is not None and killer.at < expected, killer.at
    with sqlite3.connect(db) as conn:
        keys = conn.execute("SELECT denoiser, scene, spp, COUNT(*) FROM units GROUP BY denoiser, scene, spp").fetchall()
        frames = conn.execute("SELECT COUNT(*) FROM frames").fetchone()[0]
        finished = conn.execute("SELECT COUNT(*) FROM runs WHERE finished_at IS NOT NULL").fetchone()[0]
    assert len(keys) == expected and {n for *_, n in keys} == {1}
    assert frames == expected * 2 and finished == 1
