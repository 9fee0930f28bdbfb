"""Feature renderer throughput against Mitsuba's own ``path`` integrator, in one run.

Both render the same scene at the same resolution, spp and max depth (Mitsuba with an ``hdrfilm``
and a box filter, the pixel filter of our noisy buffers). Ours is timed twice: as a noisy frame
(the diffuse/specular split, every feature buffer and all per-pixel variances, returned as host
arrays) and as a reference frame (color, diffuse, specular and their variances: no features).
Each renderer is warmed up once (JIT compilation; for ours also the ``dr.freeze`` recording of its
passes, which later frames of a dataset replay), then timed ``--repeats`` times, interleaved, and
the medians are compared; the minimum is printed too, since other processes on a shared machine
only ever add time. ``--no-freeze`` traces our passes afresh every frame instead (the cost of a
one-off frame; Mitsuba's ``path`` traces its C++ integrator every time, which is cheap).

    .venv/bin/python bench/render_throughput.py [--scene cornell|glossy|cluttered] [--size 128] [--spp 16]
        [--max-depth 8] [--repeats 7] [--target-lanes N] [--no-freeze]

Prints samples per second of each and the ratios ours / path (the target is >= 0.9).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.generator.contract.camera_track import CameraTrack  # noqa: E402
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan  # noqa: E402
from denoisebench.generator.render import passes as render_passes  # noqa: E402
from denoisebench.generator.render.frame import load_scene, render_frame  # noqa: E402
from denoisebench.mitsuba_runtime import load_mitsuba  # noqa: E402


def cornell_scene(mi, glossy: bool) -> dict:
    scene = mi.cornell_box()
    del scene["sensor"]
    if glossy:
        scene["large-box"]["bsdf"] = {
            "type": "principled",
            "base_color": {"type": "rgb", "value": [0.8, 0.8, 0.8]},
            "roughness": 0.25,
            "metallic": 0.5,
        }
        scene["small-box"]["bsdf"] = {"type": "roughconductor", "alpha": 0.1}
    return scene


def cluttered_scene(mi, size: int, spp: int, max_depth: int):
    """(scene, camera, plan, sensor) of cluttered seed 4 (a static stage: Mitsuba renders what we do)."""
    import tempfile

    from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import get_family

    with tempfile.TemporaryDirectory() as folder:
        translated = translate_usd(get_family("cluttered").author(folder, seed=4, frames=2))
        scene = build_mitsuba_scene(translated)
    plan = make_render_plan(translated.effects, RenderOptions(max_depth=max_depth))
    return scene, translated.camera, plan, mi.load_dict(sensor_dict(translated.camera, 1, size, size, spp))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--scene",
        choices=("cornell", "glossy", "cluttered"),
        default="cornell",
        help="cluttered: the cluttered family, seed 4 (static: no depth of field, no object motion blur)",
    )
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--max-depth", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--target-lanes", type=int, default=None, help="render_frame's target_lanes")
    parser.add_argument("--no-freeze", action="store_true", help="trace our passes afresh every frame")
    args = parser.parse_args(argv)
    render_passes.FREEZE_PASSES = not args.no_freeze

    mi = load_mitsuba()
    import drjit as dr

    size, spp = args.size, args.spp
    if args.scene == "cluttered":
        scene, camera, plan, sensor = cluttered_scene(mi, size, spp, args.max_depth)
    else:
        scene = load_scene(cornell_scene(mi, args.scene == "glossy"))
        pose = np.eye(4)
        pose[2, 3] = 3.9  # the Cornell box's own camera, in USD convention (looks down -Z)
        camera = CameraTrack(poses=np.stack([pose, pose]), fov_x_deg=39.3077)
        effects = ["area_lights", "indirect"] + (["glossy"] if args.scene == "glossy" else [])
        plan = make_render_plan(effects, RenderOptions(max_depth=args.max_depth))
    sensor = (
        sensor
        if args.scene == "cluttered"
        else mi.load_dict(
            {
                "type": "perspective",
                "fov": camera.fov_x_deg,
                "fov_axis": "x",
                "near_clip": camera.near_clip,
                "far_clip": camera.far_clip,
                "to_world": mi.ScalarTransform4f(camera.mitsuba_to_world(1)),
                "film": {
                    "type": "hdrfilm",
                    "width": size,
                    "height": size,
                    "rfilter": {"type": "box"},
                    "pixel_format": "rgb",
                },
                "sampler": {"type": "independent", "sample_count": spp},
            }
        )
    )
    integrator = mi.load_dict({"type": "path", "max_depth": args.max_depth, "rr_depth": plan.rr_depth})

    cpu = {}  # process CPU seconds (all threads) per run: robust to other processes on a shared machine

    def run_path(seed: int) -> float:
        start = time.perf_counter()
        cpu0 = time.process_time()
        image = mi.render(scene, sensor=sensor, integrator=integrator, seed=seed, spp=spp)
        dr.eval(image)
        np.asarray(image)  # both renderers end with host arrays
        cpu.setdefault("path", []).append(time.process_time() - cpu0)
        return time.perf_counter() - start

    extra = {} if args.target_lanes is None else {"target_lanes": args.target_lanes}

    def run_ours(seed: int, reference: bool = False) -> float:
        start = time.perf_counter()
        cpu0 = time.process_time()
        render_frame(scene, camera, 1, plan, width=size, height=size, spp=spp, seed=seed, reference=reference, **extra)
        cpu.setdefault("ours_ref" if reference else "ours", []).append(time.process_time() - cpu0)
        return time.perf_counter() - start

    runs = {"path": run_path, "ours": run_ours, "ours_ref": lambda seed: run_ours(seed, reference=True)}
    labels = {
        "path": "mitsuba path",
        "ours": "ours, noisy (features + variances)",
        "ours_ref": "ours, reference (color only)",
    }
    for run in runs.values():
        run(1000)  # warm-up: JIT compilation
    cpu.clear()
    times = {name: [] for name in runs}
    for k in range(args.repeats):
        for name, run in runs.items():
            times[name].append(run(k))
    samples = size * size * spp
    print(
        f"scene={args.scene} {size}x{size} spp={spp} max_depth={args.max_depth} repeats={args.repeats} "
        f"threads={dr.thread_count()} target_lanes={extra.get('target_lanes', 'default')} "
        f"frozen={render_passes.FREEZE_PASSES}"
    )
    medians = {name: statistics.median(t) for name, t in times.items()}
    for name, t in times.items():
        print(
            f"{labels[name]:36s}: {samples / medians[name] / 1e6:7.3f} Msamples/s  "
            f"(median {medians[name] * 1e3:7.1f} ms, min {min(t) * 1e3:7.1f} ms)"
        )
    for name in ("ours", "ours_ref"):
        print(
            f"throughput ratio {name:8s} / path: median {medians['path'] / medians[name]:.3f}  "
            f"min {min(times['path']) / min(times[name]):.3f}  "
            f"CPU-time median {statistics.median(cpu['path']) / statistics.median(cpu[name]):.3f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
