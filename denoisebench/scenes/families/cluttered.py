"""cluttered: 10-50 procedural objects on a ground plane, made the way SBMC makes its training scenes.

Following Gharbi et al. 2019 (SBMC's scene generator), with a richer shape library:

* objects: 10-50 shapes from :mod:`denoisebench.scenes.shapes` (superquadrics, tori, rocks, vases,
  bevelled and twisted boxes, rods, leaves) at random scale and rotation about the vertical, placed
  by Poisson-disc dart throwing on the ground so that their footprint circles (inflated by their
  travel when they move) never overlap: no interpenetration at any time;
* materials: SBMC's mix on UsdPreviewSurface (:data:`MATERIAL_MIX`: mirror 5 %, glass 5 %, metal
  10 %, plastic 20 %, substrate 10 %, uber 30 %, matte 20 %); the first three objects are glass,
  metal and mirror so that every stage has the same material effects; every non-delta material has a
  procedural texture (:mod:`denoisebench.scenes.procedural_textures`) written as a PNG, sampled
  through a ``UsdTransform2d`` at a random UV scale (0.5-8);
* light: one procedural environment (:mod:`denoisebench.scenes.environments`), rotated about the
  vertical at random, with a ``DistantLight`` sun for the sunny kinds;
* camera: random field of view (focal length 20-60 mm), a partial orbit over the sequence; depth of
  field with probability 0.5, focused on one of the objects; object motion blur with probability
  0.5: then up to :data:`MAX_MOVING` objects translate (0.08-0.25 units per frame) and turn (up to
  :data:`SPIN` degrees per frame), and the shutter is open half a frame.

Effects therefore vary by seed: the stage's metadata declares its own (``depth_of_field`` and
``motion_blur`` when drawn), and the family's effects are their union.

Held-out variation (as Kubric holds out objects and backgrounds): :func:`variant_pool` puts a seed
in the ``held_out`` pool (about :data:`HELD_OUT_FRACTION` of seeds) or the ``train`` pool; held-out
stages draw shape kinds, texture kinds and environments from :data:`HELD_OUT` that train stages never
use (:data:`TRAIN`). The pool and the variants drawn are recorded on ``/World`` as
``customData["denoisebench:variants"]`` and read by :func:`stage_variants`.
"""

from __future__ import annotations

import hashlib

import numpy as np
from pxr import Gf, Sdf, UsdGeom, UsdShade

from denoisebench.scenes import camera_paths, environments, geometry, procedural_textures, shapes
from denoisebench.scenes.authoring import SceneBuilder
from denoisebench.scenes.effects import validate_effects

#: SBMC's material mix (Gharbi et al. 2019), as fractions.
MATERIAL_MIX = {
    "mirror": 0.05,
    "glass": 0.05,
    "metal": 0.10,
    "plastic": 0.20,
    "substrate": 0.10,
    "uber": 0.30,
    "matte": 0.20,
}
#: Effects of every cluttered stage; ``depth_of_field`` and ``motion_blur`` are drawn per seed.
ALWAYS = ("glossy", "specular", "transmission", "textures", "environment")
EFFECTS = validate_effects(ALWAYS + ("depth_of_field", "motion_blur"))
#: Most objects that move within the shutter (the cost of object motion blur grows with them).
MAX_MOVING = 6
#: Largest turn of a moving object about the vertical, degrees per frame. Turning costs no room on the
#: ground (travel inflates an object's footprint for the whole sequence and so the stage, which the camera
#: then frames from further away), so it carries most of the blur: at 150 degrees per frame a 0.5-unit
#: object's rim sweeps up to 0.65 units in the half-frame shutter, about 4 px of a 64 px frame.
SPIN = 150.0
#: Objects per stage.
OBJECTS = (10, 50)
#: Share of seeds in the held-out pool.
HELD_OUT_FRACTION = 0.2
#: Variants each pool draws from: shape kinds, texture kinds, environments (disjoint across pools).
TRAIN = {
    "shapes": ("superquadric", "torus", "rock", "vase", "bevelled_box", "rod"),
    "textures": ("noise", "stripes", "checks"),
    "environments": ("sky_sun", "overcast", "studio"),
}
HELD_OUT = {"shapes": ("twisted_box", "leaf"), "textures": ("marble", "wood"), "environments": ("sunset",)}
#: Key of the variants record in ``/World``'s customData.
VARIANTS_KEY = "denoisebench:variants"
TEXTURE_SIZE = 128


def variant_pool(seed: int) -> str:
    """``"held_out"`` or ``"train"``: a hash of the seed (BLAKE2b), the same on every machine."""
    digest = hashlib.blake2b(f"cluttered:{int(seed)}".encode(), digest_size=8).digest()
    return "held_out" if int.from_bytes(digest, "little") / 2.0**64 < HELD_OUT_FRACTION else "train"


def stage_variants(stage) -> dict:
    """The variants record of a cluttered stage (``{}`` for other stages)."""
    world = stage.GetPrimAtPath("/World")
    data = world.GetCustomDataByKey(VARIANTS_KEY) if world else None
    return {k: (list(v) if not isinstance(v, str) else v) for k, v in dict(data or {}).items()}


def _material(b: SceneBuilder, name: str, kind: str, rng: np.random.Generator, texture: str | None):
    """A UsdPreviewSurface of SBMC's ``kind`` (the textured kinds sample ``texture`` at a random UV scale)."""
    if kind == "mirror":
        return b.material(name, diffuse=rng.uniform(0.85, 1.0, 3), roughness=0.0, metallic=1.0)
    if kind == "glass":
        return b.material(name, diffuse=(1.0, 1.0, 1.0), roughness=0.0, opacity=0.0, ior=rng.uniform(1.4, 1.6))
    if kind == "metal":
        return b.material(name, diffuse=rng.uniform(0.5, 1.0, 3), roughness=rng.uniform(0.08, 0.35), metallic=1.0)
    roughness = {
        "plastic": rng.uniform(0.1, 0.35),
        "substrate": rng.uniform(0.3, 0.6),
        "uber": rng.uniform(0.05, 1.0),
        "matte": 1.0,
    }[kind]
    metallic = float(rng.uniform(0.0, 1.0)) if kind == "uber" and rng.random() < 0.3 else 0.0
    if metallic > 0.5:
        roughness = max(roughness, 0.08)  # textured metals stay glossy, never a near-delta lobe
    material = b.material(
        name, diffuse=(1.0, 1.0, 1.0), roughness=roughness, metallic=metallic, diffuse_texture=texture
    )
    _uv_scale(b, material, float(np.exp(rng.uniform(np.log(0.5), np.log(8.0)))))
    return material


def _uv_scale(b: SceneBuilder, material, scale: float) -> None:
    """Insert a ``UsdTransform2d`` (uniform ``scale``) between the material's st reader and its texture."""
    path = material.GetPath()
    texture = UsdShade.Shader(b.stage.GetPrimAtPath(path.AppendChild("DiffuseTexture")))
    reader = UsdShade.Shader(b.stage.GetPrimAtPath(path.AppendChild("StReader")))
    transform = UsdShade.Shader.Define(b.stage, path.AppendChild("StTransform"))
    transform.CreateIdAttr("UsdTransform2d")
    transform.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.GetOutput("result"))
    transform.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(round(scale, 4), round(scale, 4)))
    out = transform.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    texture.GetInput("st").ConnectToSource(out)


def _place(rng: np.random.Generator, radii: np.ndarray, area: float, gap: float = 0.05) -> np.ndarray:
    """Poisson-disc dart throwing of discs of ``radii`` in a disc of radius ``area`` (largest first).

    Returns N×2 centres; a disc that finds no room after many darts goes to a ring outside the rest."""
    order = np.argsort(-radii, kind="stable")
    centres = np.zeros((len(radii), 2))
    placed: list[int] = []
    for i in order:
        for _ in range(400):
            r = area * np.sqrt(rng.random())
            angle = rng.uniform(0.0, 2.0 * np.pi)
            candidate = np.array([r * np.cos(angle), r * np.sin(angle)])
            if all(np.linalg.norm(candidate - centres[j]) >= radii[i] + radii[j] + gap for j in placed):
                break
        else:  # no room: beyond everything placed so far
            reach = max((np.linalg.norm(centres[j]) + radii[j] for j in placed), default=0.0)
            angle = rng.uniform(0.0, 2.0 * np.pi)
            candidate = (reach + radii[i] + gap) * np.array([np.cos(angle), np.sin(angle)])
        centres[i] = candidate
        placed.append(i)
    return centres


def build(b: SceneBuilder, rng: np.random.Generator) -> None:
    pool = variant_pool(b.seed)
    variants = HELD_OUT if pool == "held_out" else TRAIN
    depth_of_field = bool(rng.random() < 0.5)
    motion_blur = bool(rng.random() < 0.5)
    b.effects = validate_effects(
        ALWAYS + (("depth_of_field",) if depth_of_field else ()) + (("motion_blur",) if motion_blur else ())
    )

    # Textures: a few per stage, shared by the textured materials.
    texture_kinds = [str(k) for k in rng.choice(variants["textures"], size=4)]
    texture_assets = [
        b.texture(f"tex{i}_{kind}", procedural_textures.make(kind, rng, TEXTURE_SIZE))
        for i, kind in enumerate(texture_kinds)
    ]

    # Ground: a large matte or substrate plane with its own texture.
    ground_kind = str(rng.choice(["matte", "substrate"]))
    ground = _material(b, "Ground", ground_kind, rng, texture_assets[0])
    b.mesh("Ground", geometry.grid(60.0, 60.0, 1, 1, axis="y", st_repeat=12.0), ground)

    count = int(rng.integers(OBJECTS[0], OBJECTS[1] + 1))
    kinds_of_material = list(MATERIAL_MIX)
    weights = np.array(list(MATERIAL_MIX.values()))
    materials = ["glass", "metal", "mirror"] + [
        str(k) for k in rng.choice(kinds_of_material, size=count - 3, p=weights / weights.sum())
    ]
    shape_kinds = [str(k) for k in rng.choice(variants["shapes"], size=count)]
    meshes = [shapes.make(kind, rng, float(rng.uniform(0.3, 0.9))) for kind in shape_kinds]

    # Movers: up to MAX_MOVING objects travel (speed per frame) and turn, only with motion blur.
    movers = set()
    if motion_blur:
        movers = {
            int(i) for i in rng.choice(count, size=int(rng.integers(1, min(MAX_MOVING, count) + 1)), replace=False)
        }
    velocity = np.zeros((count, 2))
    spin = np.zeros(count)
    for i in sorted(movers):
        angle = rng.uniform(0.0, 2.0 * np.pi)
        velocity[i] = rng.uniform(0.08, 0.25) * np.array([np.cos(angle), np.sin(angle)])
        spin[i] = rng.uniform(-SPIN, SPIN)
    half_travel = np.linalg.norm(velocity, axis=1) * (0.5 * max(b.frames - 1, 0) + 0.5)  # sequence and shutter
    radii = np.array([m.extra["radius"] for m in meshes]) + half_travel
    area = float(np.sqrt(np.sum(np.square(radii)) * 2.5))
    centres = _place(rng, radii, area)

    middle = 0.5 * (b.frames - 1)
    for i, (mesh, kind) in enumerate(zip(meshes, materials)):
        texture = texture_assets[int(rng.integers(0, len(texture_assets)))]
        material = _material(b, f"M{i:02d}_{kind}", kind, rng, texture)
        heading = float(rng.uniform(0.0, 360.0))
        prim = b.mesh(f"Object{i:02d}_{shape_kinds[i]}", mesh, material, double_sided=shape_kinds[i] == "leaf")
        xform = UsdGeom.Xformable(prim)
        translate, rotate = xform.AddTranslateOp(), xform.AddRotateYOp()
        if i in movers:
            for f in range(b.frames):
                x, z = centres[i] + velocity[i] * (f - middle)
                translate.Set(Gf.Vec3d(round(float(x), 5), 0.0, round(float(z), 5)), float(f))
                rotate.Set(round(heading + spin[i] * (f - middle), 4), float(f))
        else:
            translate.Set(Gf.Vec3d(round(float(centres[i][0]), 5), 0.0, round(float(centres[i][1]), 5)))
            rotate.Set(round(heading, 4))

    # Environment, rotated about the vertical; a sun for the sunny kinds.
    environment = str(rng.choice(variants["environments"]))
    image, intensity, sun = environments.make(environment, rng)
    dome = b.dome_light("Environment", intensity, texture=b.texture(f"env_{environment}", image))
    turn = float(rng.uniform(0.0, 360.0))
    UsdGeom.Xformable(dome).AddRotateYOp().Set(round(turn, 4))
    if sun is not None:
        azimuth, elevation, sun_intensity, colour = sun
        a, e = np.deg2rad(azimuth + turn), np.deg2rad(elevation)
        towards_sun = np.array([np.cos(e) * np.cos(a), np.sin(e), -np.cos(e) * np.sin(a)])
        b.distant_light("Sun", 0.53, sun_intensity, colour, direction=-towards_sun)

    # Camera: random field of view, a partial orbit around the clutter.
    focal = float(rng.uniform(20.0, 60.0))
    half_fov = np.arctan(18.0 / focal)  # 36 mm filmback
    distance = area / np.tan(half_fov) * rng.uniform(0.9, 1.3)
    height = distance * rng.uniform(0.3, 0.8)
    target = np.array([0.0, 0.3, 0.0])
    poses = camera_paths.orbit(
        target,
        distance,
        height,
        rng.uniform(0.0, 360.0),
        rng.choice([-1.0, 1.0]) * rng.uniform(5.0, 15.0),
        b.frames,
        b.up,
    )
    fstop, focus = 0.0, 0.0
    if depth_of_field:
        focus_on = int(rng.integers(0, count))
        point = np.array([centres[focus_on][0], 0.5 * meshes[focus_on].extra["height"], centres[focus_on][1]])
        eye = poses[b.frames // 2][:3, 3]
        focus = float(np.linalg.norm(point - eye))
        fstop = float(rng.uniform(1.2, max(1.3, min(2.8, focal / 12.0))))
    shutter = (-0.25, 0.25) if motion_blur else (0.0, 0.0)
    b.camera(poses, focal_length_mm=focal, clipping=(0.05, 500.0), fstop=fstop, focus_distance=focus, shutter=shutter)

    record = {
        "pool": pool,
        "shapes": sorted(set(shape_kinds)),
        "textures": sorted(set(texture_kinds)),
        "environment": environment,
        "objects": count,
        "moving": len(movers),
    }
    b.stage.GetPrimAtPath("/World").SetCustomDataByKey(VARIANTS_KEY, record)
