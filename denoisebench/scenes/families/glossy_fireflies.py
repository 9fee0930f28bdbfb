"""glossy_fireflies: tiny, very bright sphere lights seen in glossy metal (firefly bait a reference resolves).

Notes
-----
The fireflies of a low-spp render come from glossy reflections of small intense lights: paths
camera → glossy metal → light, which next-event estimation with MIS samples well, and one-bounce
chains (metal → metal or floor → light) that are rare at 1–4 spp but that a path-traced reference
converges on. The family is built so that its reference converges; the earlier design's did not: caustic paths
(tiny light → near-mirror sphere, roughness down to 0.05 → dark diffuse backdrop or mirror-like
floor) are found by a path tracer only by chance, so its floor estimate did not fall with spp.
What changed, and why (each measured with ``bench/reference_floor.py``, 64 px, 3 scenes, seeds
900–902, references forced to 256 and 1024 spp):

* Every glossy surface has roughness 0.3–0.38: a rough vertex followed by a much sharper one
  before the light is the caustic pattern (its value is high only in a small region that the
  rough vertex's sampling rarely hits). A mirror-like floor (0.02–0.04) made it worse.
* No dark diffuse backdrop (it received the spheres' caustics: 23 % of the floor); the floor is
  a dielectric (diffuse 0.3 under a glossy coat), so the scene keeps a diffuse lobe.
* The tiny lights (radius 0.024–0.029 m, radiance 1.2–3·10⁴) hang above and in front of the
  objects, so their glossy reflections face the camera; the fill is brighter (20–30, was
  0.4–0.8), so the one-bounce chains are a smaller share of the pixels they reach.

Measured (``bench/reference_floor.py --family glossy_fireflies --ref-spp 256,1024 --size 64 --scenes 3``):
reference floors 0.00040 / 0.0011 / 0.0011 at 1024 spp, falling 2.4–3.6× from 256 spp, growth
1.04–1.16 (below the 1.25 at which a floor counts as still growing); the layouts rejected above gave
0.0069 / 0.027 / 0.017, not falling from 256 spp (ratio 0.68–1.06), growth 1.8–2.4. Direct light alone
(``--max-depth 2``) falls exactly as 1/spp (ratio 3.9–4.0, growth 0.98–1.0): the glossy
highlights themselves are resolved; what is left is one-bounce glossy transport.
Still hard for denoisers (64 px, 4 frames, 1024-spp reference): at 4 spp the noisy input's robust
relMSE is 0.048, cross_bilateral's 0.012 and OIDN's 2.3 (its raw relMSE 952: it spreads the
directly seen sub-pixel lights over the black background).
"""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry
from denoisebench.scenes.authoring import SceneBuilder

_METAL_TINTS = [(0.95, 0.93, 0.88), (1.0, 0.78, 0.34), (0.95, 0.64, 0.54), (0.91, 0.92, 0.92), (0.55, 0.56, 0.58)]

#: Every light of this family smaller than this radius (meters) counts as "small".
SMALL_LIGHT_RADIUS = 0.03


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    # A glossy dielectric floor (diffuse under a coat as rough as the metals: see Notes). No backdrop.
    floor = b.material("Floor", diffuse=(0.3, 0.3, 0.32), metallic=0.0, roughness=rng.uniform(0.3, 0.38))
    b.mesh("Floor", geometry.grid(10.0, 10.0, 1, 1, axis="y"), floor)

    # Glossy metal spheres and blocks on an arc.
    count = int(rng.integers(5, 8))
    angles = np.linspace(-60.0, 60.0, count) + rng.uniform(-6.0, 6.0, count)
    for i, ang in enumerate(angles):
        tint = _METAL_TINTS[int(rng.integers(len(_METAL_TINTS)))]
        mat = b.material(f"Metal{i}", diffuse=tint, metallic=1.0, roughness=rng.uniform(0.3, 0.38))
        dist = rng.uniform(1.0, 1.8)
        x, z = dist * np.sin(np.deg2rad(ang)), -dist * np.cos(np.deg2rad(ang)) + 0.5
        if rng.random() < 0.7:
            r = rng.uniform(0.2, 0.4)
            b.sphere(f"Sphere{i}", r, mat, translate=(x, r, z))
        else:
            s = rng.uniform(0.3, 0.5)
            b.cube(f"Block{i}", s, mat, translate=(x, s / 2, z), rotate=(0.0, rng.uniform(0.0, 90.0), 0.0))

    # The fireflies' source: one or two tiny, intense sphere lights above and in front of the objects.
    for k in range(int(rng.integers(1, 3))):
        radius = rng.uniform(0.024, 0.029)
        b.sphere_light(
            f"TinyLight{k}",
            radius,
            intensity=rng.uniform(1.2e4, 3.0e4),
            color=(1.0, rng.uniform(0.85, 0.95), rng.uniform(0.7, 0.85)),
            translate=(rng.uniform(-1.5, 1.5), rng.uniform(1.2, 2.0), rng.uniform(-0.5, 1.0)),
        )
    # A fill bright enough that one-bounce glossy chains are a small share of what they reach.
    b.rect_light("Fill", 2.0, 1.0, intensity=rng.uniform(20.0, 30.0), matrix=b.aim((0.0, 3.0, 3.0), (0.0, 0.3, 0.0)))

    # Partial orbit around the arc.
    start = 90.0 + rng.uniform(-15.0, 15.0)
    poses = camera_paths.orbit(
        (0.0, 0.3, 0.0),
        rng.uniform(3.6, 4.2),
        rng.uniform(0.5, 0.9),
        start,
        rng.choice([-1.0, 1.0]) * rng.uniform(12.0, 20.0),
        b.frames,
        b.up,
    )
    b.camera(poses, focal_length_mm=32.0, clipping=(0.05, 50.0))
