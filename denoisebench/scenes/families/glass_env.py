"""glass_env: glass and chrome on a pedestal floor under an image-based studio dome; centimeters."""

from __future__ import annotations

import numpy as np

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder

CM = 1.0  # the stage is in centimeters (metersPerUnit 0.01): 1 unit = 1 cm


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    floor = b.material("Floor", diffuse=rng.uniform(0.4, 0.6, 3), roughness=0.9)
    b.mesh("Floor", geometry.grid(1000 * CM, 1000 * CM, 1, 1, axis="y"), floor)
    pedestal = b.material("Pedestal", diffuse=(0.75, 0.75, 0.75), roughness=0.8)
    b.cylinder("Pedestal", 90 * CM, 10 * CM, "Y", pedestal, translate=(0.0, 5 * CM, 0.0))

    # Clear dielectrics: opacity 0 with an ior, perfectly smooth (specular + transmission).
    glass = b.material("Glass", diffuse=(1.0, 1.0, 1.0), roughness=0.0, opacity=0.0, ior=rng.uniform(1.45, 1.55))
    tinted = b.material(
        "TintedGlass",
        diffuse=(rng.uniform(0.6, 0.9), rng.uniform(0.8, 1.0), rng.uniform(0.85, 1.0)),
        roughness=0.0,
        opacity=0.0,
        ior=1.5,
    )
    water = b.material("Water", diffuse=(1.0, 1.0, 1.0), roughness=0.0, opacity=0.0, ior=1.33)
    chrome = b.material("Chrome", diffuse=(0.95, 0.95, 0.95), roughness=0.0, metallic=1.0)

    top = 10 * CM
    r = rng.uniform(22, 32) * CM
    b.sphere("GlassBall", r, glass, translate=(rng.uniform(-45, -30) * CM, top + r, rng.uniform(-10, 10) * CM))
    s = rng.uniform(30, 40) * CM
    b.cube(
        "GlassBlock",
        s,
        tinted,
        translate=(rng.uniform(20, 40) * CM, top + s / 2, rng.uniform(-35, -15) * CM),
        rotate=(0.0, rng.uniform(0.0, 90.0), 0.0),
    )
    h = rng.uniform(35, 50) * CM
    b.cylinder(
        "WaterColumn",
        rng.uniform(10, 14) * CM,
        h,
        "Y",
        water,
        translate=(rng.uniform(-10, 10) * CM, top + h / 2, rng.uniform(-50, -35) * CM),
    )
    rc = rng.uniform(14, 20) * CM
    b.mesh(
        "ChromeBall",
        geometry.uv_sphere(rc, 32, 16),
        chrome,
        translate=(rng.uniform(25, 45) * CM, top + rc, rng.uniform(20, 40) * CM),
    )

    # Image-based studio lighting only.
    env = b.texture("studio_env", textures.studio_latlong(512, 256, rng))
    b.dome_light("Studio", intensity=rng.uniform(1.5, 2.5), texture=env)

    # Orbit around the pedestal.
    poses = camera_paths.orbit(
        (0.0, 30 * CM, 0.0),
        rng.uniform(260, 320) * CM,
        rng.uniform(60, 110) * CM,
        90.0 + rng.uniform(-30.0, 30.0),
        rng.choice([-1.0, 1.0]) * rng.uniform(20.0, 40.0),
        b.frames,
        b.up,
    )
    b.camera(poses, focal_length_mm=40.0, clipping=(1.0 * CM, 10000.0 * CM))
