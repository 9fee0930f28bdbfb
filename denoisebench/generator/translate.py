"""USD stage → :class:`TranslatedScene`: the supported subset, with one warning per skipped thing.

Walks the composed stage once (active, visible, non-guide prims), translating gprims, materials,
lights and the camera, and reads the stage's effects (declared in its metadata, inferred from
what is in it). The README's "Supported USD subset" section lists what is understood; anything
else gets one warning naming the prim. A stage that does not open, or has no camera, is a
:class:`UserInputError` (the CLI exits 2).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator import usd_geometry as geometry
from denoisebench.generator.effects_inference import infer_effects
from denoisebench.generator.render_plan import STAGE_MAX_DEPTH_KEY, check_max_depth
from denoisebench.generator.translated_scene import TranslatedScene
from denoisebench.generator.usd_camera import find_camera, read_camera
from denoisebench.generator.usd_lights import read_light
from denoisebench.generator.usd_materials import bound_material
from denoisebench.generator.usd_stage import frame_range, open_stage, stage_to_mitsuba_matrix
from denoisebench.scenes.effects import METADATA_KEY, validate_effects

# Prim types that carry no geometry of their own and are silently traversed.
_STRUCTURAL = {"", "Xform", "Scope", "Material", "Shader", "NodeGraph", "GeomSubset", "Camera", "RenderSettings",
               "RenderProduct", "RenderVar", "SkelRoot", "Skeleton"}


def translate_usd(path: str | Path, camera_path: str | None = None) -> TranslatedScene:
    """Open and translate a USD file."""
    stage = open_stage(path)
    return translate_stage(stage, camera_path=camera_path, source=str(path))


def translate_stage(stage, camera_path: str | None = None, source: str = "") -> TranslatedScene:
    """Translate an open ``Usd.Stage``."""
    from pxr import Usd, UsdGeom, UsdLux

    warnings: list[str] = []
    to_mitsuba = stage_to_mitsuba_matrix(stage)
    frames = frame_range(stage)
    camera_prim = find_camera(stage, camera_path)
    camera = read_camera(stage, camera_prim, frames, to_mitsuba, warnings)

    materials: dict = {}
    bsdfs: dict[str, dict] = {}
    bsdf_ids: dict[int, str] = {}
    shapes: list[dict] = []
    emitters: list[dict] = []
    used_materials = []
    light_kinds: list[str] = []

    def bind(record: dict, material) -> None:
        key = id(material)
        if key not in bsdf_ids:
            bsdf_ids[key] = f"bsdf_{len(bsdf_ids):03d}"
            bsdfs[bsdf_ids[key]] = material.bsdf
            used_materials.append(material)
        record["bsdf"] = bsdf_ids[key]
        if material.emission is not None:
            record["emitter"] = {"type": "area", "radiance": list(material.emission)}
        shapes.append(record)

    iterator = iter(Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
    for prim in iterator:
        if prim.IsPseudoRoot():
            continue
        imageable = UsdGeom.Imageable(prim)
        if imageable and (
            imageable.ComputeVisibility(0) == UsdGeom.Tokens.invisible
            or imageable.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy)
        ):
            iterator.PruneChildren()
            continue
        type_name = str(prim.GetTypeName())
        path = str(prim.GetPath())
        if prim.HasAPI(UsdLux.LightAPI) or type_name.endswith("Light"):
            light_kinds.append(type_name)
            new_shapes, new_emitters = read_light(prim, to_mitsuba @ geometry.local_to_world(prim), warnings)
            for record in new_shapes:
                record["bsdf"] = None
                shapes.append(record)
            emitters.extend(new_emitters)
            continue
        if prim.IsA(UsdGeom.Gprim):
            if geometry.is_transform_animated(prim):
                warnings.append(f"{path}: animated transform; geometry is rendered at its first-frame pose")
            to_world = to_mitsuba @ geometry.local_to_world(prim)
            if prim.IsA(UsdGeom.Mesh):
                translated = geometry.read_mesh(prim, to_world, warnings)
                if translated is None:
                    continue
                record, face_ids = translated
                for part, subset in geometry.subset_records(prim, record, face_ids):
                    bind(part, bound_material(subset if subset is not None else prim, materials, warnings))
                continue
            if type_name in geometry.SUPPORTED_PRIMITIVES:
                record = geometry.read_primitive(prim, to_world, warnings)
                if record is not None:
                    bind(record, bound_material(prim, materials, warnings))
                continue
            warnings.append(f"{path}: prim type {type_name} is not supported; skipped")
            continue
        if type_name not in _STRUCTURAL:
            warnings.append(f"{path}: prim type {type_name} is not supported; skipped")

    if not shapes and not emitters:
        warnings.append("stage has no supported geometry or lights: the image will be black")
    if not any("emitter" in s for s in shapes) and not emitters:
        warnings.append("stage has no light: the image will be black")

    metadata = dict(stage.GetRootLayer().customLayerData.get(METADATA_KEY, {}) or {})
    try:
        declared = validate_effects(list(metadata.get("effects", [])))
    except ValueError as error:
        raise UserInputError(f"{source or 'stage'}: {error}") from None
    inferred = infer_effects(camera, used_materials, light_kinds, shapes, emitters)
    stage_depth = metadata.get(STAGE_MAX_DEPTH_KEY)
    if stage_depth is not None:
        try:
            stage_depth = check_max_depth(stage_depth, f"customLayerData denoisebench.{STAGE_MAX_DEPTH_KEY}")
        except ValueError as error:
            raise UserInputError(f"{source or 'stage'}: {error}") from None
    return TranslatedScene(
        scene_dict={"bsdfs": bsdfs, "shapes": shapes, "emitters": emitters},
        camera=camera,
        effects_declared=declared,
        effects_inferred=inferred,
        warnings=warnings,
        source=source,
        family=str(metadata.get("family", "")),
        seed=int(metadata["seed"]) if "seed" in metadata else None,
        max_depth=stage_depth,
    )


def scene_bounds(translated: TranslatedScene) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds of the translated geometry (for previews and sanity checks)."""
    lows, highs = [], []
    for shape in translated.scene_dict["shapes"]:
        if shape["kind"] == "sphere":
            center = np.asarray(shape["center"])
            lows.append(center - shape["radius"])
            highs.append(center + shape["radius"])
        else:
            lows.append(shape["positions"].min(0))
            highs.append(shape["positions"].max(0))
    if not lows:
        return np.zeros(3), np.zeros(3)
    return np.min(lows, 0), np.max(highs, 0)
