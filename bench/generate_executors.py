"""Local vs Ray executor on one small dataset: wall time, render samples per second, same bytes.

    .venv/bin/python bench/generate_executors.py [--size 64] [--frames 3] [--families cornell,dim_room]

Both runs render the same config into fresh folders in this process; the local run goes first and
is the peer (ratios are Ray / local). Kernels are compiled (or loaded from Dr.Jit's cache) by a
throw-away warm-up run first, so neither executor pays for compilation the other does not. Ray's
wall time includes starting a local cluster (``num_cpus`` = this machine's cores), which is what
a user of ``--executor ray`` without ``--ray-address`` pays too.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import tempfile
import time
from pathlib import Path

from denoisebench.dataset import manifest_without_timings
from denoisebench.generator.dataset_run import GenerateRequest, generate_dataset
from denoisebench.generator.executors import LocalExecutor, RayExecutor


def _hashes(root: Path) -> dict[str, str]:
    return {
        p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*.exr"))
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--families", default="cornell,dim_room")
    args = parser.parse_args()
    families = tuple(args.families.split(","))
    with tempfile.TemporaryDirectory() as tmp:

        def request(name: str) -> GenerateRequest:
            return GenerateRequest(
                out=Path(tmp) / name,
                families=families,
                frames=args.frames,
                width=args.size,
                height=args.size,
                spp=(1, 4),
                ref_spp=64,
            )

        generate_dataset(request("warm"), LocalExecutor(), progress=False)
        results = {}
        for name in ("local", "ray"):
            started = time.perf_counter()
            executor = LocalExecutor() if name == "local" else RayExecutor(num_cpus=os.cpu_count())
            try:
                summary = generate_dataset(request(name), executor, progress=False)
            finally:
                executor.close()
            results[name] = (time.perf_counter() - started, summary)
        same = _hashes(Path(tmp) / "local") == _hashes(Path(tmp) / "ray") and manifest_without_timings(
            Path(tmp) / "local" / "dataset.json"
        ) == manifest_without_timings(Path(tmp) / "ray" / "dataset.json")
    print(
        f"config: {','.join(families)}, {args.frames} frames, {args.size}x{args.size}, spp 1,4, ref 64; "
        f"{os.cpu_count()} cores"
    )
    for name, (wall, summary) in results.items():
        print(
            f"{name:6s} wall {wall:7.2f} s   render {summary.render_seconds:7.2f} s   "
            f"{summary.samples_per_second:10.3g} samples/s (render)   {summary.samples / wall:10.3g} samples/s (wall)"
        )
    (lw, ls), (rw, rs) = results["local"], results["ray"]
    print(
        f"ray/local: wall {rw / lw:.2f}x, render samples/s {rs.samples_per_second / ls.samples_per_second:.2f}x; "
        f"same bytes: {same}"
    )


if __name__ == "__main__":
    main()
