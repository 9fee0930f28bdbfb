"""Feature renderer throughput against Mitsuba's own ``path`` integrator, in one run.

Both render the same scene at the same resolution, spp and max depth (Mitsuba with an ``hdrfilm``
and a box filter, the pixel filter of our noisy buffers); ours also produces the diffuse/specular
split, every feature buffer and all per-pixel variances. Each renderer is warmed up once (JIT
compilation), then timed ``--repeats`` times, interleaved, and the medians are compared.

    .venv/bin/python bench/render_throughput.py [--scene cornell|glossy] [--size 128] [--spp 16]
        [--max-depth 8] [--repeats 5]

Prints samples per second of both and their ratio (ours / path; the target is >= 0.9).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from denoisebench.generator.camera_track import CameraTrack  # noqa: E402
from denoisebench.generator.feature_renderer import load_scene, render_frame  # noqa: E402
from denoisebench.generator.render_plan import RenderOptions, make_render_plan  # noqa: E402
from denoisebench.mitsuba_runtime import load_mitsuba  # noqa: E402


def cornell_scene(mi, glossy: bool) -> dict:
    scene = mi.cornell_box()
    del scene["sensor"]
    if glossy:
        scene["large-box"]["bsdf"] = {"type": "principled", "base_color": {"type": "rgb", "value": [0.8, 0.8, 0.8]},
                                      "roughness": 0.25, "metallic": 0.5}
        scene["small-box"]["bsdf"] = {"type": "roughconductor", "alpha": 0.1}
    return scene


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", choices=("cornell", "glossy"), default="cornell")
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--max-depth", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)

    mi = load_mitsuba()
    import drjit as dr

    scene = load_scene(cornell_scene(mi, args.scene == "glossy"))
    pose = np.eye(4)
    pose[2, 3] = 3.9  # the Cornell box's own camera, in USD convention (looks down -Z)
    camera = CameraTrack(poses=np.stack([pose, pose]), fov_x_deg=39.3077)
    effects = ["area_lights", "indirect"] + (["glossy"] if args.scene == "glossy" else [])
    plan = make_render_plan(effects, RenderOptions(max_depth=args.max_depth))
    size, spp = args.size, args.spp

    sensor = mi.load_dict({
        "type": "perspective", "fov": camera.fov_x_deg, "fov_axis": "x",
        "near_clip": camera.near_clip, "far_clip": camera.far_clip,
        "to_world": mi.ScalarTransform4f(camera.mitsuba_to_world(1)),
        "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent", "sample_count": spp},
    })
    integrator = mi.load_dict({"type": "path", "max_depth": args.max_depth, "rr_depth": plan.rr_depth})

    def run_path(seed: int) -> float:
        start = time.perf_counter()
        image = mi.render(scene, sensor=sensor, integrator=integrator, seed=seed, spp=spp)
        dr.eval(image)
        np.asarray(image)  # both renderers end with host arrays
        return time.perf_counter() - start

    def run_ours(seed: int) -> float:
        start = time.perf_counter()
        render_frame(scene, camera, 1, plan, width=size, height=size, spp=spp, seed=seed)
        return time.perf_counter() - start

    run_path(1000)  # warm-up: JIT compilation
    run_ours(1000)
    ours, path = [], []
    for k in range(args.repeats):
        path.append(run_path(k))
        ours.append(run_ours(k))
    samples = size * size * spp
    t_ours, t_path = statistics.median(ours), statistics.median(path)
    print(f"scene={args.scene} {size}x{size} spp={spp} max_depth={args.max_depth} repeats={args.repeats}")
    print(f"mitsuba path     : {samples / t_path / 1e6:8.3f} Msamples/s  (median {t_path * 1e3:8.1f} ms)")
    print(f"feature renderer : {samples / t_ours / 1e6:8.3f} Msamples/s  (median {t_ours * 1e3:8.1f} ms)")
    print(f"throughput ratio (ours / path): {t_path / t_ours:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
