"""Seconds of the issue-41 methods: ``lightfield`` per megapixel and ``mdas``'s decisions, fixed and per-pixel cost apart.

    .venv/bin/python bench/lightfield_mdas_cost.py [--sizes 32,64] [--spp 4] [--repeats 2]

``lightfield`` runs on synthetic depth-of-field frames (``denoisebench.denoisers.synthetic``) at each
size; ``mdas`` runs on the synthetic light field (``denoisebench.sampling.synthetic_lightfield``: no
renderer, so its seconds are the sampler's own decisions and reconstruction, not rendering). Each figure
is the minimum over ``--repeats`` runs. A line ``a + b·MP`` is fitted through the sizes, so that the fixed
cost is not scaled by pixel count (docs/architecture.md, Metrics). The load average is printed before and
after: on a shared 2-core machine the figures move with it.

Measured (2 cores, load average 1.2; 4 spp): lightfield 1.08 s at 32 px, 3.79 s at 64 px: 0.17 s +
884 s/MP; mdas decisions and reconstruction 0.14 s and 0.48 s: 0.03 s + 111 s/MP.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.baselines.lightfield import LightField  # noqa: E402
from denoisebench.denoisers.synthetic import make_scene, render  # noqa: E402
from denoisebench.sampling.harness import run_sampler  # noqa: E402
from denoisebench.sampling.mdas import MDAS  # noqa: E402
from denoisebench.sampling.protocol import Budget  # noqa: E402
from denoisebench.sampling.synthetic_lightfield import SyntheticLightField  # noqa: E402


def _best(call, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="32,64")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    print(f"load average before: {os.getloadavg()}")
    rows = []
    for size in sizes:
        frame = render(make_scene("depth_of_field", size, size, 0), args.spp, 1, samples=True, reference_samples=4)
        lf = _best(lambda frame=frame: LightField().denoise(frame), args.repeats)
        result = run_sampler(MDAS(), SyntheticLightField(size, size, seed=0), Budget(spp=args.spp))
        rows.append((size, lf, result.decision_seconds))
        print(
            f"{size:>4} px  lightfield {lf:8.3f} s ({lf / (size * size / 1e6):8.0f} s/MP)  mdas decisions {result.decision_seconds:7.3f} s"
        )
    if len(rows) > 1:
        mp = np.array([r[0] ** 2 / 1e6 for r in rows])
        for index, name in ((1, "lightfield"), (2, "mdas decisions")):
            slope, fixed = np.polyfit(mp, np.array([r[index] for r in rows]), 1)
            print(f"{name}: {fixed:.3f} s + {slope:.0f} s/MP")
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
