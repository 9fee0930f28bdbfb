"""The sampler card's figures: every built-in sampler, with and without denoisers, at equal spp and at equal time.

For every scene of ``--data`` (a dataset with references, e.g. the demo families) and its first
``--frames`` frames, each built-in sampler renders live (``denoisebench/sampling/live.py``: the
scene's own stage and plan, a seed disjoint from the stored inputs' and the reference's, the same
seed for every sampler) at each ``--spp`` mean budget; its image is scored against the dataset's
reference with relMSE (docs/architecture.md: ``mean((p − r)² / (r² + 0.01))``) as it is and after each of
``--denoisers`` (run under the harness contract, ``denoisers/runner.run_frame``, fed the sampler's
buffers). Equal time: uniform is rendered again at the spp that takes the adaptive sampler's seconds
(render + decision, scaled from uniform's seconds per sample in the same run), and scored the same
way.

Printed per family and spp (means over scenes and frames): seconds, decision share, relMSE with each
denoiser, the ratio to uniform at equal spp and at equal time, pixels left with < 1 sample.

    .venv/bin/python bench/sampler_card.py --data DATASET [--spp 8,16] [--frames 1]
        [--denoisers none,cross_bilateral_fast,oidn]
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.dataset import open_dataset  # noqa: E402
from denoisebench.dataset.frame import Frame  # noqa: E402
from denoisebench.denoisers.registry import load_denoiser  # noqa: E402
from denoisebench.denoisers.runner import run_frame  # noqa: E402
from denoisebench.metrics.ours.spatial import relmse  # noqa: E402
from denoisebench.sampling.live import LiveScene, run_live  # noqa: E402
from denoisebench.sampling.protocol import Budget  # noqa: E402
from denoisebench.sampling.registry import BUILTINS, load_sampler  # noqa: E402


def scores(result, reference, denoisers, scene, index) -> dict[str, float]:
    """relMSE of the sampler's image as it is ("none") and after each denoiser."""
    out = {}
    buffers = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in result.buffers.items()}
    frame = Frame(buffers=buffers, spp=max(int(round(result.mean_spp)), 1), scene=scene, index=index)
    for name, denoiser in denoisers.items():
        if denoiser is None:
            out[name] = relmse(buffers["color"], reference)
            continue
        done = run_frame(denoiser, frame, name=name)
        out[name] = relmse(done.output, reference) if done.ok else float("nan")
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", required=True)
    parser.add_argument("--spp", default="8,16")
    parser.add_argument("--frames", type=int, default=1)
    parser.add_argument("--denoisers", default="none,cross_bilateral_fast")
    args = parser.parse_args(argv)
    budgets = [float(s) for s in args.spp.split(",")]
    data = open_dataset(args.data)
    denoisers = {n: None if n == "none" else load_denoiser(n) for n in args.denoisers.split(",")}
    table: dict[tuple, list[dict]] = defaultdict(list)
    samplers = list(BUILTINS)
    for scene in data.scenes:
        family = data.scene(scene, renders=False).record.get("family", scene)
        live = LiveScene.from_dataset(data, scene)
        for index in range(min(args.frames, live.frames)):
            reference = data.reference(scene, index)[0]["color"]
            run_live(load_sampler("uniform"), live, index, Budget(spp=1))  # warm-up: kernels compile
            for spp in budgets:
                results = {name: run_live(load_sampler(name), live, index, Budget(spp=spp)) for name in samplers}
                per_sample = results["uniform"].seconds / max(results["uniform"].samples, 1)
                for name, result in results.items():
                    row = {
                        "seconds": result.seconds,
                        "decision": result.decision_seconds / max(result.seconds, 1e-12),
                        "empty": result.pixels_without_samples,
                        **{f"{d}": v for d, v in scores(result, reference, denoisers, scene, index).items()},
                    }
                    if name != "uniform":
                        equal_spp = max(result.seconds / per_sample / (live.width * live.height), 1.0)
                        same_time = run_live(load_sampler("uniform"), live, index, Budget(spp=equal_spp))
                        for d, v in scores(same_time, reference, denoisers, scene, index).items():
                            row[f"{d}@t"] = v
                        row["equal_time_spp"] = equal_spp
                    table[(family, spp, name)].append(row)
            print(f"done {scene} frame {index}", file=sys.stderr)

    names = list(denoisers)
    print(f"dataset {args.data}: {len(data.scenes)} scenes, {args.frames} frame(s) each; relMSE against the reference")
    head = ["family", "spp", "sampler", "s", "decide"] + names + [f"{n} /uni" for n in names]
    head += [f"{n} /uni@t" for n in names] + ["uni@t spp", "<1 spp"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for (family, spp, name), rows in sorted(
        table.items(), key=lambda kv: (kv[0][0], kv[0][1], samplers.index(kv[0][2]))
    ):
        mean = {key: float(np.mean([r[key] for r in rows])) for key in rows[0]}
        uniform = {key: float(np.mean([r[key] for r in table[(family, spp, "uniform")]])) for key in names}
        cells = [family, f"{spp:g}", name, f"{mean['seconds']:.3f}", f"{mean['decision']:.1%}"]
        cells += [f"{mean[n]:.4f}" for n in names]
        cells += [f"{mean[n] / uniform[n]:.3f}" for n in names]
        if name == "uniform":
            cells += ["–"] * len(names) + ["–"]
        else:
            cells += [f"{mean[n] / mean[n + '@t']:.3f}" for n in names] + [f"{mean['equal_time_spp']:.1f}"]
        cells.append(str(int(max(r["empty"] for r in rows))))
        print("| " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
