"""What a PointInstancer costs against the same instances written out as plain prims (issue 44).

Authors two stages with N copies of a 2 208-triangle prototype on a grid (one ``PointInstancer``; N
``Xform`` + ``Mesh`` prims), then, each in its own process (peak memory apart), translates it,
builds the Mitsuba scene and renders 64×64 at 4 spp with Mitsuba ``path``::

    .venv/bin/python bench/instancer_cost.py --count 10000

Measured on 2 cores (llvm_ad_rgb), N = 1 000: instanced 0.1 s translate, 0.2 s build, 95 s render
(Mitsuba 3.9 traces each instance as its own nested virtual call) before the renderer merged groups
above ``render.scene.INSTANCE_LIMIT``; merged, N = 10 000: 0.1 s translate, 59 s build (one 22 M
triangle mesh), 0.6 s render, 2.9 GiB peak.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def author(path: Path, count: int, instanced: bool) -> None:
    from pxr import Gf, Usd, UsdGeom, UsdLux

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    camera = UsdGeom.Camera.Define(stage, "/Camera")
    camera.AddTranslateOp().Set(Gf.Vec3d(0, 30, 80))
    camera.AddRotateXOp().Set(-20.0)
    UsdLux.DomeLight.Define(stage, "/Dome")
    side = int(np.ceil(np.sqrt(count)))
    positions = [(float(i % side - side / 2), 0.0, float(i // side - side / 2)) for i in range(count)]
    u, v = np.meshgrid(np.linspace(0, np.pi, 24), np.linspace(0, 2 * np.pi, 48), indexing="ij")
    points = np.stack([np.sin(u) * np.cos(v), np.cos(u) + 0.5, np.sin(u) * np.sin(v)], -1).reshape(-1, 3) * 0.3
    index = np.arange(24 * 48).reshape(24, 48)
    quads = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], -1).reshape(-1, 4)

    def prototype(path: str) -> None:
        mesh = UsdGeom.Mesh.Define(stage, path + "/Mesh")
        mesh.CreatePointsAttr([tuple(map(float, p)) for p in points])
        mesh.CreateFaceVertexCountsAttr([4] * len(quads))
        mesh.CreateFaceVertexIndicesAttr(quads.reshape(-1).tolist())

    if instanced:
        instancer = UsdGeom.PointInstancer.Define(stage, "/World/Instancer")
        UsdGeom.Xform.Define(stage, "/World/Instancer/Prototype")
        prototype("/World/Instancer/Prototype")
        instancer.CreatePrototypesRel().AddTarget("/World/Instancer/Prototype")
        instancer.CreatePositionsAttr([Gf.Vec3f(*p) for p in positions])
        instancer.CreateProtoIndicesAttr([0] * count)
    else:
        for i, position in enumerate(positions):
            holder = UsdGeom.Xform.Define(stage, f"/World/X{i}")
            holder.AddTranslateOp().Set(Gf.Vec3d(*position))
            prototype(f"/World/X{i}")
    stage.GetRootLayer().Save()


def measure(path: str) -> dict:
    from denoisebench.generator.render.scene import build_mitsuba_scene, sensor_dict
    from denoisebench.generator.usd.translate import translate_usd
    from denoisebench.mitsuba_runtime import load_mitsuba

    mi = load_mitsuba()
    start = time.perf_counter()
    translated = translate_usd(path)
    translate = time.perf_counter() - start
    start = time.perf_counter()
    scene = build_mitsuba_scene(translated, sensor_dict(translated.camera, 0, 64, 64, 4), {"type": "path"})
    build = time.perf_counter() - start
    start = time.perf_counter()
    image = np.array(mi.render(scene))
    render = time.perf_counter() - start
    return {
        "translate_s": round(translate, 2),
        "build_s": round(build, 2),
        "render_s": round(render, 2),
        "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
        "mean": float(image.mean()),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=10000)
    parser.add_argument("--measure", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        print(json.dumps(measure(args.measure)))
        return
    folder = Path(tempfile.mkdtemp(prefix="instancer-cost-"))
    for mode in ("instanced", "flat"):
        path = folder / f"{mode}.usda"
        author(path, args.count, mode == "instanced")
        out = subprocess.run(
            [sys.executable, __file__, "--measure", str(path)], capture_output=True, text=True, check=True
        )
        print(mode, args.count, out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    main()
