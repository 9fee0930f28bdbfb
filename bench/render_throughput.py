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

Without ``--scene``, ``--size`` or ``--spp`` it measures the three regimes of DEFAULT_REGIMES: the
cluttered scene at 1024x1024 and 1 and 4 spp (where denoisers live: a per-pixel cost of the buffers
shows there), and the Cornell box at 128x128 and 16 spp (the single regime's defaults, where ours is
closest to ``path``: 0.9-1.0; cluttered at that size is ~1.4); with any of them, the one regime
asked for.

    .venv/bin/python bench/render_throughput.py                      # the three regimes
    .venv/bin/python bench/render_throughput.py --scene cluttered --size 1024 --spp 1 --repeats 3
        [--scene cornell|glossy|cluttered] [--size 128] [--spp 16] [--max-depth 8] [--repeats N]
        [--target-lanes N] [--no-freeze]

Prints samples per second of each and the ratios ours / path per regime, then a summary (targets:
noisy >= 0.85 at 1 MP 1 spp, >= 0.9 at 1 MP 4 spp and at 128 px 16 spp).
"""

from __future__ import annotations

import argparse
import gc
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


def cluttered_scene(mi, max_depth: int):
    """(scene, camera, plan) of cluttered seed 4 (a static stage: Mitsuba renders what we do)."""
    import tempfile

    from denoisebench.generator.render.scene import build_mitsuba_scene
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.scenes import get_family

    with tempfile.TemporaryDirectory() as folder:
        translated = translate_usd(get_family("cluttered").author(folder, seed=4, frames=2))
        scene = build_mitsuba_scene(translated)
    return scene, translated.camera, make_render_plan(translated.effects, RenderOptions(max_depth=max_depth))


#: (scene, size, spp, repeats) measured when no regime is named on the command line.
DEFAULT_REGIMES = (("cluttered", 1024, 1, 3), ("cluttered", 1024, 4, 3), ("cornell", 128, 16, 7))


def make_scene(mi, name: str, max_depth: int):
    """(scene, camera, plan) of ``name``: the sensor is made per size (:func:`make_sensor`)."""
    if name == "cluttered":
        return cluttered_scene(mi, max_depth)
    scene = load_scene(cornell_scene(mi, name == "glossy"))
    pose = np.eye(4)
    pose[2, 3] = 3.9  # the Cornell box's own camera, in USD convention (looks down -Z)
    camera = CameraTrack(poses=np.stack([pose, pose]), fov_x_deg=39.3077)
    effects = ["area_lights", "indirect"] + (["glossy"] if name == "glossy" else [])
    return scene, camera, make_render_plan(effects, RenderOptions(max_depth=max_depth))


def make_sensor(mi, name: str, camera, *, size: int, spp: int):
    """Mitsuba's sensor for ``path``: the camera of our frame 1, an ``hdrfilm`` with a box filter."""
    if name == "cluttered":
        from denoisebench.generator.render.scene import sensor_dict

        return mi.load_dict(sensor_dict(camera, 1, size, size, spp))
    return mi.load_dict(
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


def measure(mi, built: tuple, regime: tuple, *, options) -> dict:
    """Time ``path``, ours (noisy) and ours (reference) in one regime; print them; return the ratios."""
    import drjit as dr

    (name, scene, camera, plan), (size, spp, repeats) = built, regime
    sensor = make_sensor(mi, name, camera, size=size, spp=spp)
    integrator = mi.load_dict({"type": "path", "max_depth": options.max_depth, "rr_depth": plan.rr_depth})
    cpu = {}  # process CPU seconds (all threads) per run: robust to other processes on a shared machine

    def run_path(seed: int) -> float:
        start = time.perf_counter()
        cpu0 = time.process_time()
        image = mi.render(scene, sensor=sensor, integrator=integrator, seed=seed, spp=spp)
        dr.eval(image)
        np.asarray(image)  # both renderers end with host arrays
        cpu.setdefault("path", []).append(time.process_time() - cpu0)
        return time.perf_counter() - start

    extra = {} if options.target_lanes is None else {"target_lanes": options.target_lanes}

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
    times = {key: [] for key in runs}
    for k in range(repeats):
        for key, run in runs.items():
            times[key].append(run(k))
    samples = size * size * spp
    print(
        f"scene={name} {size}x{size} spp={spp} max_depth={options.max_depth} repeats={repeats} "
        f"threads={dr.thread_count()} target_lanes={extra.get('target_lanes', 'default')} "
        f"frozen={render_passes.FREEZE_PASSES}"
    )
    medians = {key: statistics.median(t) for key, t in times.items()}
    for key, t in times.items():
        print(
            f"{labels[key]:36s}: {samples / medians[key] / 1e6:7.3f} Msamples/s  "
            f"(median {medians[key] * 1e3:7.1f} ms, min {min(t) * 1e3:7.1f} ms)"
        )
    ratios = {}
    for key in ("ours", "ours_ref"):
        ratios[key] = (
            medians["path"] / medians[key],
            min(times["path"]) / min(times[key]),
            statistics.median(cpu["path"]) / statistics.median(cpu[key]),
        )
        print(
            f"throughput ratio {key:8s} / path: median {ratios[key][0]:.3f}  min {ratios[key][1]:.3f}  "
            f"CPU-time median {ratios[key][2]:.3f}",
            flush=True,
        )
    return ratios


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--scene",
        choices=("cornell", "glossy", "cluttered"),
        default=None,
        help="cluttered: the cluttered family, seed 4 (static: no depth of field, no object motion blur); "
        "default: the three DEFAULT_REGIMES, or cornell when --size or --spp is given",
    )
    parser.add_argument("--size", type=int, default=None, help="image side in pixels (default 128 for one regime)")
    parser.add_argument("--spp", type=int, default=None, help="samples per pixel (default 16 for one regime)")
    parser.add_argument("--max-depth", type=int, default=8)
    parser.add_argument(
        "--repeats", type=int, default=None, help="timed runs per renderer (default: 3 at 1 MP, 7 otherwise)"
    )
    parser.add_argument("--target-lanes", type=int, default=None, help="render_frame's target_lanes")
    parser.add_argument("--no-freeze", action="store_true", help="trace our passes afresh every frame")
    args = parser.parse_args(argv)
    render_passes.FREEZE_PASSES = not args.no_freeze
    if args.scene is None and args.size is None and args.spp is None:
        regimes = [
            (scene, size, spp, repeats if args.repeats is None else args.repeats)
            for scene, size, spp, repeats in DEFAULT_REGIMES
        ]
    else:
        size = 128 if args.size is None else args.size
        spp = 16 if args.spp is None else args.spp
        repeats = args.repeats if args.repeats is not None else 3 if size >= 1024 else 7
        regimes = [(args.scene or "cornell", size, spp, repeats)]
    for name, size, spp, repeats in regimes:
        if size < 1 or spp < 1 or repeats < 1:
            print(
                f"render_throughput: --size, --spp and --repeats must be >= 1 (got {size}, {spp}, {repeats})",
                file=sys.stderr,
            )
            return 2

    mi = load_mitsuba()
    built, summary = None, []
    for name, size, spp, repeats in regimes:
        if built is None or built[0] != name:
            # One scene alive at a time: Dr.Jit's virtual calls dispatch over every live instance of a
            # domain, so a scene kept from an earlier regime slowed Mitsuba's path on the next (the
            # Cornell box at 128 px took 0.81 s instead of 0.45 s after the cluttered regimes).
            built = None
            render_passes.forget_scene()
            gc.collect()
            built = (name, *make_scene(mi, name, args.max_depth))
        summary.append(((name, size, spp), measure(mi, built, (size, spp, repeats), options=args)))
        print()
    print("summary (ours / path: median, min, CPU-time median)")
    for (name, size, spp), ratios in summary:
        noisy, ref = ratios["ours"], ratios["ours_ref"]
        print(
            f"  {name:9s} {size:5d}^2 {spp:3d} spp   noisy {noisy[0]:.3f} {noisy[1]:.3f} {noisy[2]:.3f}   "
            f"reference {ref[0]:.3f} {ref[1]:.3f} {ref[2]:.3f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
