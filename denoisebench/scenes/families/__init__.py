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
        name="cornell",
        effects=("area_lights", "indirect"),
        description="Closed Cornell box: ceiling rect light, red/green walls as GeomSubsets of one room mesh, two blocks.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="slow dolly in",
        build=cornell.build,
    ),
    SceneFamily(
        name="glossy_fireflies",
        effects=("glossy", "area_lights"),
        description="Tiny intense sphere lights seen through brushed-metal floor and glossy metal spheres (fireflies).",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="partial orbit",
        build=glossy_fireflies.build,
    ),
    SceneFamily(
        name="dim_room",
        effects=("textures", "area_lights", "indirect"),
        description="Closed room lit by a rect light hidden behind a shelf facing the wall: mostly indirect light.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="handheld shake",
        build=dim_room.build,
    ),
    SceneFamily(
        name="thin_geometry",
        effects=("environment",),
        description="Sub-pixel wires, a welded-mesh fence and grass blades under a sun and a constant sky dome.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="pan",
        build=thin_geometry.build,
    ),
    SceneFamily(
        name="texture_checker",
        effects=("textures", "area_lights"),
        description="Fine checkerboard floor with a roughness map, zone plate board, striped cubes; Z-up stage.",
        up_axis="Z",
        meters_per_unit=1.0,
        camera_move="grazing dolly",
        build=texture_checker.build,
    ),
    SceneFamily(
        name="depth_of_field",
        effects=("depth_of_field", "textures", "area_lights"),
        description="Rows of objects from 2 to 11 m, f/1.2-2.0 50 mm lens focused on the third row, emissive bokeh balls.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="slow truck",
        build=depth_of_field.build,
    ),
    SceneFamily(
        name="motion_blur",
        effects=("motion_blur", "textures", "environment"),
        description="Whip pan (6-10 degrees per frame) through columns and striped boards, shutter -0.25..0.25 frames.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="fast pan",
        build=motion_blur.build,
    ),
    SceneFamily(
        name="glass_env",
        effects=("specular", "transmission", "environment"),
        description="Smooth glass, water and chrome on a pedestal under a textured studio dome light; centimeter stage.",
        up_axis="Y",
        meters_per_unit=0.01,
        camera_move="orbit",
        build=glass_env.build,
    ),
    SceneFamily(
        name="outdoor_sun",
        effects=("glossy", "textures", "environment"),
        description="Glossy metal sculptures on a textured meadow under a distant sun and a sky dome.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="handheld orbit",
        build=outdoor_sun.build,
    ),
    SceneFamily(
        name="moving_objects",
        effects=("textures", "area_lights"),
        description="A box slides and turns behind pillars, a ball rolls in front, a box spins (object motion; near-still camera).",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="slow push-in",
        build=moving_objects.build,
    ),
    SceneFamily(
        name="cluttered",
        effects=cluttered.EFFECTS,
        description="SBMC-style clutter: 10-50 procedural shapes, SBMC's material mix, textured, one rotated environment; "
        "depth of field and object motion blur each with p=0.5 (effects per seed); held-out test variants.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="partial orbit",
        build=cluttered.build,
    ),
    SceneFamily(
        name="fog_smoke",
        effects=("specular", "transmission", "environment", "media"),
        description="Participating media: a fog bank lit through a skylight, a smoke plume on a seeded density grid, "
        "a subsurface glass sphere.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="partial orbit",
        build=fog_smoke.build,
    ),
    SceneFamily(
        name="fur_field",
        effects=fur_field.EFFECTS,
        description="Production-style USD: thousands of grass curves and a furry critter (hair BSDF), an instanced field "
        "of pebbles and mushrooms (PointInstancer), MaterialX materials; held-out fur and prototype variants.",
        up_axis="Y",
        meters_per_unit=1.0,
        camera_move="low orbit",
        build=fur_field.build,
    ),
)
