"""UsdLux lights → Mitsuba emitters (plain data; Mitsuba world space).

Radiance of every light is ``color · intensity · 2^exposure`` (UsdLux), divided by the light's
area when ``inputs:normalize`` is on. Shapes: RectLight (``width`` × ``height`` in its XY plane,
emitting toward −Z) → an emissive ``rectangle``; DiskLight → an emissive ``disk``; SphereLight →
an emissive ``sphere`` (or, with ``treatAsPoint``, a ``point`` light of the same power);
DistantLight → ``directional`` with that product as irradiance (its ``angle`` is ignored: a
delta light); DomeLight → ``envmap`` from ``inputs:texture:file`` (lat-long, +Y up) or
``constant``. Zero-area or non-emitting lights are skipped with a warning, as are light types and
inputs outside this subset (shaping, color temperature, light-linking, textures on area lights).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from denoisebench.generator.usd_geometry import area_of, mesh_entry, tessellate_plane
from denoisebench.generator.usd_stage import check_finite

AREA_LIGHT_TYPES = ("RectLight", "DiskLight", "SphereLight")
SUPPORTED_LIGHT_TYPES = AREA_LIGHT_TYPES + ("DistantLight", "DomeLight")
# Mitsuba's rectangle and disk emit along their +Z normal; UsdLux lights emit along -Z.
_FLIP_Z = np.diag([1.0, -1.0, -1.0, 1.0])


def _input(light_api, name, path, default=None):
    attribute = light_api.GetPrim().GetAttribute(f"inputs:{name}")
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
        warnings.append(f"{path}: color temperature is not supported; ignored")
    if prim.HasAPI(UsdLux.ShapingAPI):
        warnings.append(f"{path}: light shaping (cone, IES) is not supported; ignored")
    return np.clip(color, 0.0, None) * intensity * 2.0**exposure


def read_light(prim, to_world: np.ndarray, warnings: list[str]) -> tuple[list[dict], list[dict]]:
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
        entry["emitter"] = {"type": "area", "radiance": value.tolist()}
        entry["light"] = kind
        return [entry], []

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
        if _input(light, "treatAsPoint", path, False):
            # A point light carrying the sphere's power: flux L·π·4πr² = 4π·I  →  I = π r² L.
            power_radius = world_radius if world_radius > 0 else 1.0
            value = radiance / (4 * math.pi * power_radius**2) if normalize else radiance
            intensity = value * math.pi * power_radius**2
            return [], [{"type": "point", "position": to_world[:3, 3].tolist(), "intensity": intensity.tolist(), "prim": path}]
        entry = {"kind": "sphere", "name": path, "center": to_world[:3, 3].tolist(), "radius": world_radius}
        return emissive(entry, 4 * math.pi * world_radius**2)
    if kind == "DistantLight":
        direction = to_world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        direction /= max(np.linalg.norm(direction), 1e-20)
        return [], [{"type": "directional", "direction": direction.tolist(), "irradiance": radiance.tolist(), "prim": path}]
    # DomeLight
    texture = _input(light, "texture:file", path)
    rotation = to_world[:3, :3] / np.maximum(np.linalg.norm(to_world[:3, :3], axis=0), 1e-20)
    if texture is not None:
        resolved = getattr(texture, "resolvedPath", "") or ""
        if resolved and Path(resolved).is_file():
            tint = radiance / max(float(radiance.max()), 1e-20)
            if not np.allclose(tint, 1.0):
                warnings.append(f"{path}: DomeLight color tint with a texture is not supported; its luminance scale is used")
            return [], [{"type": "envmap", "filename": resolved, "scale": float(radiance.max()), "rotation": rotation.tolist(), "prim": path}]
        warnings.append(f"{path}: DomeLight texture '{getattr(texture, 'path', texture)}' not found; constant radiance used")
    return [], [{"type": "constant", "radiance": radiance.tolist(), "prim": path}]

