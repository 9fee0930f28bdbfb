"""fur_field: USD as production assets write it: thousands of grass curves on a textured
ground, a furry critter, an instanced field of pebbles and mushrooms, MaterialX materials.

* **Curves**: grass blades are cubic B-spline ``BasisCurves`` (tapered widths) under a MaterialX
  ``standard_surface``; the critter's fur is B-spline strands normal to its body, with a
  ``denoisebench_hair`` surface on the ``denoisebench`` render context (Mitsuba's ``hair`` BSDF).
* **Instances**: one ``PointInstancer`` places pebbles and mushrooms (positions, quaternion yaw,
  scales, ``protoIndices``; a few ``invisibleIds``).
* **Materials**: every material carries a MaterialX network on ``outputs:mtlx:surface``
  (``ND_standard_surface_surfaceshader`` or ``ND_open_pbr_surface_surfaceshader``; the ground's base
  colour is ``ND_image_color3`` × ``ND_multiply_color3FA``) and, as production assets do, a
  ``UsdPreviewSurface`` fallback with the same values on the universal ``outputs:surface``.

Held-out variation: :func:`variant_pool` puts about :data:`HELD_OUT_FRACTION` of seeds in the
``held_out`` pool, which draws red (pheomelanin) fur and crystal prototypes instead of mushrooms;
the record is ``/World`` customData ``denoisebench:variants``.
"""

from __future__ import annotations

import hashlib

import numpy as np
from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

from denoisebench.scenes import camera_paths, geometry, textures
from denoisebench.scenes.authoring import SceneBuilder

EFFECTS = ("glossy", "textures", "environment")
HELD_OUT_FRACTION = 0.2
VARIANTS_KEY = "denoisebench:variants"
GRASS = (1500, 2500)
FUR = (800, 1200)
INSTANCES = (120, 200)


def variant_pool(seed: int) -> str:
    """``"held_out"`` or ``"train"``: a hash of the seed, the same on every machine."""
    digest = hashlib.blake2b(f"fur_field:{int(seed)}".encode(), digest_size=8).digest()
    return "held_out" if int.from_bytes(digest, "little") / 2.0**64 < HELD_OUT_FRACTION else "train"


def _mtlx(b: SceneBuilder, material: UsdShade.Material, surface: str, inputs: dict) -> UsdShade.Shader:
    """Add a MaterialX surface (``ND_<surface>_surfaceshader``) on ``outputs:mtlx:surface``."""
    path = material.GetPath()
    shader = UsdShade.Shader.Define(b.stage, path.AppendChild("MtlxSurface"))
    shader.CreateIdAttr(f"ND_{surface}_surfaceshader")
    for name, value in inputs.items():
        kind = Sdf.ValueTypeNames.Color3f if isinstance(value, tuple) else Sdf.ValueTypeNames.Float
        shader.CreateInput(name, kind).Set(Gf.Vec3f(*value) if isinstance(value, tuple) else float(value))
    material.CreateSurfaceOutput("mtlx").ConnectToSource(shader.ConnectableAPI(), "out")
    return shader


def _ground(b: SceneBuilder, rng: np.random.Generator) -> UsdShade.Material:
    noise = textures.value_noise(rng, 256, octaves=5, base_cells=8)
    soil = np.stack([0.35 + 0.2 * noise, 0.25 + 0.15 * noise, 0.12 + 0.08 * noise], axis=-1)
    asset = b.texture("soil", soil)
    tint = float(rng.uniform(0.8, 1.0))
    material = b.material("Soil", roughness=0.9, diffuse_texture=asset)
    shader = _mtlx(b, material, "standard_surface", {"specular_roughness": 0.9})
    image = UsdShade.Shader.Define(b.stage, material.GetPath().AppendChild("MtlxSoilImage"))
    image.CreateIdAttr("ND_image_color3")
    file_input = image.CreateInput("file", Sdf.ValueTypeNames.Asset)
    file_input.Set(Sdf.AssetPath(asset))
    file_input.GetAttr().SetColorSpace("srgb_texture")
    multiply = UsdShade.Shader.Define(b.stage, material.GetPath().AppendChild("MtlxTint"))
    multiply.CreateIdAttr("ND_multiply_color3FA")
    multiply.CreateInput("in1", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        image.CreateOutput("out", Sdf.ValueTypeNames.Color3f)
    )
    multiply.CreateInput("in2", Sdf.ValueTypeNames.Float).Set(tint)
    shader.CreateInput("base_color", Sdf.ValueTypeNames.Color3f).ConnectToSource(
        multiply.CreateOutput("out", Sdf.ValueTypeNames.Color3f)
    )
    return material


def _curves(b: SceneBuilder, name: str, roots: np.ndarray, directions: np.ndarray, length, rng, widths, material):
    """B-spline strands (5 control points) from ``roots`` along ``directions``, bending a little."""
    count = len(roots)
    t = np.linspace(0.0, 1.0, 5)[None, :, None]
    bend = rng.normal(scale=0.25, size=(count, 1, 3)) * (t**2)
    lengths = np.asarray(length)[:, None, None] if np.ndim(length) else length
    points = roots[:, None, :] + lengths * (directions[:, None, :] * t + bend)
    curves = UsdGeom.BasisCurves.Define(b.stage, b._path("/World/Geometry", name))
    curves.CreateTypeAttr(UsdGeom.Tokens.cubic)
    curves.CreateBasisAttr(UsdGeom.Tokens.bspline)
    curves.CreateWrapAttr(UsdGeom.Tokens.nonperiodic)
    curves.CreateCurveVertexCountsAttr(Vt.IntArray([5] * count))
    flat = np.round(points.reshape(-1, 3), 5).astype(np.float32)
    curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(flat))
    taper = np.tile(np.linspace(widths[0], widths[1], 5), count).astype(np.float32)
    curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(np.round(taper, 6)))
    curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    low, high = flat.min(0), flat.max(0)
    curves.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, low)), Gf.Vec3f(*map(float, high))]))
    b.bind(curves, material)
    return curves


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    pool = variant_pool(b.seed)
    ground = _ground(b, rng)
    b.mesh("Ground", geometry.grid(30.0, 30.0, 1, 1, axis="y", st_repeat=6.0), ground)

    # Grass: thousands of thin tapered B-spline blades on a patch around the critter.
    green = (float(rng.uniform(0.15, 0.3)), float(rng.uniform(0.4, 0.6)), float(rng.uniform(0.08, 0.15)))
    grass_material = b.material("Grass", diffuse=green, roughness=0.6)
    _mtlx(b, grass_material, "standard_surface", {"base_color": green, "specular_roughness": 0.6})
    count = int(rng.integers(*GRASS))
    radius = np.sqrt(rng.uniform(0.0, 1.0, count)) * 2.5
    angle = rng.uniform(0.0, 2 * np.pi, count)
    roots = np.stack([radius * np.cos(angle), np.zeros(count), radius * np.sin(angle)], -1)
    up = np.array([0.0, 1.0, 0.0]) + rng.normal(scale=0.15, size=(count, 3))
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    _curves(b, "Grass", roots, up, rng.uniform(0.15, 0.35, count), rng, (0.012, 0.002), grass_material)

    # The critter: a body with fur strands along its normals (hair BSDF via the denoisebench context).
    melanin = (0.2, 1.2) if pool == "held_out" else (float(rng.uniform(0.6, 1.6)), 0.0)
    body_colour = (0.55, 0.25, 0.1) if pool == "held_out" else (0.3, 0.22, 0.15)
    fur = b.material("Fur", diffuse=body_colour, roughness=0.25, metallic=1.0)
    hair = UsdShade.Shader.Define(b.stage, fur.GetPath().AppendChild("Hair"))
    hair.CreateIdAttr("denoisebench_hair")
    hair.CreateInput("eumelanin", Sdf.ValueTypeNames.Float).Set(float(melanin[0]))
    hair.CreateInput("pheomelanin", Sdf.ValueTypeNames.Float).Set(float(melanin[1]))
    hair.CreateInput("longitudinal_roughness", Sdf.ValueTypeNames.Float).Set(0.25)
    fur.CreateSurfaceOutput("denoisebench").ConnectToSource(hair.ConnectableAPI(), "surface")
    skin = b.material("Skin", diffuse=body_colour, roughness=0.7)
    _mtlx(b, skin, "open_pbr_surface", {"base_color": body_colour, "specular_roughness": 0.7})
    body_radius = float(rng.uniform(0.3, 0.4))
    centre = np.array([0.0, body_radius * 0.9, 0.0])
    b.mesh("Body", geometry.uv_sphere(body_radius, 24, 12), skin, translate=tuple(centre))
    strands = int(rng.integers(*FUR))
    normals = rng.normal(size=(strands, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[:, 1] = np.abs(normals[:, 1]) * 0.8 + 0.2 * normals[:, 1]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    _curves(b, "Fur", centre + normals * body_radius * 0.98, normals, 0.08, rng, (0.006, 0.001), fur)

    # An instanced field: pebbles and mushrooms (held out: crystals) around the grass patch.
    _field(b, rng, pool)

    sun_az, sun_el = rng.uniform(0.0, 360.0), rng.uniform(25.0, 55.0)
    sky = b.texture("sky", textures.sky_latlong(256, 128, sun_az, sun_el, sun_radius_deg=3.0))
    b.dome_light("Sky", intensity=float(rng.uniform(0.8, 1.2)), texture=sky)
    el, az = np.deg2rad(sun_el), np.deg2rad(sun_az)
    b.distant_light(
        "Sun",
        0.53,
        intensity=float(rng.uniform(3.0, 4.5)),
        color=(1.0, 0.95, 0.85),
        direction=-np.array([np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az)]),
    )
    poses = camera_paths.orbit(
        (0.0, 0.3, 0.0),
        float(rng.uniform(2.2, 3.0)),
        float(rng.uniform(0.6, 1.0)),
        float(rng.uniform(0.0, 360.0)),
        float(rng.choice([-1.0, 1.0]) * rng.uniform(6.0, 12.0)),
        b.frames,
        b.up,
    )
    b.camera(poses, focal_length_mm=35.0, clipping=(0.02, 200.0))
    b.stage.GetPrimAtPath("/World").SetCustomDataByKey(
        VARIANTS_KEY,
        {"pool": pool, "prototypes": ["pebble", "crystal" if pool == "held_out" else "mushroom"], "fur": pool},
    )


def _field(b: SceneBuilder, rng: np.random.Generator, pool: str) -> None:
    instancer = UsdGeom.PointInstancer.Define(b.stage, b._path("/World/Geometry", "Field"))
    stone_colour = (0.45, 0.43, 0.4)
    stone = b.material("Stone", diffuse=stone_colour, roughness=0.8)
    _mtlx(b, stone, "open_pbr_surface", {"base_color": stone_colour, "specular_roughness": 0.8})
    pebble_root = UsdGeom.Xform.Define(b.stage, b._path(str(instancer.GetPath()), "Pebble"))
    b.mesh(
        "PebbleMesh", geometry.uv_sphere(0.08, 16, 8), stone, scale=(1.4, 0.6, 1.0), parent=str(pebble_root.GetPath())
    )
    second = UsdGeom.Xform.Define(b.stage, b._path(str(instancer.GetPath()), "Second"))
    if pool == "held_out":
        crystal_colour = (0.6, 0.3, 0.8)
        crystal = b.material("Crystal", diffuse=crystal_colour, roughness=0.3, metallic=1.0)
        _mtlx(
            b, crystal, "standard_surface", {"base_color": crystal_colour, "metalness": 1.0, "specular_roughness": 0.3}
        )
        b.mesh(
            "CrystalMesh",
            geometry.box((0.06, 0.2, 0.06), center=(0.0, 0.1, 0.0)),
            crystal,
            parent=str(second.GetPath()),
        )
    else:
        cap_colour = (0.7, 0.1, 0.05)
        cap = b.material("Cap", diffuse=cap_colour, roughness=0.3, metallic=1.0)
        _mtlx(b, cap, "standard_surface", {"base_color": cap_colour, "metalness": 1.0, "specular_roughness": 0.3})
        stem = b.material("Stem", diffuse=(0.85, 0.82, 0.75), roughness=0.7)
        _mtlx(b, stem, "standard_surface", {"base_color": (0.85, 0.82, 0.75), "specular_roughness": 0.7})
        b.mesh(
            "StemMesh", geometry.box((0.03, 0.12, 0.03), center=(0.0, 0.06, 0.0)), stem, parent=str(second.GetPath())
        )
        b.mesh(
            "CapMesh",
            geometry.uv_sphere(0.07, 16, 8),
            cap,
            translate=(0.0, 0.12, 0.0),
            scale=(1.0, 0.5, 1.0),
            parent=str(second.GetPath()),
        )
    rel = instancer.CreatePrototypesRel()
    rel.AddTarget(pebble_root.GetPath())
    rel.AddTarget(second.GetPath())
    count = int(rng.integers(*INSTANCES))
    radius = rng.uniform(2.6, 4.5, count)
    angle = rng.uniform(0.0, 2 * np.pi, count)
    positions = np.round(np.stack([radius * np.cos(angle), np.zeros(count), radius * np.sin(angle)], -1), 5)
    yaw = rng.uniform(0.0, np.pi, count)
    instancer.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(positions.astype(np.float32)))
    instancer.CreateOrientationsAttr(
        Vt.QuathArray([Gf.Quath(float(np.cos(a)), 0.0, float(np.sin(a)), 0.0) for a in yaw])
    )
    scales = np.round(rng.uniform(0.6, 1.6, count), 4)
    instancer.CreateScalesAttr(Vt.Vec3fArray([Gf.Vec3f(float(s), float(s), float(s)) for s in scales]))
    instancer.CreateProtoIndicesAttr(Vt.IntArray([int(i) for i in rng.integers(0, 2, count)]))
    instancer.CreateInvisibleIdsAttr(Vt.Int64Array([int(i) for i in rng.choice(count, size=3, replace=False)]))
