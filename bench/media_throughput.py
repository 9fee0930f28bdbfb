"""Participating media: our volumetric tracer against Mitsuba's ``volpath``, and what media cost a scene without any.

Part 1 (``--scene``): the same media scene, resolution, spp and depth (unbounded, Russian roulette from 5:
both at their defaults), rendered by Mitsuba's ``volpath`` (``hdrfilm``, box filter) and by ours as a
noisy frame (lobe split, every feature buffer, all variances: host arrays) and as a reference frame
(color only). Scenes: ``fog_smoke`` (the procedural media family, seed 3: homogeneous fog, a
heterogeneous smoke grid, a subsurface sphere) or any Mitsuba XML file (``--xml``, e.g. one of
mitsuba-data's ``tests/scenes/participating_media``). Each renderer is warmed up once, then timed
``--repeats`` times interleaved; medians compared (target: ours / volpath >= 0.8).

Part 2 (``--before REV``): a scene without media (the Cornell box, 128 px, 16 spp, every feature)
timed by this checkout and by the tree of git revision ``REV`` (extracted to a temporary folder), in
alternating subprocesses; prints the throughput ratio after / before (target >= 0.98) and whether
the frames are the same bytes.

    .venv/bin/python bench/media_throughput.py [--scene fog_smoke | --xml FILE] [--size 64] [--spp 16]
        [--repeats 5] [--before REV]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from denoisebench.mitsuba_runtime import load_mitsuba  # noqa: E402

#: Part 2's worker: render the Cornell box with every feature; print seconds per frame and a digest.
_WORKER = r"""
import hashlib, sys, time, numpy as np
from denoisebench.mitsuba_runtime import load_mitsuba
mi = load_mitsuba()
from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.render_plan import RenderOptions, make_render_plan
from denoisebench.generator.render.frame import render_frame
d = mi.cornell_box(); d.pop("sensor"); d.pop("integrator"); scene = mi.load_dict(d)
pose = np.eye(4); pose[2, 3] = 3.9
camera = CameraTrack(poses=np.stack([pose, pose]), fov_x_deg=39.3077)
plan = make_render_plan(["area_lights", "indirect"], RenderOptions())
render_frame(scene, camera, 1, plan, width=128, height=128, spp=16, seed=99)  # warm-up
times, digest = [], hashlib.sha256()
for k in range(int(sys.argv[1])):
    t = time.perf_counter()
    frame = render_frame(scene, camera, 1, plan, width=128, height=128, spp=16, seed=k)
    times.append(time.perf_counter() - t)
    for name in sorted(frame.buffers):
        digest.update(frame.buffers[name].tobytes())
print(min(times), sorted(times)[len(times) // 2], digest.hexdigest())
"""


def _media_scene(mi, args):
    from denoisebench.generator.contract.render_plan import make_render_plan

    if args.xml:
        from denoisebench.generator.mitsuba_xml import load_mitsuba_xml

        translated, scene = load_mitsuba_xml(args.xml, frames=2)
        peer = scene
        sensor = None
    else:
        from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
        from denoisebench.generator.usd.translate import translate_usd
        from denoisebench.scenes import get_family

        with tempfile.TemporaryDirectory() as folder:
            translated = translate_usd(get_family(args.scene).author(folder, seed=3, frames=2))
            scene = build_mitsuba_scene(translated)
            peer = build_mitsuba_scene(translated, integrator={"type": "volpath"})
        sensor = mi.load_dict(sensor_dict(translated.camera, 1, args.size, args.size, args.spp))
    plan = make_render_plan(translated.effects_inferred)  # unbounded depth: Mitsuba's defaults
    if sensor is None:
        from denoisebench.generator.render.scene import sensor_dict

        sensor = mi.load_dict(sensor_dict(translated.camera, 1, args.size, args.size, args.spp))
    return scene, peer, sensor, translated.camera, plan


def part1(args) -> None:
    mi = load_mitsuba()
    import drjit as dr

    from denoisebench.generator.render.frame import render_frame

    scene, peer, sensor, camera, plan = _media_scene(mi, args)
    integrator = mi.load_dict({"type": "volpath"})
    size, spp = args.size, args.spp

    def run_volpath(seed):
        start = time.perf_counter()
        image = mi.render(peer, sensor=sensor, integrator=integrator, seed=seed, spp=spp)
        np.asarray(image)
        return time.perf_counter() - start

    def run_ours(seed, reference=False):
        start = time.perf_counter()
        render_frame(scene, camera, 1, plan, width=size, height=size, spp=spp, seed=seed, reference=reference)
        return time.perf_counter() - start

    runs = {
        "volpath": run_volpath,
        "ours": run_ours,
        "ours_ref": lambda seed: run_ours(seed, reference=True),
    }
    labels = {
        "volpath": "mitsuba volpath",
        "ours": "ours, noisy (features + variances)",
        "ours_ref": "ours, reference (color only)",
    }
    for run in runs.values():
        run(1000)
    times = {name: [] for name in runs}
    for k in range(args.repeats):
        for name, run in runs.items():
            times[name].append(run(k))
    samples = size * size * spp
    print(f"scene={args.xml or args.scene} {size}x{size} spp={spp} repeats={args.repeats} threads={dr.thread_count()}")
    medians = {name: statistics.median(t) for name, t in times.items()}
    for name, t in times.items():
        print(
            f"{labels[name]:36s}: {samples / medians[name] / 1e6:7.3f} Msamples/s  "
            f"(median {medians[name] * 1e3:7.1f} ms, min {min(t) * 1e3:7.1f} ms)"
        )
    for name in ("ours", "ours_ref"):
        print(
            f"throughput ratio {name:8s} / volpath: median {medians['volpath'] / medians[name]:.3f}  "
            f"min {min(times['volpath']) / min(times[name]):.3f}"
        )


def part2(args) -> None:
    with tempfile.TemporaryDirectory() as folder:
        archive = subprocess.run(
            ["git", "archive", args.before, "denoisebench"], cwd=ROOT, capture_output=True, check=True
        )
        subprocess.run(["tar", "-x", "-C", folder], input=archive.stdout, check=True)
        trees = {"before": folder, "after": str(ROOT)}
        results = {name: [] for name in trees}
        digests = {}
        for _ in range(args.rounds):
            for name, tree in trees.items():
                out = subprocess.run(
                    [sys.executable, "-c", _WORKER, str(args.repeats)],
                    cwd=tree,
                    env={"PYTHONPATH": tree, "PATH": "/usr/bin:/bin"},
                    capture_output=True,
                    text=True,
                    check=True,
                )
                best, median, digest = out.stdout.split()[-3:]
                results[name].append(float(median))
                digests[name] = digest
    before, after = statistics.median(results["before"]), statistics.median(results["after"])
    print(f"media-free cornell 128x128 16 spp, every feature; before = {args.before}")
    print(
        f"seconds per frame (median of {args.rounds} rounds x {args.repeats}): before {before:.4f}  after {after:.4f}"
    )
    print(f"throughput ratio after / before: {before / after:.3f}")
    print(f"same bytes: {digests['before'] == digests['after']}  ({digests['after'][:16]})")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="fog_smoke", help="a procedural family with media")
    parser.add_argument("--xml", default=None, help="a Mitsuba XML scene with media instead")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--before", default=None, help="git revision for part 2 (media-free cost before/after)")
    parser.add_argument("--rounds", type=int, default=3, help="part 2: alternating subprocess rounds")
    parser.add_argument("--skip-media", action="store_true", help="only part 2")
    args = parser.parse_args(argv)
    if not args.skip_media:
        part1(args)
    if args.before:
        part2(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
