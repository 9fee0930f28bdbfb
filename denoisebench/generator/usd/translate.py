"""USD stage → :class:`TranslatedScene`: the supported subset, with one warning per skipped thing.

Walks the composed stage once (active, visible, non-guide prims), translating gprims, materials,
lights and the camera, and reads the stage's effects (declared in its metadata, inferred from
what is in it). docs/scenes.md, "Supported USD subset", lists what is understood; anything
else gets one warning naming the prim. A stage that does not open, or has no camera, is a
:class:`UserInputError` (the CLI exits 2).

User-facing entry points (``scenes check/preview``, ``generate --usd``) translate with
``strict=True``: a stage with nothing renderable (no supported geometry and no light) or without
any light is then refused with a one-line hint (``--default-light``) instead of rendering black.
USD's own diagnostics (unresolved references, unknown schemas, ...) are caught with a
``UsdUtils.CoalescingDiagnosticDelegate`` while the stage opens and translates, and summarised as
one warning per prim (``<prim>: USD: <first message> (+N more)``) instead of flooding stderr.
The camera is ``camera_path``, else the stage metadata's ``camera`` (what ``generate --camera``
writes into the copied stage), else the first camera; ``auto_camera``/``default_light`` author
:mod:`~denoisebench.generator.usd.additions`' camera and lights into the stage's session layer.
"""

from __future__ import annotations

import os
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.render_plan import STAGE_MAX_DEPTH_KEY, check_max_depth
from denoisebench.generator.contract.scene_parts import (
    AreaEmitter,
    CurvesShape,
    EmitterRecord,
    InstanceGroup,
    MeshShape,
    ShapeRecord,
    ShutterMotion,
    SphereShape,
)
from denoisebench.generator.contract.translated_scene import TranslatedScene, shutter_keys
from denoisebench.generator.usd import curves, geometry, instancers
from denoisebench.generator.usd.additions import add_auto_camera, add_default_lights, stage_has_light
from denoisebench.generator.usd.camera import find_camera, read_camera
from denoisebench.generator.usd.effects import infer_effects
from denoisebench.generator.usd.lights import read_light
from denoisebench.generator.usd.materials import bound_material
from denoisebench.generator.usd.media import attach_media, refuse_volume
from denoisebench.generator.usd.stage import frame_range, open_stage, stage_to_mitsuba_matrix
from denoisebench.scenes.effects import METADATA_KEY, validate_effects

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).

# Prim types that carry no geometry of their own and are silently traversed.
_STRUCTURAL = {
    "",
    "Xform",
    "Scope",
    "Material",
    "Shader",
    "NodeGraph",
    "GeomSubset",
    "Camera",
    "RenderSettings",
    "RenderProduct",
    "RenderVar",
    "SkelRoot",
    "Skeleton",
}


def translate_usd(
    path: str | Path,
    camera_path: str | None = None,
    *,
    auto_camera: bool = False,
    default_light: bool = False,
    frames: int = 8,
    strict: bool = False,
) -> TranslatedScene:
    """Open and translate a USD file (see the module docstring for the keyword options)."""
    from pxr import UsdUtils

    collector = UsdUtils.CoalescingDiagnosticDelegate()
    try:
        stage = open_stage(path)
        if auto_camera or default_light:
            stage.SetEditTarget(stage.GetSessionLayer())
            camera_path = apply_additions(stage, camera_path, auto_camera, default_light, frames)
        translated = translate_stage(stage, camera_path=camera_path, source=str(path), strict=strict)
    finally:
        diagnostics = collector.TakeCoalescedDiagnostics()
        del collector
    translated.warnings[:0] = summarise_diagnostics(diagnostics)
    return translated


def apply_additions(stage, camera_path: str | None, auto_camera: bool, default_light: bool, frames: int) -> str | None:
    """Author ``--auto-camera`` / ``--default-light`` into the stage's current edit target; return the camera path."""

    if auto_camera:
        if camera_path:
            raise UserInputError("give --camera or --auto-camera, not both")
        camera_path = add_auto_camera(stage, frames)
    if default_light and not stage_has_light(stage):
        add_default_lights(stage)
    return camera_path


def summarise_diagnostics(diagnostics) -> list[str]:
    """USD's coalesced diagnostics → one warning per prim (first message, and how many more)."""
    by_prim: dict[str, list[str]] = {}
    for coalesced in diagnostics:
        for item in coalesced.unsharedItems:
            text = " ".join(str(item.commentary).split())
            mtlx = re.search(r"Could not open asset @([^@]+\.mtlx)@", text)
            if mtlx and Path(mtlx.group(1)).is_file():
                continue  # usd-core has no .mtlx format: materialx.py reads the document itself
            match = re.match(r"In <(/[^>]*)>: (.*)", text)
            prim, message = (match.group(1), match.group(2)) if match else ("stage", text)
            message = re.sub(r" \((?:instantiating|composing) stage on stage .*\)$", "", message)
            by_prim.setdefault(prim, []).append(message[:200])
    out = []
    for prim, messages in by_prim.items():
        more = f" (+{len(messages) - 1} more)" if len(messages) > 1 else ""
        out.append(f"{prim}: USD: {messages[0]}{more}")
    return out


def translate_stage(stage, camera_path: str | None = None, source: str = "", strict: bool = False) -> TranslatedScene:
    """Translate an open ``Usd.Stage``."""
    from pxr import Usd, UsdGeom, UsdLux

    warnings: list[str] = []
    metadata = dict(stage.GetRootLayer().customLayerData.get(METADATA_KEY, {}) or {})
    camera_path = camera_path or (str(metadata["camera"]) if metadata.get("camera") else None)
    to_mitsuba = stage_to_mitsuba_matrix(stage)
    frames = frame_range(stage)
    camera_prim = find_camera(stage, camera_path)
    camera = read_camera(stage, camera_prim, frames, to_mitsuba, warnings)

    materials: dict = {}
    bsdfs: dict[str, dict] = {}
    bsdf_ids: dict[int, str] = {}
    shapes: list[ShapeRecord] = []
    emitters: list[EmitterRecord] = []
    used_materials = []
    light_kinds: list[str] = []

    instance_groups: list[InstanceGroup] = []

    def bind(record: ShapeRecord, material, into: list | None = None) -> None:
        key = id(material)
        if key not in bsdf_ids:
            bsdf_ids[key] = f"bsdf_{len(bsdf_ids):03d}"
            bsdfs[bsdf_ids[key]] = material.bsdf
            used_materials.append(material)
        record = replace(record, bsdf=bsdf_ids[key])
        if material.emission is not None:
            record = replace(record, emitter=AreaEmitter(radiance=tuple(material.emission)))
        (shapes if into is None else into).append(record)

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
            if len(frames) > 1 and geometry.is_transform_animated(prim):
                warnings.append(f"{path}: animated light; rendered at its first-frame pose")
            new_shapes, new_emitters = read_light(prim, to_mitsuba @ geometry.local_to_world(prim, frames[0]), warnings)
            shapes.extend(new_shapes)  # no bsdf: a light's own geometry renders black
            emitters.extend(new_emitters)
            continue
        if prim.IsA(UsdGeom.PointInstancer):
            iterator.PruneChildren()  # prototypes render only where the instancer puts them
            plain, groups = instancers.read_instancer(
                prim,
                to_mitsuba,
                frames,
                camera,
                warnings,
                lambda p, space, t, analytic: _gprim_parts(p, space, t, warnings, materials, analytic),
            )
            for record, material in plain:
                bind(record, material)
            for name, group_parts, poses in groups:
                records: list[ShapeRecord] = []
                for record, material in group_parts:
                    bind(record, material, into=records)
                instance_groups.append(InstanceGroup(name=name, shapes=tuple(records), to_world=poses))
            continue
        if prim.IsA(UsdGeom.BasisCurves):
            if len(frames) > 1 and (
                geometry.is_transform_animated(prim)
                or UsdGeom.BasisCurves(prim).GetPointsAttr().GetNumTimeSamples() > 1
            ):
                warnings.append(f"{path}: animated curves are not supported; rendered at their first-frame pose")
            record = curves.read_curves(
                prim, to_mitsuba @ geometry.local_to_world(prim, frames[0]), warnings, frames[0]
            )
            if record is not None:
                bind(record, bound_material(prim, materials, warnings))
            continue
        if prim.IsA(UsdGeom.Gprim):
            if type_name == "Volume":
                refuse_volume(prim)  # its fields hold a medium we cannot read: a one-line error, never dropped light
            if not (prim.IsA(UsdGeom.Mesh) or type_name in geometry.SUPPORTED_PRIMITIVES):
                warnings.append(f"{path}: prim type {type_name} is not supported; skipped")
                continue
            moving = len(frames) > 1 and (geometry.is_transform_animated(prim) or geometry.are_points_animated(prim))
            parts = _gprim_parts(prim, to_mitsuba, frames[0], warnings, materials, analytic=not moving)
            if moving and parts:
                # parts is already the first frame's (analytic=False when moving)
                parts = _attach_frames(
                    prim,
                    parts,
                    [parts] + [_gprim_parts(prim, to_mitsuba, t, [], materials, analytic=False) for t in frames[1:]],
                    warnings,
                )
                if camera.has_open_shutter and not geometry.are_points_animated(prim):
                    parts = _attach_shutter_motion(prim, parts, to_mitsuba, frames, camera, warnings)
            parts = attach_media(prim, parts, to_mitsuba, to_mitsuba @ geometry.local_to_world(prim, frames[0]))
            for record, material in parts:
                bind(record, material)
            continue
        if type_name not in _STRUCTURAL:
            warnings.append(f"{path}: prim type {type_name} is not supported; skipped")

    lit = any(s.emitter is not None for s in shapes) or bool(emitters)
    if strict and not any(s.bsdf for s in shapes) and not instance_groups:
        # Mitsuba cannot trace a scene without shapes (and lights alone show nothing but a sky).
        skipped = sorted({w.split(": prim type ")[1].split(" ")[0] for w in warnings if ": prim type " in w})
        detail = f" (unsupported: {', '.join(skipped)})" if skipped else ""
        raise UserInputError(f"{source or 'stage'}: nothing renderable: no supported geometry{detail}")
    if strict and not lit:
        raise UserInputError(
            f"{source or 'stage'}: no light in the stage; add one, or pass --default-light "
            "(a uniform dome and a key light)"
        )
    if not shapes and not emitters:
        warnings.append("stage has no supported geometry or lights: the image will be black")
    if not lit:
        warnings.append("stage has no light: the image will be black")
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
        camera=camera,
        bsdfs=bsdfs,
        shapes=tuple(shapes),
        emitters=tuple(emitters),
        instance_groups=tuple(instance_groups),
        effects_declared=declared,
        effects_inferred=inferred,
        warnings=warnings,
        source=source,
        family=str(metadata.get("family", "")),
        seed=int(metadata["seed"]) if "seed" in metadata else None,
        max_depth=stage_depth,
        variants=_variants(stage),
        materials=[_relative_report(m.report, source) for m in used_materials if m.report],
    )


def _relative_report(report: dict, source: str) -> dict:
    """A material's translation record with its ``.mtlx`` document relative to the stage's folder."""
    out = dict(report)
    if out.get("document") and source:
        out["document"] = Path(os.path.relpath(out["document"], Path(source).resolve().parent)).as_posix()
    return out


def _variants(stage) -> dict:
    """``/World`` customData ``denoisebench:variants`` as plain data (a cluttered stage's pools)."""
    prim = stage.GetDefaultPrim() or stage.GetPrimAtPath("/World")
    data = prim.GetCustomDataByKey("denoisebench:variants") if prim else None
    if not data:
        return {}
    return {str(k): (v if isinstance(v, (str, int, float)) else [str(x) for x in v]) for k, v in dict(data).items()}


def _gprim_parts(prim, to_mitsuba, time: float, warnings: list[str], materials: dict, analytic: bool):
    """A gprim at ``time`` → [(shape record, MaterialInfo)] (one per material subset of a mesh)."""
    from pxr import UsdGeom

    to_world = to_mitsuba @ geometry.local_to_world(prim, time)
    if prim.IsA(UsdGeom.Mesh):
        # The material decides which primvar holds the texture coordinates (varname).
        uv_name = bound_material(prim, materials, warnings).uv_primvar
        translated = geometry.read_mesh(prim, to_world, warnings, uv_name=uv_name, time=time)
        if translated is None:
            return []
        record, face_ids = translated
        return [
            (part, bound_material(subset if subset is not None else prim, materials, warnings))
            for part, subset in geometry.subset_records(prim, record, face_ids)
        ]
    record = geometry.read_primitive(prim, to_world, warnings, analytic=analytic)
    return [] if record is None else [(record, bound_material(prim, materials, warnings))]


def _attach_frames(prim, parts, per_frame, warnings: list[str]) -> list:
    """``parts`` of a moving gprim, each record given its vertices at every frame (``frame_positions``,
    ``frame_normals``).

    Needs the same triangles at every frame; a changing topology keeps the first frame's pose (warning)."""
    path = str(prim.GetPath())
    if any(len(frame_parts) != len(parts) for frame_parts in per_frame):
        warnings.append(f"{path}: topology changes over time; rendered at its first-frame pose")
        return parts
    for index, (record, _) in enumerate(parts):
        records = [frame_parts[index][0] for frame_parts in per_frame]
        if any(
            not isinstance(r, MeshShape)
            or r.positions.shape != record.positions.shape
            or not np.array_equal(r.faces, record.faces)
            for r in records
        ):
            warnings.append(f"{path}: topology changes over time; rendered at its first-frame pose")
            return parts
    out = []
    for index, (record, material) in enumerate(parts):
        records = [frame_parts[index][0] for frame_parts in per_frame]
        normals = None if record.normals is None else np.stack([r.normals for r in records])
        out.append(
            (replace(record, frame_positions=np.stack([r.positions for r in records]), frame_normals=normals), material)
        )
    return out


def _attach_shutter_motion(prim, parts, to_mitsuba, frames, camera, warnings: list[str]) -> list:
    """``parts`` of a rigidly moving gprim, each given its poses within the shutter (``shutter_motion``).

    Keys every 1/SHUTTER_SUBSTEPS frame over all frames' shutters (time code = first frame + key time);
    emissive parts are refused (no moving emitters: they keep each frame's pose, one warning)."""
    times = shutter_keys(len(frames), camera.shutter_open, camera.shutter_close)
    poses = np.stack([to_mitsuba @ geometry.local_to_world(prim, frames[0] + float(t)) for t in times])
    first = to_mitsuba @ geometry.local_to_world(prim, frames[0])
    if abs(np.linalg.det(first[:3, :3])) < 1e-12 or not np.all(np.isfinite(poses)):
        warnings.append(f"{prim.GetPath()}: degenerate transform; no motion blur within the shutter")
        return parts
    motion = ShutterMotion(times=times, to_world=poses, from_record=np.linalg.inv(first))
    out = []
    for record, material in parts:
        if material.emission is not None or record.emitter is not None:
            warnings.append(
                f"{prim.GetPath()}: emissive geometry moving within the shutter is not supported; "
                "rendered at each frame's pose (no motion blur on it)"
            )
            out.append((record, material))
            continue
        out.append((replace(record, shutter_motion=motion), material))
    return out


def scene_bounds(translated: TranslatedScene) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounds of the translated geometry (for previews and sanity checks)."""
    lows, highs = [], []
    for shape in translated.shapes:
        if isinstance(shape, SphereShape):
            center = np.asarray(shape.center)
            lows.append(center - shape.radius)
            highs.append(center + shape.radius)
        elif isinstance(shape, CurvesShape):
            lows.append((shape.points[:, :3] - shape.points[:, 3:]).min(0))
            highs.append((shape.points[:, :3] + shape.points[:, 3:]).max(0))
        else:
            lows.append(shape.positions.min(0))
            highs.append(shape.positions.max(0))
    for group in translated.instance_groups:
        for shape in group.shapes:
            if isinstance(shape, SphereShape):
                corners = np.asarray(shape.center) + shape.radius * np.array(
                    [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
                )
            else:
                low, high = shape.positions.min(0), shape.positions.max(0)
                corners = np.array(
                    [[a, b, c] for a in (low[0], high[0]) for b in (low[1], high[1]) for c in (low[2], high[2])]
                )
            placed = np.einsum("kij,nj->kni", group.to_world[:, :3, :3], corners) + group.to_world[:, None, :3, 3]
            lows.append(placed.reshape(-1, 3).min(0))
            highs.append(placed.reshape(-1, 3).max(0))
    if not lows:
        return np.zeros(3), np.zeros(3)
    return np.min(lows, 0), np.max(highs, 0)
