"""UsdGeom.PointInstancer → Mitsuba instancing (``shapegroup`` + ``instance``), as plain data.

What an instancer means here (USD's PointInstancer schema):

* ``prototypes`` (targets; children of the instancer by convention, never rendered where they are
  authored), ``protoIndices`` (which prototype each instance is), ``positions``, ``orientations``
  (quaternions), ``scales``, and the prototype root's own transform: USD's
  ``ComputeInstanceTransformsAtTime`` composes them. ``invisibleIds`` and inactive ids
  (``ComputeMaskAtTime``) drop instances. Each prototype's gprims are read relative to its root
  (nested PointInstancers and lights inside prototypes are skipped with a warning).
* **Static instancers** become one *instance group* per used prototype: its records in prototype
  space and K×4×4 poses, an :class:`~denoisebench.generator.contract.scene_parts.InstanceGroup` of the
  translated scene's ``instance_groups``;
  the renderer loads each group's shapes once (a Mitsuba ``shapegroup``) and places ``K``
  ``instance`` objects, so that 10 000 instances cost their geometry's memory once.
  Emissive prototype shapes cannot live in a Mitsuba shapegroup: they are written out per instance.
  A prototype sphere that some instance scales non-uniformly is tessellated (once, in the group).
  Above ``render.scene.INSTANCE_LIMIT`` instances per scene the renderer merges each group into one
  mesh per prototype part instead (Mitsuba 3.9's JIT variants trace every instance as its own nested
  virtual call: 1 000 instances took 95 s to render here, against 1.6 s written out); the contract
  still holds the geometry once.
* **Animated instancers** (time-sampled positions, orientations, scales or indices, non-zero
  ``velocities`` or ``angularVelocities`` (USD extrapolates positions along them), an animated
  instancer transform, or moving prototype geometry) are written out as plain shapes, one per
  instance and prototype part, each with its per-frame vertices (``frame_positions``: object motion
  between frames and motion vectors) and, when the shutter is open and the prototype is rigid, its
  sub-frame poses (``shutter_motion``: motion blur within the shutter), exactly as a moving gprim.
  A changing instance count keeps the first frame's instances (warning).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from denoisebench.generator.contract.scene_parts import MeshShape, ShapeRecord, ShutterMotion, SphereShape
from denoisebench.generator.contract.translated_scene import shutter_keys
from denoisebench.generator.usd import geometry
from denoisebench.generator.usd.stage import check_finite

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).


def _transforms(instancer, time: float):
    """(K×4×4 column-vector instance transforms in the instancer's space, proto index per instance, mask)."""
    from pxr import Usd, UsdGeom

    matrices = instancer.ComputeInstanceTransformsAtTime(
        Usd.TimeCode(time),
        Usd.TimeCode(time),
        UsdGeom.PointInstancer.IncludeProtoXform,
        UsdGeom.PointInstancer.IgnoreMask,
    )
    indices = np.asarray(instancer.GetProtoIndicesAttr().Get(time) or [], dtype=np.int64)
    if matrices is None or len(matrices) == 0:
        return np.zeros((0, 4, 4)), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    array = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4).transpose(0, 2, 1)
    check_finite(array, str(instancer.GetPath()), "instance transforms")
    mask = instancer.ComputeMaskAtTime(time)
    mask = np.ones(len(array), dtype=bool) if not mask else np.asarray(list(mask), dtype=bool)
    return array, indices[: len(array)], mask


def is_animated(instancer) -> bool:
    """Some attribute that places instances is time-sampled, or the instancer's transform is."""
    attributes = (
        instancer.GetPositionsAttr(),
        instancer.GetOrientationsAttr(),
        instancer.GetOrientationsfAttr() if hasattr(instancer, "GetOrientationsfAttr") else None,
        instancer.GetScalesAttr(),
        instancer.GetProtoIndicesAttr(),
        instancer.GetInvisibleIdsAttr(),
    )
    if any(a is not None and a and a.GetNumTimeSamples() > 1 for a in attributes):
        return True
    for attribute in (instancer.GetVelocitiesAttr(), instancer.GetAngularVelocitiesAttr()):
        # USD moves instances along their velocities between position samples (and past the last one).
        values = attribute.Get(attribute.GetTimeSamples()[0]) if attribute.GetNumTimeSamples() else attribute.Get()
        if values is not None and len(values) and np.any(np.asarray(values, dtype=np.float64) != 0):
            return True
    return geometry.is_transform_animated(instancer.GetPrim())


def _prototype_gprims(root, warnings: list[str]):
    """The visible gprims under a prototype root (instance proxies included)."""
    from pxr import Usd, UsdGeom, UsdLux

    iterator = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
    for prim in iterator:
        imageable = UsdGeom.Imageable(prim)
        if imageable and (
            imageable.ComputeVisibility(0) == UsdGeom.Tokens.invisible
            or imageable.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy)
        ):
            iterator.PruneChildren()
            continue
        if prim.IsA(UsdGeom.PointInstancer):
            warnings.append(f"{prim.GetPath()}: nested PointInstancer inside a prototype is not supported; skipped")
            iterator.PruneChildren()
            continue
        if prim.HasAPI(UsdLux.LightAPI):
            warnings.append(f"{prim.GetPath()}: light inside a PointInstancer prototype is not supported; skipped")
            continue
        if prim.IsA(UsdGeom.Gprim):
            yield prim


def _prototype_parts(root, time: float, analytic: bool, gprim_parts, warnings: list[str]):
    """[(record in the prototype root's space, MaterialInfo)] of a prototype, and whether any part moves."""
    from pxr import UsdGeom

    root_inverse = np.linalg.inv(geometry.local_to_world(root, time))
    parts, moving = [], False
    for prim in _prototype_gprims(root, warnings):
        if not (prim.IsA(UsdGeom.Mesh) or str(prim.GetTypeName()) in geometry.SUPPORTED_PRIMITIVES):
            warnings.append(f"{prim.GetPath()}: prim type {prim.GetTypeName()} is not supported; skipped")
            continue
        moving = moving or geometry.are_points_animated(prim) or _moves_within(prim, root)
        parts.extend(gprim_parts(prim, root_inverse, time, analytic))
    return parts, moving


def _moves_within(prim, root) -> bool:
    from pxr import UsdGeom

    current = prim
    while current and current != root:
        if current.IsA(UsdGeom.Xformable) and UsdGeom.Xformable(current).TransformMightBeTimeVarying():
            return True
        current = current.GetParent()
    return False


def read_instancer(prim, to_mitsuba, frames, camera, warnings: list[str], gprim_parts):
    """A PointInstancer → (plain (record, material) parts to add as shapes, instance groups).

    ``gprim_parts(prim, to_space, time, analytic)``: the translator's reader of one gprim (records
    baked with ``to_space @ local_to_world(prim)``). Groups: ``(name, [(record, material)], K×4×4
    float64 poses)``; the translator binds the parts' materials and makes each group an
    :class:`~denoisebench.generator.contract.scene_parts.InstanceGroup`."""
    from pxr import UsdGeom

    instancer = UsdGeom.PointInstancer(prim)
    path = str(prim.GetPath())
    prototypes = instancer.GetPrototypesRel().GetForwardedTargets()
    if not prototypes:
        warnings.append(f"{path}: PointInstancer without prototypes; skipped")
        return [], []
    stage = prim.GetStage()
    roots = [stage.GetPrimAtPath(p) for p in prototypes]
    matrices, indices, mask = _transforms(instancer, frames[0])
    if len(matrices) == 0:
        warnings.append(f"{path}: PointInstancer without instances; skipped")
        return [], []
    if len(indices) < len(matrices) or (len(indices) and (indices.min() < 0 or indices.max() >= len(roots))):
        warnings.append(f"{path}: protoIndices do not match prototypes/positions; skipped")
        return [], []
    base = to_mitsuba @ geometry.local_to_world(prim, frames[0])
    animated = (len(frames) > 1 or camera.has_open_shutter) and is_animated(instancer)
    plain: list = []
    groups: list[tuple] = []
    for proto_index, root in enumerate(roots):
        chosen = np.flatnonzero((indices == proto_index) & mask)
        if not len(chosen):
            continue
        if not root:
            warnings.append(f"{path}: prototype {prototypes[proto_index]} does not exist; its instances skipped")
            continue
        parts, proto_moving = _prototype_parts(root, frames[0], not animated, gprim_parts, warnings)
        if not parts:
            continue
        if animated or (proto_moving and len(frames) > 1):
            plain.extend(
                _written_out(instancer, root, proto_index, chosen, to_mitsuba, frames, camera, gprim_parts, warnings)
            )
            continue
        poses = base[None] @ matrices[chosen]
        scales = np.linalg.norm(poses[:, :3, :3], axis=1)
        if any(isinstance(r, SphereShape) for r, _ in parts) and not np.allclose(scales, scales[:, :1], rtol=1e-6):
            # A non-uniformly scaled analytic sphere is an ellipsoid: tessellate it once, in the group.
            parts, _ = _prototype_parts(root, frames[0], False, gprim_parts, warnings)
        kept = [(r, m) for r, m in parts if m.emission is None]
        for record, material in parts:
            if material.emission is not None:  # emitters cannot be instanced in Mitsuba: one shape per instance
                plain.extend((_placed(record, pose, f"{path}/{k}"), material) for k, pose in zip(chosen, poses))
        if kept:
            groups.append((f"{path}:{root.GetPath()}", kept, poses))
    return plain, groups


def _placed(record: ShapeRecord, pose: np.ndarray, prefix: str) -> MeshShape | SphereShape:
    """A copy of a prototype-space record moved to ``pose`` (spheres: tessellated when not uniform)."""
    if isinstance(record, SphereShape):
        scale = np.linalg.norm(pose[:3, :3], axis=0)
        if np.allclose(scale, scale[0], rtol=1e-6):
            center = pose[:3, :3] @ np.asarray(record.center) + pose[:3, 3]
            return replace(
                record, name=f"{prefix}{record.name}", center=tuple(center.tolist()), radius=record.radius * scale[0]
            )
        positions, faces, normals, _ = geometry.tessellate_sphere(record.radius)
        record = geometry.mesh_entry(record.name, positions + np.asarray(record.center), faces, normals)
    return replace(
        record,
        name=f"{prefix}{record.name}",
        positions=geometry._transform_points(pose, record.positions.astype(np.float64)).astype(np.float32),
        normals=None
        if record.normals is None
        else geometry._transform_normals(pose, record.normals.astype(np.float64)).astype(np.float32),
        faces=np.ascontiguousarray(record.faces[:, [0, 2, 1]]) if np.linalg.det(pose[:3, :3]) < 0 else record.faces,
    )


def _written_out(instancer, root, proto_index, chosen, to_mitsuba, frames, camera, gprim_parts, warnings):
    """An animated instancer's instances of one prototype as plain moving shapes (see the module docstring)."""
    path = str(instancer.GetPath())
    prim = instancer.GetPrim()
    per_frame = []
    for time in frames:
        matrices, indices, _ = _transforms(instancer, time)
        if len(matrices) <= chosen.max() or not np.array_equal(indices[chosen], np.full(len(chosen), proto_index)):
            warnings.append(f"{path}: instances change over time; rendered at their first-frame poses")
            per_frame = per_frame[:1] * len(frames)
            break
        per_frame.append(to_mitsuba @ geometry.local_to_world(prim, time) @ matrices[chosen])
    parts_per_frame = [_prototype_parts(root, t, False, gprim_parts, warnings)[0] for t in frames]
    if any(len(p) != len(parts_per_frame[0]) for p in parts_per_frame):
        warnings.append(f"{root.GetPath()}: prototype topology changes over time; first frame used")
        parts_per_frame = parts_per_frame[:1] * len(frames)
    rigid = all(
        all(np.array_equal(a[0].positions, b[0].positions) for a, b in zip(parts_per_frame[0], frame_parts))
        for frame_parts in parts_per_frame
    )
    keys = shutter_keys(len(frames), camera.shutter_open, camera.shutter_close) if camera.has_open_shutter else None
    key_poses = None
    if keys is not None and rigid:
        stacked = []
        for t in keys:
            matrices, _, _ = _transforms(instancer, frames[0] + float(t))
            if len(matrices) <= chosen.max():
                stacked = None
                break
            stacked.append(to_mitsuba @ geometry.local_to_world(prim, frames[0] + float(t)) @ matrices[chosen])
        key_poses = None if stacked is None else np.stack(stacked, axis=1)  # instances × keys × 4 × 4
    out = []
    for slot, instance in enumerate(chosen):
        for part_index, (record, material) in enumerate(parts_per_frame[0]):
            frames_records = [
                _placed(parts_per_frame[f][part_index][0], per_frame[f][slot], f"{path}/{instance}")
                for f in range(len(frames))
            ]
            placed = frames_records[0]
            motion = None
            if key_poses is not None and material.emission is None:
                first = per_frame[0][slot]
                if abs(np.linalg.det(first[:3, :3])) > 1e-12:
                    motion = ShutterMotion(times=keys, to_world=key_poses[slot], from_record=np.linalg.inv(first))
            placed = replace(
                placed,
                frame_positions=np.stack([r.positions for r in frames_records]),
                frame_normals=None if placed.normals is None else np.stack([r.normals for r in frames_records]),
                shutter_motion=motion,
            )
            out.append((placed, material))
    return out
