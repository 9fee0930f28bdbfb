"""Build Mitsuba objects from a :class:`TranslatedScene`'s typed records.

Triangle meshes are made with ``mi.Mesh`` and filled through ``mi.traverse`` (no temporary PLY
files); BSDFs are loaded once each and shared by every shape that uses them.

Moving objects: a scene whose shapes move (:attr:`TranslatedScene.moving`) is built per frame
(``frame=i``): moving meshes take their frame-``i`` vertices, and *every* mesh gets the vertex
attribute :data:`PREVIOUS_POSITION` (its world positions one frame earlier; equal to the current
ones for static meshes and at frame 0). The feature integrator interpolates it at the first hit
to reproject the point the surface occupied in the previous frame (object motion vectors).
Analytic spheres never move (moving spheres are tessellated), so they need no attribute.

Media: a shape record with a ``medium`` (generator/usd/media.py) gets that medium as its interior, and a
``null`` BSDF when no material is bound to it (an invisible boundary: fog, smoke); one inside another
medium's boundary gets that medium as its exterior (:func:`~denoisebench.generator.render.media.enclosing_media`).

Motion within the shutter: shapes whose records hold ``shutter_motion`` (rigid shapes of a stage with
an open shutter) are, when :func:`build_mitsuba_scene` is asked for the feature renderer (no sensor,
no integrator), left out of the main scene and built in their object space (in layout scenes: each
shape at its own slot, see :func:`~denoisebench.generator.render.motion.plan_layout`);
the result is a :class:`~denoisebench.generator.render.motion.ShutterMotionScene` that the feature
integrator intersects at every ray's own time. With a sensor or an integrator (Mitsuba's own
renders) every shape sits at the frame's pose, as before: Mitsuba cannot move shapes within a frame.

A material, mesh or light that Mitsuba refuses is never a crash: the material becomes grey
diffuse, the mesh or light is skipped, each with one line added to ``translated.warnings``; a
scene left without any shape, or one ``load_dict`` still refuses, is a one-line UserInputError. Sensors come from
:func:`sensor_dict`, built from the camera track at a given frame (Mitsuba's own cameras: used by
previews and by the tests that compare our renderer with Mitsuba's ``path`` integrator).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.scene_parts import (
    AreaEmitter,
    ConstantEmitter,
    CurvesShape,
    DirectionalEmitter,
    EmitterRecord,
    EnvmapEmitter,
    InstanceGroup,
    MeshShape,
    PointEmitter,
    SphereShape,
    SpotEmitter,
)
from denoisebench.generator.contract.translated_scene import TranslatedScene
from denoisebench.generator.render.media import enclosing_media, medium_dict
from denoisebench.generator.render.motion import MovingShapes, ShutterMotionScene, object_space, plan_layout
from denoisebench.mitsuba_runtime import load_mitsuba


def _transform(mi, matrix) -> object:
    return mi.ScalarTransform4f(np.asarray(matrix, dtype=np.float64).tolist())


def _mitsuba_values(mi, value):
    """Plain BSDF data → ``load_dict`` values: texture ``data`` arrays → TensorXf, ``to_uv`` → ScalarTransform3f."""
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            if key == "data" and isinstance(item, np.ndarray):
                if item.ndim != 3 or min(item.shape) < 1:
                    raise ValueError(f"texture of shape {item.shape}")
                out[key] = mi.TensorXf(np.ascontiguousarray(item, dtype=np.float32))
            elif key == "to_uv":
                out[key] = mi.ScalarTransform3f(np.asarray(item, dtype=np.float64).tolist())
            else:
                out[key] = _mitsuba_values(mi, item)
        return out
    return value


def _emitter_object(mi, record: AreaEmitter):
    return mi.load_dict({"type": "area", "radiance": {"type": "rgb", "value": list(record.radiance)}})


#: Mesh attribute with each vertex's world position in the previous frame (moving scenes only).
PREVIOUS_POSITION = "vertex_prev_position"


def _build_mesh(mi, record: MeshShape, bsdf, emitter, frame: int | None = None, medium=None, exterior=None):
    props = mi.Properties()
    if bsdf is not None:
        props["bsdf"] = bsdf
    if medium is not None:
        props["interior"] = medium
    if exterior is not None:
        props["exterior"] = exterior
    if emitter is not None:
        props["emitter"] = emitter
    positions, faces = record.positions, record.faces
    normals = record.normals
    previous = None
    if frame is not None:
        previous = positions
        if record.frame_positions is not None:
            frames = record.frame_positions
            positions, previous = frames[frame], frames[max(frame - 1, 0)]
            if record.frame_normals is not None:
                normals = record.frame_normals[frame]
    mesh = mi.Mesh(
        record.name,
        len(positions),
        len(faces),
        props,
        has_vertex_normals=record.normals is not None,
        has_vertex_texcoords=record.uvs is not None,
    )
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(positions.reshape(-1))
    params["faces"] = mi.UInt32(faces.reshape(-1))
    if normals is not None:
        params["vertex_normals"] = mi.Float(np.asarray(normals, dtype=np.float32).reshape(-1))
    if record.uvs is not None:
        params["vertex_texcoords"] = mi.Float(record.uvs.reshape(-1))
    params.update()
    if previous is not None:
        mesh.add_attribute(PREVIOUS_POSITION, 3, np.asarray(previous, dtype=np.float32).reshape(-1).tolist())
    return mesh


#: Control points of the zero-radius B-spline appended to every ``bsplinecurve`` (:func:`_build_curves`).
BSPLINE_GUARD_POINTS = 4


def _build_curves(mi, record: CurvesShape, bsdf):
    """A curves record (usd/curves.py) → Mitsuba ``bsplinecurve``/``linearcurve``, loaded from the text
    file Mitsuba 3.9 reads (``x y z radius`` per control point, a blank line between curves).

    A ``bsplinecurve`` gets one more curve at the end, a guard: the last curve's last four control
    points with radius 0, i.e. a copy of the last segment's centre line, inside its tube.

    Notes:
        Mitsuba 3.9.1's ``bsplinecurve`` reads its segment-index buffer one element past the end for
        rare rays on the LLVM variant (under ``drjit.JitFlag.Debug``: ``drjit.gather(): out-of-bounds
        read from position N in an array of size N``, N the segment count). The index it then reads
        is garbage, and the kernel segfaults: fur_field_102 of ``--seed 100`` crashed generation at
        a reference round, and Mitsuba's own ``path`` crashes there at ``seed=392``, 64², 8 spp.
        Upstream clamps the segment index since (mitsuba3 pull request 1928); pip has no such
        release. With the guard, position N is the guard segment, whose points lie on the real last
        segment: such a rare hit is shaded from that centre line, and the guard itself cannot be hit
        (radius 0, inside a tube of positive radius). The light is the same; the BVH is not, so
        renders agree with an unguarded one only up to float rounding (paths that diverge after a
        rounding difference, about 1 % of the pixels of a fur_field frame past 1e-3).
        ``linearcurve`` is left as it is (not seen to fail).
    """
    import os
    import tempfile

    blocks, start = [], 0
    for count in record.counts:
        block = record.points[start : start + int(count)]
        start += int(count)
        blocks.append("\n".join(" ".join(f"{v:.9g}" for v in row) for row in block))
    if record.basis != "linear" and start >= BSPLINE_GUARD_POINTS:
        guard = np.array(record.points[start - BSPLINE_GUARD_POINTS : start], dtype=np.float64)
        guard[:, 3] = 0.0
        blocks.append("\n".join(" ".join(f"{v:.9g}" for v in row) for row in guard))
    handle, name = tempfile.mkstemp(prefix="denoisebench-curves-", suffix=".txt")
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write("\n\n".join(blocks) + "\n")
        kind = "linearcurve" if record.basis == "linear" else "bsplinecurve"
        return mi.load_dict({"type": kind, "filename": name, "bsdf": bsdf})
    finally:
        os.unlink(name)


def _emitter_dict(mi, record: EmitterRecord) -> dict:
    """The ``mi.load_dict`` dictionary of an emitter record."""
    if isinstance(record, PointEmitter):
        return {
            "type": "point",
            "position": list(record.position),
            "intensity": {"type": "rgb", "value": list(record.intensity)},
        }
    if isinstance(record, SpotEmitter):
        return {
            "type": "spot",
            "to_world": _transform(mi, record.to_world),
            "cutoff_angle": record.cutoff_angle,
            "beam_width": record.beam_width,
            "intensity": {"type": "rgb", "value": list(record.intensity)},
        }
    if isinstance(record, DirectionalEmitter):
        return {
            "type": "directional",
            "direction": list(record.direction),
            "irradiance": {"type": "rgb", "value": list(record.irradiance)},
        }
    if isinstance(record, EnvmapEmitter):
        rotation = np.eye(4)
        rotation[:3, :3] = np.asarray(record.rotation)
        data = np.asarray(record.data, dtype=np.float32)
        if data.ndim != 3 or data.shape[2] != 3 or data.shape[0] < 1 or data.shape[1] < 1:
            raise ValueError(f"environment image of shape {data.shape}")  # mi.Bitmap segfaults on an empty one
        image = mi.Bitmap(np.ascontiguousarray(data), mi.Bitmap.PixelFormat.RGB)
        return {"type": "envmap", "bitmap": image, "scale": record.scale, "to_world": _transform(mi, rotation)}
    if isinstance(record, ConstantEmitter):
        return {"type": "constant", "radiance": {"type": "rgb", "value": list(record.radiance)}}
    raise ValueError(f"unknown emitter record {type(record).__name__}")


def scene_objects(translated: TranslatedScene, frame: int = 0, shutter_motion: bool = False) -> dict:
    """The ``mi.load_dict`` dictionary of a translated scene with Mitsuba objects (no sensor/integrator).

    ``frame`` places moving shapes (ignored for static scenes). ``shutter_motion``: shapes that move
    within the shutter are returned apart, under ``moving_<index>`` keys, as ``((record in object
    space, BSDF), shutter_motion record, (bounding-sphere centre, radius) in object space)``."""
    mi = load_mitsuba()

    def skipped(line: str) -> None:
        if line not in translated.warnings:
            translated.warnings.append(line)

    bsdfs = {}
    for key, value in translated.bsdfs.items():
        try:
            bsdfs[key] = mi.load_dict(_mitsuba_values(mi, value))
        except Exception as error:  # a material Mitsuba refuses: grey, never a crash
            skipped(f"{key}: Mitsuba refuses the material ({_short(error)}); grey diffuse used")
            bsdfs[key] = mi.load_dict({"type": "diffuse"})
    black = None
    moving = translated.moving
    out: dict = {"type": "scene"}
    # Participating media, one Mitsuba object each, shared as one boundary's interior and another's exterior
    shapes = translated.shapes
    media = {i: mi.load_dict(medium_dict(mi, r.medium)) for i, r in enumerate(shapes) if r.medium is not None}
    outer = enclosing_media(shapes) if media else {}
    for index, record in enumerate(shapes):
        emitter = _emitter_object(mi, record.emitter) if record.emitter is not None else None
        bsdf = bsdfs.get(record.bsdf) if record.bsdf else None
        if bsdf is None:
            # Lights' own geometry: black, so it only emits (and blocks light, as a real fixture does).
            black = black or mi.load_dict({"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}})
            bsdf = black
        key = f"shape_{index:04d}"
        medium = media.get(index)  # a medium boundary (generator/usd/media.py): its interior, null unless a material
        exterior = media.get(outer.get(index))  # nested in another medium: that one outside it
        moves_in_shutter = shutter_motion and isinstance(record, MeshShape) and record.shutter_motion is not None
        if medium is not None:
            if record.medium.null_boundary:
                bsdf = mi.load_dict({"type": "null"})
            if moves_in_shutter:
                raise UserInputError(f"{record.name}: a medium boundary moving within the shutter is not supported")
        if moves_in_shutter:
            local = object_space(record)
            points = local.positions.astype(np.float64)
            centre = 0.5 * (points.min(0) + points.max(0))
            radius = float(np.sqrt(np.max(np.sum(np.square(points - centre), axis=1))))
            out[f"moving_{index:04d}"] = ((local, bsdf), record.shutter_motion, (centre, radius))
        elif isinstance(record, CurvesShape):
            try:
                out[key] = _build_curves(mi, record, bsdf)
            except Exception as error:
                skipped(f"{record.name}: Mitsuba cannot build these curves ({_short(error)}); skipped")
        elif isinstance(record, SphereShape):
            shape = {"type": "sphere", "center": list(record.center), "radius": record.radius, "bsdf": bsdf}
            if emitter is not None:
                shape["emitter"] = emitter
            if medium is not None:
                shape["interior"] = medium
            if exterior is not None:
                shape["exterior"] = exterior
            out[key] = shape
        else:
            try:
                out[key] = _build_mesh(mi, record, bsdf, emitter, frame if moving else None, medium, exterior)
            except Exception as error:  # a prim that breaks Mitsuba is skipped with its warning
                skipped(f"{record.name}: Mitsuba cannot build this mesh ({_short(error)}); skipped")
    groups = translated.instance_groups
    merge = sum(len(group.to_world) for group in groups) > INSTANCE_LIMIT
    for index, group in enumerate(groups):
        (_add_merged if merge else _add_instances)(mi, out, index, group, bsdfs, skipped)
    for index, record in enumerate(translated.emitters):
        try:
            out[f"emitter_{index:03d}"] = mi.load_dict(_emitter_dict(mi, record))
        except Exception as error:
            skipped(f"{record.prim or 'light'}: Mitsuba cannot build this light ({_short(error)}); skipped")
    return out


#: Instance groups render as Mitsuba ``instance`` objects up to this many instances in a scene; above it,
#: each group's instances are merged into one mesh per prototype part. Mitsuba 3.9's JIT variants trace
#: every instance as its own nested virtual call (a trace that grows quadratically with their number,
#: mitsuba3 issues #1017 and #1945): measured here (2 cores, llvm_ad_rgb, 64×64 at 4 spp) 1 000 instances
#: took 95 s to render against 1.6 s for the same shapes written out. Merging keeps the contract's
#: geometry once (prototype + matrices) and expands it only inside Mitsuba.
INSTANCE_LIMIT = 64


def _add_merged(mi, out: dict, index: int, group: InstanceGroup, bsdfs: dict, skipped) -> None:
    """An instance group as one merged mesh per prototype mesh (and one sphere per instance)."""
    poses = np.asarray(group.to_world, dtype=np.float64)
    linear, offset = poses[:, :3, :3], poses[:, :3, 3]
    for j, record in enumerate(group.shapes):
        bsdf = bsdfs.get(record.bsdf) or mi.load_dict({"type": "diffuse"})
        key = f"instance_{index:03d}_{j:04d}"
        if isinstance(record, SphereShape):
            centre = np.einsum("kij,j->ki", linear, np.asarray(record.center, dtype=np.float64)) + offset
            scale = np.cbrt(np.abs(np.linalg.det(linear)))
            for k in range(len(poses)):
                out[f"{key}_{k:07d}"] = {
                    "type": "sphere",
                    "center": centre[k].tolist(),
                    "radius": float(record.radius * scale[k]),
                    "bsdf": bsdf,
                }
            continue
        if not isinstance(record, MeshShape):
            continue
        points = record.positions.astype(np.float64)
        positions = np.einsum("kij,nj->kni", linear, points) + offset[:, None, :]
        faces = record.faces.astype(np.int64)
        flipped = np.linalg.det(linear) < 0
        faces_all = np.where(flipped[:, None, None], faces[None][:, :, [0, 2, 1]], faces[None])
        faces_all = faces_all + (np.arange(len(poses)) * len(points))[:, None, None]
        normals = None
        if record.normals is not None:
            inverse_t = np.linalg.inv(linear).transpose(0, 2, 1)
            normals = np.einsum("kij,nj->kni", inverse_t, record.normals.astype(np.float64))
            normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-20)
            normals = normals.reshape(-1, 3).astype(np.float32)
        merged = MeshShape(
            name=f"{group.name}/{record.name}",
            positions=positions.reshape(-1, 3).astype(np.float32),
            faces=faces_all.reshape(-1, 3).astype(np.uint32),
            normals=normals,
            uvs=None if record.uvs is None else np.tile(record.uvs, (len(poses), 1)),
        )
        try:
            out[key] = _build_mesh(mi, merged, bsdf, None)
        except Exception as error:
            skipped(f"{record.name}: Mitsuba cannot build this mesh ({_short(error)}); skipped")


def _add_instances(mi, out: dict, index: int, group: InstanceGroup, bsdfs: dict, skipped) -> None:
    """An instance group: its shapes once, as a Mitsuba ``shapegroup``, and one ``instance`` per
    ``to_world`` matrix (static; no emitters inside)."""
    members: dict = {"type": "shapegroup"}
    for j, record in enumerate(group.shapes):
        bsdf = bsdfs.get(record.bsdf) or mi.load_dict({"type": "diffuse"})
        try:
            if isinstance(record, SphereShape):
                members[f"shape_{j:04d}"] = mi.load_dict(
                    {"type": "sphere", "center": list(record.center), "radius": record.radius, "bsdf": bsdf}
                )
            else:
                members[f"shape_{j:04d}"] = _build_mesh(mi, record, bsdf, None)
        except Exception as error:
            skipped(f"{record.name}: Mitsuba cannot build this mesh ({_short(error)}); skipped")
    if len(members) == 1:
        return
    # Mitsuba 3.9's instance takes its shapegroup by reference to a sibling (an object fails: "Couldn't find key").
    out[f"group_{index:03d}"] = members
    for k, matrix in enumerate(group.to_world):
        out[f"instance_{index:03d}_{k:07d}"] = {
            "type": "instance",
            "shapegroup": {"type": "ref", "id": f"group_{index:03d}"},
            "to_world": _transform(mi, matrix),
        }


def _short(error: Exception) -> str:
    return " ".join(str(error).split())[:160]


def sensor_dict(
    camera: CameraTrack, frame: int, width: int, height: int, spp: int, seed: int = 0, aperture_scale: float = 1.0
) -> dict:
    """A Mitsuba perspective/thin-lens sensor matching ``camera`` at ``frame`` (box filter, independent sampler)."""
    mi = load_mitsuba()
    sensor = {
        "type": "thinlens" if camera.has_depth_of_field and aperture_scale > 0 else "perspective",
        "fov": camera.fov_x_deg,
        "fov_axis": "x",
        "near_clip": camera.near_clip,
        "far_clip": camera.far_clip,
        "to_world": _transform(mi, camera.mitsuba_to_world(frame)),
        "film": {
            "type": "hdrfilm",
            "width": width,
            "height": height,
            "rfilter": {"type": "box"},
            "pixel_format": "rgb",
        },
        "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
    }
    if sensor["type"] == "thinlens":
        sensor["aperture_radius"] = camera.aperture_radius * aperture_scale
        sensor["focus_distance"] = camera.focus_distance
    return sensor


def build_mitsuba_scene(
    translated: TranslatedScene,
    sensor: dict | None = None,
    integrator: dict | None = None,
    frame: int = 0,
    shutter_motion: bool | None = None,
):
    """``mi.Scene`` of a translated stage at ``frame`` (matters for moving scenes), optionally with a sensor and an integrator.

    ``shutter_motion`` (default: when neither a sensor nor an integrator is given and some shape moves
    within the shutter) returns a :class:`ShutterMotionScene` for the feature renderer instead."""
    mi = load_mitsuba()
    if shutter_motion is None:
        shutter_motion = sensor is None and integrator is None and translated.shutter_moving
    objects = scene_objects(translated, frame, shutter_motion=bool(shutter_motion))
    moving = [objects.pop(key) for key in sorted(k for k in objects if k.startswith("moving_"))]
    if sensor is not None:
        objects["sensor"] = sensor
    if integrator is not None:
        objects["integrator"] = integrator
    if not moving and not any(key.startswith(("shape_", "instance_")) for key in objects):
        raise UserInputError(f"{translated.source or 'stage'}: nothing renderable: no shape that Mitsuba can build")
    try:
        base = mi.load_dict(objects)
        if not moving:
            return base
        motions, bounds = [m for _, m, _ in moving], [b for _, _, b in moving]
        groups, offsets, _ = plan_layout(bounds, motions)
        layouts = []
        for members in groups:
            layout = {"type": "scene"}
            for j in members:
                local, bsdf = moving[j][0]
                shifted = replace(local, positions=(local.positions + (offsets[j] - bounds[j][0])).astype(np.float32))
                layout[f"moving_{j:04d}"] = _build_mesh(mi, shifted, bsdf, None)
            layouts.append(mi.load_dict(layout))
        return ShutterMotionScene(base, MovingShapes(mi, layouts, groups, motions, bounds, offsets))
    except Exception as error:
        raise UserInputError(
            f"{translated.source or 'stage'}: Mitsuba cannot build the scene ({_short(error)})"
        ) from None
