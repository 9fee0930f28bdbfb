"""Effects read off a translated stage (compared with those its metadata declares).

Thresholds: ``specular`` for metals or dielectrics with roughness < 0.05 (a near-delta lobe);
``glossy`` for roughness in [0.05, 0.4) on metals or dielectrics; ``transmission`` for
opacity < 1; ``textures`` for any bitmap in use; ``area_lights`` for Rect/Disk/Sphere lights and
emissive geometry; ``environment`` for a Dome light; ``depth_of_field`` for a lens aperture;
``motion_blur`` for an open shutter on an animated camera or with a shape that moves within it
(a mesh with ``shutter_motion``: object motion blur); ``media`` for a gprim that bounds a
participating medium (generator/usd/media.py). ``indirect`` (multi-bounce transport
matters) cannot be read off a stage reliably; it is only ever declared.
"""

from __future__ import annotations

from denoisebench.generator.contract.scene_parts import ConstantEmitter, EnvmapEmitter, MeshShape
from denoisebench.scenes.effects import validate_effects

SPECULAR_ROUGHNESS = 0.05
GLOSSY_ROUGHNESS = 0.4
METALLIC_THRESHOLD = 0.5


def infer_effects(camera, materials, light_kinds, shapes, emitters) -> tuple[str, ...]:
    found = set()
    if camera.has_depth_of_field:
        found.add("depth_of_field")
    shutter_moving = any(isinstance(s, MeshShape) and s.shutter_motion is not None for s in shapes)
    if camera.has_open_shutter and (camera.is_animated or shutter_moving):
        found.add("motion_blur")
    for material in materials:
        non_diffuse = material.metallic > METALLIC_THRESHOLD or material.opacity < 1.0
        if non_diffuse and material.roughness < SPECULAR_ROUGHNESS:
            found.add("specular")
        elif non_diffuse and material.roughness < GLOSSY_ROUGHNESS:
            found.add("glossy")
        if material.opacity < 1.0:
            found.add("transmission")
        if material.textured:
            found.add("textures")
        if material.emission is not None:
            found.add("area_lights")
    if any(shape.light in ("RectLight", "DiskLight", "SphereLight") for shape in shapes):
        found.add("area_lights")
    if any(isinstance(e, (EnvmapEmitter, ConstantEmitter)) for e in emitters) or "DomeLight" in light_kinds:
        found.add("environment")
    if any(shape.medium is not None for shape in shapes):
        found.add("media")
    return validate_effects(found)
