"""UsdLux lights → Mitsuba emitters (plain data; Mitsuba world space).

Radiance of every light is ``color · intensity · 2^exposure`` (UsdLux), divided by the light's
area when ``inputs:normalize`` is on. Shapes: RectLight (``width`` × ``height`` in its XY plane,
emitting toward −Z) → an emissive ``rectangle``; DiskLight → an emissive ``disk``; SphereLight →
an emissive ``sphere``; DistantLight → ``directional`` with that product as irradiance;
DomeLight → ``envmap`` from ``inputs:texture:file`` (lat-long, +Y up) or ``constant``.

Point and spot lights (what Blender and most DCCs export):

* A SphereLight with ``treatAsPoint`` (UsdLux's attribute is named exactly that, *without* an
  ``inputs:`` prefix; the prefixed spelling some tools write is read too) or with radius 0 is a
  Mitsuba ``point`` light carrying the power of the sphere: flux L·π·4πr² = 4π·I, so I = π r² L,
  and with ``normalize`` (L divided by the area 4πr²) I = L/4. A radius-0 light has no area, so it
  always takes the normalized form I = L/4 (the power Blender meant when it wrote ``normalize``).
* ``UsdLuxShapingAPI`` on such a light makes it a Mitsuba ``spot`` pointing along the light's −Z:
  ``cutoff_angle`` = ``shaping:cone:angle`` (the half-angle, degrees) and ``beam_width`` =
  angle · (1 − ``shaping:cone:softness``) (Mitsuba's smooth fall-off between the two). A cone of
  90° or more is no cone (a point light); ``shaping:focus`` and IES profiles do not map and get a
  warning, as does shaping on area, distant and dome lights (they keep their unshaped emission).
* DistantLight ``angle`` (the sun's apparent diameter, degrees): Mitsuba's ``directional`` is a delta
  light, so shadows are hard. Up to :data:`SUN_ANGLE_LIMIT` (the real sun is 0.53°) that is what an
  eye sees and no warning is given; a wider angle gets one warning (soft shadows rendered hard).

Zero-area or non-emitting lights are skipped with a warning, as are light types and inputs
outside this subset (light-linking, textures on area lights). ``enableColorTemperature`` multiplies
the color by ``UsdLux.BlackbodyTemperatureAsRgb(colorTemperature)``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from denoisebench.generator.contract.scene_parts import (
    AreaEmitter,
    ConstantEmitter,
    DirectionalEmitter,
    EmitterRecord,
    EnvmapEmitter,
    MeshShape,
    PointEmitter,
    SphereShape,
    SpotEmitter,
)
from denoisebench.generator.usd.geometry import area_of, mesh_entry, tessellate_plane
from denoisebench.generator.usd.stage import check_finite
from denoisebench.generator.usd.textures import read_environment

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).

#: Widest DistantLight ``angle`` (degrees) rendered as a delta light without a warning.
SUN_ANGLE_LIMIT = 1.0
AREA_LIGHT_TYPES = ("RectLight", "DiskLight", "SphereLight")
SUPPORTED_LIGHT_TYPES = AREA_LIGHT_TYPES + ("DistantLight", "DomeLight")
# Mitsuba's rectangle and disk emit along their +Z normal; UsdLux lights emit along -Z.
_FLIP_Z = np.diag([1.0, -1.0, -1.0, 1.0])


def _input(light_api, name, path, default=None, prefix="inputs:"):
    attribute = light_api.GetPrim().GetAttribute(f"{prefix}{name}")
    if not attribute or not attribute.HasAuthoredValue():
        return default
    value = attribute.Get(0)
    if value is None:
        return default
    if not isinstance(value, (str, bool)) and not hasattr(value, "path"):
        check_finite(value, path, f"inputs:{name}")
    return value


def light_radiance(prim, path: str, warnings: list[str]) -> np.ndarray:
    """color · intensity · 2^exposure of a UsdLux light."""
    from pxr import UsdLux

    light = UsdLux.LightAPI(prim)
    color = np.asarray(_input(light, "color", path, (1.0, 1.0, 1.0)), dtype=np.float64)
    intensity = float(_input(light, "intensity", path, 1.0))
    exposure = float(_input(light, "exposure", path, 0.0))
    if _input(light, "enableColorTemperature", path, False):
        # UsdLux's own blackbody table (normalized to luminance 1), as Hydra renderers apply it.
        kelvin = float(_input(light, "colorTemperature", path, 6500.0))
        color = color * np.asarray(UsdLux.BlackbodyTemperatureAsRgb(kelvin), dtype=np.float64)
    return np.clip(color, 0.0, None) * intensity * 2.0**exposure


def read_light(
    prim, to_world: np.ndarray, warnings: list[str]
) -> tuple[list[MeshShape | SphereShape], list[EmitterRecord]]:
    """One UsdLux light → (shape records with an emitter, emitter records)."""
    path = str(prim.GetPath())
    kind = prim.GetTypeName()
    if kind not in SUPPORTED_LIGHT_TYPES:
        warnings.append(f"{path}: light type {kind} is not supported; skipped")
        return [], []
    radiance = light_radiance(prim, path, warnings)
    if not np.any(radiance > 0):
        warnings.append(f"{path}: {kind} emits nothing (intensity or color is zero); skipped")
        return [], []
    from pxr import UsdLux

    light = UsdLux.LightAPI(prim)
    normalize = bool(_input(light, "normalize", path, False))

    def emissive(entry, area):
        if area <= 0 or not math.isfinite(area):
            warnings.append(f"{path}: {kind} has zero area; skipped (it would emit nothing)")
            return [], []
        value = radiance / area if normalize else radiance
        return [replace(entry, emitter=AreaEmitter(radiance=tuple(value.tolist())), light=str(kind))], []

    shaped = prim.HasAPI(UsdLux.ShapingAPI) or prim.GetAttribute("inputs:shaping:cone:angle").HasAuthoredValue()
    if shaped and kind != "SphereLight":
        warnings.append(f"{path}: light shaping (cone, IES) on a {kind} does not map to Mitsuba; ignored")
    if kind == "RectLight":
        width = float(_input(light, "width", path, 1.0))
        height = float(_input(light, "height", path, 1.0))
        if _input(light, "texture:file", path) is not None:
            warnings.append(f"{path}: RectLight texture is not supported; constant radiance used")
        positions, faces, normals, _ = tessellate_plane(width, height, "Z")
        matrix = to_world @ _FLIP_Z
        entry = mesh_entry(path, positions @ matrix[:3, :3].T + matrix[:3, 3], faces)
        return emissive(entry, area_of(entry))
    if kind == "DiskLight":
        radius = float(_input(light, "radius", path, 0.5))
        angles = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        rim = np.stack([radius * np.cos(angles), radius * np.sin(angles), np.zeros_like(angles)], 1)
        positions = np.concatenate([[[0.0, 0.0, 0.0]], rim])
        i = np.arange(64)
        faces = np.stack([np.zeros(64, int), 1 + i, 1 + (i + 1) % 64], 1)
        matrix = to_world @ _FLIP_Z
        entry = mesh_entry(path, positions @ matrix[:3, :3].T + matrix[:3, 3], faces)
        return emissive(entry, area_of(entry))
    if kind == "SphereLight":
        radius = float(_input(light, "radius", path, 0.5))
        scale = float(np.cbrt(abs(np.linalg.det(to_world[:3, :3]))))
        world_radius = radius * scale
        as_point = bool(_input(light, "treatAsPoint", path, False, prefix="")) or bool(
            _input(light, "treatAsPoint", path, False)
        )
        if as_point or world_radius <= 0:
            # A point light carrying the sphere's power: flux L·π·4πr² = 4π·I  →  I = π r² L.
            if normalize or world_radius <= 0:
                intensity = radiance / 4.0
            else:
                intensity = radiance * math.pi * world_radius**2
            return [], [_point_or_spot(prim, light, to_world, intensity, shaped, path, warnings)]
        if shaped:
            warnings.append(f"{path}: light shaping (cone) on an area SphereLight does not map to Mitsuba; ignored")
        entry = SphereShape(name=path, center=tuple(to_world[:3, 3].tolist()), radius=world_radius)
        return emissive(entry, 4 * math.pi * world_radius**2)
    if kind == "DistantLight":
        angle = float(_input(light, "angle", path, 0.53))
        if angle > SUN_ANGLE_LIMIT:
            warnings.append(f"{path}: DistantLight angle {angle:g}° rendered as a delta light (hard shadows)")
        direction = to_world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        direction /= max(np.linalg.norm(direction), 1e-20)
        return [], [
            DirectionalEmitter(prim=path, direction=tuple(direction.tolist()), irradiance=tuple(radiance.tolist()))
        ]
    # DomeLight
    texture = _input(light, "texture:file", path)
    rotation = to_world[:3, :3] / np.maximum(np.linalg.norm(to_world[:3, :3], axis=0), 1e-20)
    if texture is not None:
        image = read_environment(prim, texture, warnings)
        if image is not None:
            tint = radiance / max(float(radiance.max()), 1e-20)
            if not np.allclose(tint, 1.0):
                warnings.append(
                    f"{path}: DomeLight color tint with a texture is not supported; its luminance scale is used"
                )
            return [], [EnvmapEmitter(prim=path, data=image, scale=float(radiance.max()), rotation=rotation)]
    return [], [ConstantEmitter(prim=path, radiance=tuple(radiance.tolist()))]


def _point_or_spot(prim, light, to_world, intensity, shaped, path, warnings) -> PointEmitter | SpotEmitter:
    """A Mitsuba ``point`` or (ShapingAPI cone) ``spot`` emitter record at the light's origin."""
    position = to_world[:3, 3]
    record = PointEmitter(prim=path, position=tuple(position.tolist()), intensity=tuple(intensity.tolist()))
    if not shaped:
        return record
    angle = float(_input(light, "shaping:cone:angle", path, 90.0))
    softness = float(np.clip(_input(light, "shaping:cone:softness", path, 0.0), 0.0, 1.0))
    if float(_input(light, "shaping:focus", path, 0.0)) != 0.0:
        warnings.append(f"{path}: shaping:focus does not map to Mitsuba's spot; ignored")
    if _input(light, "shaping:ies:file", path) is not None:
        warnings.append(f"{path}: IES profile is not supported; ignored")
    if angle >= 90.0:
        return record
    if angle <= 0.0:
        warnings.append(f"{path}: shaping:cone:angle {angle:g}; the light emits nothing; skipped")
        return replace(record, intensity=(0.0, 0.0, 0.0))
    # Mitsuba's spot shines along its local +Z; a UsdLux light along −Z. Orthonormal frame, no scale.
    forward = to_world[:3, :3] @ np.array([0.0, 0.0, -1.0])
    forward /= max(np.linalg.norm(forward), 1e-20)
    helper = np.array([0.0, 1.0, 0.0]) if abs(forward[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    right = np.cross(helper, forward)
    right /= np.linalg.norm(right)
    up = np.cross(forward, right)
    frame = np.eye(4)
    frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3] = right, up, forward, position
    return SpotEmitter(
        prim=path,
        to_world=frame,
        intensity=tuple(intensity.tolist()),
        cutoff_angle=angle,
        beam_width=angle * min(1.0 - softness, 0.999),  # equal angles: 1/0 in Mitsuba
    )
