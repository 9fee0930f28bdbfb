"""The scene families, one module each; ``ALL`` is their registration order.

Each family declares exactly the effects its stages exercise, so that the translator's inference
(fStop > 0, open shutter with a moving camera, roughness/metallic/opacity, UsdUVTexture, light
types) agrees with the declaration; ``indirect`` is declared where multi-bounce light dominates.
"""

from __future__ import annotations

from denoisebench.scenes.families import (
    cluttered,
    cornell,
    depth_of_field,
    dim_room,
    fog_smoke,
    fur_field,
    glass_env,
    glossy_fireflies,
    motion_blur,
    moving_objects,
    outdoor_sun,
    texture_checker,
    thin_geometry,
)
from denoisebench.scenes.family import SceneFamily

ALL: tuple[SceneFamily, ...] = (
    SceneFamily(
        "cornell",
        ("area_lights", "indirect"),
        "Closed Cornell box: ceiling rect light, red/green walls as GeomSubsets of one room mesh, two blocks.",
        "Y",
        1.0,
        "slow dolly in",
        cornell.build,
    ),
    SceneFamily(
        "glossy_fireflies",
        ("glossy", "area_lights"),
        "Tiny intense sphere lights seen through brushed-metal floor and glossy metal spheres (fireflies).",
        "Y",
        1.0,
        "partial orbit",
        glossy_fireflies.build,
    ),
    SceneFamily(
        "dim_room",
        ("textures", "area_lights", "indirect"),
        "Closed room lit by a rect light hidden behind a shelf facing the wall: mostly indirect light.",
        "Y",
        1.0,
        "handheld shake",
        dim_room.build,
    ),
    SceneFamily(
        "thin_geometry",
        ("environment",),
        "Sub-pixel wires, a welded-mesh fence and grass blades under a sun and a constant sky dome.",
        "Y",
        1.0,
        "pan",
        thin_geometry.build,
    ),
    SceneFamily(
        "texture_checker",
        ("textures", "area_lights"),
        "Fine checkerboard floor with a roughness map, zone plate board, striped cubes; Z-up stage.",
        "Z",
        1.0,
        "grazing dolly",
        texture_checker.build,
    ),
    SceneFamily(
        "depth_of_field",
        ("depth_of_field", "textures", "area_lights"),
        "Rows of objects from 2 to 11 m, f/1.2-2.0 50 mm lens focused on the third row, emissive bokeh balls.",
        "Y",
        1.0,
        "slow truck",
        depth_of_field.build,
    ),
    SceneFamily(
        "motion_blur",
        ("motion_blur", "textures", "environment"),
        "Whip pan (6-10 degrees per frame) through columns and striped boards, shutter -0.25..0.25 frames.",
        "Y",
        1.0,
        "fast pan",
        motion_blur.build,
    ),
    SceneFamily(
        "glass_env",
        ("specular", "transmission", "environment"),
        "Smooth glass, water and chrome on a pedestal under a textured studio dome light; centimeter stage.",
        "Y",
        0.01,
        "orbit",
        glass_env.build,
    ),
    SceneFamily(
        "outdoor_sun",
        ("glossy", "textures", "environment"),
        "Glossy metal sculptures on a textured meadow under a distant sun and a sky dome.",
        "Y",
        1.0,
        "handheld orbit",
        outdoor_sun.build,
    ),
    SceneFamily(
        "moving_objects",
        ("textures", "area_lights"),
        "A box slides and turns behind pillars, a ball rolls in front, a box spins (object motion; near-still camera).",
        "Y",
        1.0,
        "slow push-in",
        moving_objects.build,
    ),
    SceneFamily(
        "cluttered",
        cluttered.EFFECTS,
        "SBMC-style clutter: 10-50 procedural shapes, SBMC's material mix, textured, one rotated environment; "
        "depth of field and object motion blur each with p=0.5 (effects per seed); held-out test variants.",
        "Y",
        1.0,
        "partial orbit",
        cluttered.build,
    ),
    SceneFamily(
        "fog_smoke",
        ("specular", "transmission", "environment", "media"),
        "Participating media: a fog bank lit through a skylight, a smoke plume on a seeded density grid, "
        "a subsurface glass sphere.",
        "Y",
        1.0,
        "partial orbit",
        fog_smoke.build,
    ),
    SceneFamily(
        "fur_field",
        fur_field.EFFECTS,
        "Production-style USD: thousands of grass curves and a furry critter (hair BSDF), an instanced field "
        "of pebbles and mushrooms (PointInstancer), MaterialX materials; held-out fur and prototype variants.",
        "Y",
        1.0,
        "low orbit",
        fur_field.build,
    ),
)
