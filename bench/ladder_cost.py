"""What a nested spp ladder costs against its top rung alone, and against independent rungs, in one run.

A dataset frame at ``--spp 1,2,4,8,16,32,64`` is one progressive render whose rungs are snapshots
(:func:`~denoisebench.generator.render.frame.render_ladder`); the peer is a plain render at the
top rung's spp (``render_frame``), which is what the ladder would ideally cost, and
``--independent-rungs``' way (one render per rung, each with its own seed), what it cost before.
All three render the same family scene, frame and plan as ``generate-dataset`` (every feature
buffer and variance, returned as host arrays). Start-up is subtracted: each is warmed up once
(Dr.Jit compilation and the ``dr.freeze`` recordings), then timed ``--repeats`` times, interleaved
(the order reversed every other repeat). The ratio is the median over repeats of each repeat's
ladder / top rung: the two run back to back, so a shared machine's load, which changes over
seconds, weighs on both alike. The ratio of the medians and of the minima are printed beside it
(other processes only ever add time), and the ratio of the process's CPU seconds (all threads;
what the work costs when other processes hold the cores, counting Dr.Jit's workers' spinning
between kernels against the ladder).

    .venv/bin/python bench/ladder_cost.py [--family cornell] [--size 160] [--rungs 1,2,4,8,16,32,64]
        [--repeats 9]

Prints seconds of each and the ratios ladder / top rung (target <= 1.15) and independent / top rung.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan  # noqa: E402
from denoisebench.generator.frame_jobs import independent_rung_seed  # noqa: E402
from denoisebench.generator.render.frame import render_frame, render_ladder  # noqa: E402
from denoisebench.generator.render.scene import build_mitsuba_scene  # noqa: E402
from denoisebench.generator.usd.translate import translate_usd  # noqa: E402
from denoisebench.mitsuba_runtime import load_mitsuba  # noqa: E402
from denoisebench.scenes import get_family  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--family", default="cornell")
    parser.add_argument("--size", type=int, default=160)
    parser.add_argument("--rungs", default="1,2,4,8,16,32,64")
    parser.add_argument("--repeats", type=int, default=9)
    args = parser.parse_args(argv)
    rungs = sorted({int(k) for k in args.rungs.split(",")})
    mi = load_mitsuba()
    with tempfile.TemporaryDirectory() as folder:
        stage = get_family(args.family).author(Path(folder), seed=0, frames=3, width=args.size, height=args.size)
        translated = translate_usd(stage)
        scene = build_mitsuba_scene(translated)
    plan = make_render_plan(translated.effects, RenderOptions(), stage_max_depth=translated.max_depth)
    kw = dict(width=args.size, height=args.size)
    camera = translated.camera

    def ladder():
        render_ladder(scene, camera, 1, plan, rungs=rungs, seed=0, **kw)

    def top():
        render_frame(scene, camera, 1, plan, spp=rungs[-1], seed=0, **kw)

    def independent():
        for spp in rungs:
            render_frame(scene, camera, 1, plan, spp=spp, seed=independent_rung_seed(0, spp), **kw)

    runs = {"ladder": ladder, "top rung": top, "independent": independent}
    for run in runs.values():  # warm-up: compilation and freeze recordings
        run()
    times = {name: [] for name in runs}
    cpu = {name: [] for name in runs}
    for repeat in range(args.repeats):
        order = list(runs) if repeat % 2 == 0 else list(reversed(runs))  # drift in load hits both sides alike
        for name in order:
            start, start_cpu = time.perf_counter(), time.process_time()
            runs[name]()
            times[name].append(time.perf_counter() - start)
            cpu[name].append(time.process_time() - start_cpu)
    print(
        f"{args.family} {args.size}x{args.size}, rungs {','.join(map(str, rungs))}, "
        f"{args.repeats} repeats ({mi.variant()}; medians, minima in brackets)"
    )
    for name, values in times.items():
        print(f"  {name:12s} {statistics.median(values):8.3f} s  [{min(values):.3f}]")
    base = statistics.median(times["top rung"])
    base_min = min(times["top rung"])
    for name in ("ladder", "independent"):
        paired = statistics.median(a / b for a, b in zip(times[name], times["top rung"]))
        ratio = statistics.median(times[name]) / base
        cpu_ratio = statistics.median(a / b for a, b in zip(cpu[name], cpu["top rung"]))
        print(
            f"  {name} / top rung: {paired:.3f}  [median of medians {ratio:.3f}, "
            f"minima {min(times[name]) / base_min:.3f}; CPU seconds {cpu_ratio:.3f}]"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
