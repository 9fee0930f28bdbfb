"""Cost of object motion blur: the same scene rendered with its shapes moving within the shutter and static.

One stage (floor, back wall, a key light and a dome, ``--objects`` boxes and spheres that translate and
turn over the sequence, a static camera with a one-frame shutter) is rendered by the feature renderer
twice per repeat, interleaved, as noisy frames (every feature buffer) under the same render plan (time
sampling on):

* **moving**: ``build_mitsuba_scene`` as the dataset builds it: the moving shapes in object space,
  intersected at each ray's time (render/motion.py);
* **static**: ``shutter_motion=False``: the same shapes frozen at the frame's pose in the main scene.

Each on frozen passes (``dr.freeze`` replays, as datasets render) and traced afresh
(``FREEZE_PASSES = False``). Each timed call follows ``WARM_UP`` untimed ones on the same scene
(compilation and recording), ``--repeats`` rounds; medians are compared.

    .venv/bin/python bench/object_motion_cost.py [--objects 8] [--size 64] [--spp 16] [--repeats 5]

Prints seconds per frame and the ratios moving / static (the target is <= 1.5 with 8 moving objects).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pxr import Gf, UsdGeom  # noqa: E402

from denoisebench.generator.contract.render_plan import make_render_plan  # noqa: E402
from denoisebench.generator.render import passes as render_passes  # noqa: E402
from denoisebench.generator.render.frame import render_frame  # noqa: E402
from denoisebench.generator.render.scene import build_mitsuba_scene  # noqa: E402
from denoisebench.generator.usd.translate import translate_stage  # noqa: E402
from denoisebench.scenes import camera_paths, geometry  # noqa: E402
from denoisebench.scenes.authoring import SceneBuilder  # noqa: E402

FRAMES = 3
#: Untimed calls before each timed one: compilation, and the frozen pass's recordings (a scene with
#: moving shapes is recorded twice: Dr.Jit 1.5 records a function over two or more mi.Scene inputs again
#: on its third call, then replays).
WARM_UP = 3


def moving_stage(folder: Path, objects: int):
    """A stage with ``objects`` shapes moving within a one-frame shutter (deterministic)."""
    rng = np.random.default_rng(7)
    b = SceneBuilder(
        folder, family="bench", seed=0, frames=FRAMES, effects=("motion_blur", "area_lights", "environment")
    )
    b.mesh("Floor", geometry.grid(10.0, 10.0, 1, 1, axis="y"), b.material("Floor", diffuse=(0.6, 0.6, 0.6)))
    b.mesh("Wall", geometry.quad([(-5, 0, -3), (5, 0, -3), (5, 4, -3), (-5, 4, -3)]), b.material("Wall"))
    for i in range(objects):
        data = geometry.box(size=(0.4, 0.4, 0.4)) if i % 2 else geometry.uv_sphere(0.25, segments=24, rings=12)
        prim = b.mesh(f"Object{i}", data, b.material(f"Object{i}", diffuse=rng.uniform(0.2, 0.9, 3), roughness=0.4))
        xform = UsdGeom.Xformable(prim)
        translate, rotate = xform.AddTranslateOp(), xform.AddRotateYOp()
        start = np.array([-2.0 + 4.0 * i / max(objects - 1, 1), 0.3, rng.uniform(-1.5, 0.5)])
        step = rng.uniform(-0.4, 0.4, 3) * np.array([1.0, 0.0, 1.0])
        for f in range(FRAMES):
            translate.Set(Gf.Vec3d(*(start + step * f)), float(f))
            rotate.Set(float(40.0 * f), float(f))
    b.rect_light("Key", 2.0, 2.0, intensity=8.0, matrix=b.aim((0.5, 3.5, 2.0), (0.0, 0.0, -0.5)))
    b.dome_light("Sky", 0.3)
    eye = np.array([0.0, 1.6, 4.0])
    b.camera(camera_paths.dolly(eye, eye, (0.0, 0.4, -0.5), FRAMES, b.up, ease=False), 30.0, shutter=(-0.5, 0.5))
    return b.stage


def _time(scene, translated, plan, size, spp, freeze: bool) -> float:
    render_passes.FREEZE_PASSES = freeze
    start = time.perf_counter()
    render_frame(scene, translated.camera, 1, plan, width=size, height=size, spp=spp, seed=1)
    return time.perf_counter() - start


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--objects", type=int, default=8, help="moving shapes (default 8)")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    if args.objects < 1 or args.size < 1 or args.spp < 1 or args.repeats < 1:
        print("object_motion_cost: --objects, --size, --spp and --repeats must be >= 1", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as folder:
        translated = translate_stage(moving_stage(Path(folder), args.objects))
    plan = make_render_plan(translated.effects)
    moving = build_mitsuba_scene(translated, frame=1)
    static = build_mitsuba_scene(translated, frame=1, shutter_motion=False)
    runs = {
        "moving (frozen passes)": (moving, True),
        "moving (traced)": (moving, False),
        "static (frozen passes)": (static, True),
        "static (traced)": (static, False),
    }
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(args.repeats):
        for name, (scene, freeze) in runs.items():
            # Frozen passes are recorded per scene object (render/frame.py keeps one scene's): switching
            # scenes drops them, so each block warms up (records) before it is timed, as a dataset
            # frame's noisy and reference passes replay within that frame.
            for _ in range(WARM_UP):
                _time(scene, translated, plan, args.size, args.spp, freeze)
            times[name].append(_time(scene, translated, plan, args.size, args.spp, freeze))
    render_passes.FREEZE_PASSES = True
    print(
        f"{args.objects} moving objects, {args.size}x{args.size}, {args.spp} spp, {args.repeats} repeats (median, min)"
    )
    medians = {name: statistics.median(values) for name, values in times.items()}
    for name, values in times.items():
        print(f"  {name:24s} {medians[name]:.3f} s  (min {min(values):.3f} s)")
    moving_frozen, static_frozen = medians["moving (frozen passes)"], medians["static (frozen passes)"]
    print(f"ratio moving / static, both frozen:          {moving_frozen / static_frozen:.2f}")
    print(f"ratio moving / static, both traced:          {medians['moving (traced)'] / medians['static (traced)']:.2f}")
    print(
        f"ratio moving (frozen) / static (frozen) target <= 1.5: {'met' if moving_frozen <= 1.5 * static_frozen else 'NOT met'}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
