"""UsdGeom gprims → triangle meshes and analytic shapes (plain numpy data, Mitsuba world space).

* ``Mesh``: polygons fan-triangulated (exact for convex faces), ``leftHanded`` orientation
  honoured, normals (``primvars:normals`` over ``normals``) and ``primvars:st`` with their
  interpolation: vertex/varying keep shared vertices, faceVarying/uniform unroll every triangle
  corner into its own vertex. Without authored normals the mesh is shaded flat. GeomSubsets of the
  ``materialBind`` family split the mesh by material.
* ``Sphere`` stays an analytic sphere when its transform scales uniformly, else it is tessellated;
  ``Cube``, ``Cylinder``, ``Cone`` and ``Plane`` are tessellated.
* Transforms are baked into the vertices. A gprim whose transform (or an ancestor's) or whose
  ``points`` are time-sampled is read at every frame (the translator stores the per-frame vertices,
  see translate.py); such a sphere is always tessellated, so that its vertices can move and carry
  their previous-frame positions for motion vectors. Motion *within* a frame (object motion blur):
  when the camera's shutter is open, a rigidly moving gprim also gets its poses at sub-frame keys
  (``shutter_motion``, written by translate.py); the renderer intersects it at each ray's time.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.scene_parts import MeshShape, ShapeRecord, SphereShape
from denoisebench.generator.usd.stage import check_finite, to_numpy

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).


def _transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _transform_normals(matrix: np.ndarray, normals: np.ndarray) -> np.ndarray:
    inverse_transpose = np.linalg.inv(matrix[:3, :3]).T
    out = normals @ inverse_transpose.T
    length = np.linalg.norm(out, axis=1, keepdims=True)
    return out / np.maximum(length, 1e-20)


def mesh_entry(name, positions, triangles, normals=None, uvs=None) -> MeshShape:
    """A neutral triangle-mesh record: float32 N×3 positions, uint32 M×3 faces, optional attributes."""
    return MeshShape(
        name=name,
        positions=np.ascontiguousarray(positions, dtype=np.float32),
        faces=np.ascontiguousarray(triangles, dtype=np.uint32),
        normals=None if normals is None else np.ascontiguousarray(normals, dtype=np.float32),
        uvs=None if uvs is None else np.ascontiguousarray(uvs, dtype=np.float32),
    )


def triangulate(counts: np.ndarray, indices: np.ndarray, path: str, warnings: list[str]):
    """Fan-triangulate polygons. Returns (triangles as corner indices into ``indices``, face id per triangle).

    Faces with fewer than 3 vertices are skipped with one warning; inconsistent counts are an error.
    """
    counts = np.asarray(counts, dtype=np.int64)
    if np.any(counts < 0) or counts.sum() != len(indices):
        raise UserInputError(
            f"{path}: faceVertexCounts sum to {int(counts.sum())} but there are {len(indices)} faceVertexIndices"
        )
    bad = np.flatnonzero(counts < 3)
    if len(bad):
        warnings.append(f"{path}: {len(bad)} face(s) with fewer than 3 vertices cannot be triangulated; skipped")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    corners, face_ids = [], []
    for count in np.unique(counts[counts >= 3]):
        faces = np.flatnonzero(counts == count)
        base = starts[faces][:, None]
        for k in range(1, count - 1):
            corners.append(np.concatenate([base, base + k, base + k + 1], axis=1))
            face_ids.append(faces)
    if not corners:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    triangles = np.concatenate(corners)
    face_of = np.concatenate(face_ids)
    order = np.lexsort((np.arange(len(face_of)), face_of))  # keep the faces' order: deterministic output
    return triangles[order], face_of[order]


def _primvar(gprim, name: str, path: str):
    """(flattened values, interpolation) of an authored primvar, or (None, None)."""
    from pxr import UsdGeom

    primvar = UsdGeom.PrimvarsAPI(gprim.GetPrim()).GetPrimvar(name)
    if not primvar or not primvar.HasAuthoredValue():
        return None, None
    values = primvar.ComputeFlattened()
    if values is None:
        return None, None
    return check_finite(values, path, f"primvars:{name}"), str(primvar.GetInterpolation())


def _per_corner(values, interpolation, corner_point, corner_face, corner_index, path, name):
    """Expand an attribute to one value per triangle corner according to its interpolation."""
    if interpolation in ("vertex", "varying"):
        source, lookup = values, corner_point
    elif interpolation == "faceVarying":
        source, lookup = values, corner_index
    elif interpolation == "uniform":
        source, lookup = values, corner_face
    elif interpolation == "constant":
        return np.broadcast_to(
            values.reshape(-1)[: values.shape[-1]] if values.ndim > 1 else values,
            (len(corner_point),) + values.shape[1:],
        ).copy()
    else:
        raise UserInputError(f"{path}: {name} has unknown interpolation '{interpolation}'")
    if len(lookup) and lookup.max() >= len(source):
        raise UserInputError(
            f"{path}: {name} has {len(source)} values, too few for its '{interpolation}' interpolation"
        )
    return source[lookup]


def read_mesh(
    prim, to_world: np.ndarray, warnings: list[str], uv_name: str | None = None, time: float = 0.0
) -> tuple[MeshShape, np.ndarray] | None:
    """A UsdGeom.Mesh → (mesh record, source face id per triangle), or None when nothing is left.

    ``uv_name``: the primvar holding texture coordinates (the material's primvar reader
    ``varname``); without one, ``st`` then ``uv``. ``time``: the time code points are read at.
    GeomSubsets are split off by :func:`subset_records`, which needs the face ids."""
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(prim)
    path = str(prim.GetPath())
    points = mesh.GetPointsAttr().Get(time)
    counts = mesh.GetFaceVertexCountsAttr().Get(time)
    indices = mesh.GetFaceVertexIndicesAttr().Get(time)
    if points is None or counts is None or indices is None or len(points) == 0:
        warnings.append(f"{path}: mesh without points or faces; skipped")
        return None
    points = check_finite(points, path, "points").reshape(-1, 3)
    indices = np.asarray(indices, dtype=np.int64)
    if len(indices) and (indices.min() < 0 or indices.max() >= len(points)):
        raise UserInputError(
            f"{path}: faceVertexIndices reference point {int(indices.max())} but the mesh has {len(points)} points"
        )
    corners, face_of = triangulate(counts, indices, path, warnings)
    if len(corners) == 0:
        warnings.append(f"{path}: no triangles after triangulation; skipped")
        return None
    if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
        corners = corners[:, [0, 2, 1]]
    # Subdivision surfaces render as their control cage, as most previewers show them.
    normals, normal_interp = _primvar(mesh, "normals", path)
    if normals is None:
        raw = mesh.GetNormalsAttr().Get(time)
        if raw is not None and len(raw):
            normals = check_finite(raw, path, "normals")
            normal_interp = str(mesh.GetNormalsInterpolation())
    uvs, uv_interp = (None, None)
    if uv_name:
        uvs, uv_interp = _primvar(mesh, uv_name, path)
        if uvs is None:
            warnings.append(
                f"{path}: texture coordinates primvars:{uv_name} (the material's varname) not found; st used"
            )
    if uvs is None:
        uvs, uv_interp = _primvar(mesh, "st", path)
    if uvs is None:
        uvs, uv_interp = _primvar(mesh, "uv", path)

    corner_index = corners.reshape(-1)
    corner_point = indices[corner_index]
    corner_face = np.repeat(face_of, 3)
    shared = all(interp in (None, "vertex", "varying") for interp in (normal_interp, uv_interp))
    if shared:
        positions = points
        triangles = corner_point.reshape(-1, 3)
        vertex_normals = normals.reshape(-1, 3) if normals is not None else None
        vertex_uvs = uvs.reshape(-1, 2) if uvs is not None else None
        if vertex_normals is not None and len(vertex_normals) < len(points):
            raise UserInputError(f"{path}: normals has {len(vertex_normals)} values for {len(points)} points")
        if vertex_uvs is not None and len(vertex_uvs) < len(points):
            raise UserInputError(f"{path}: primvars:st has {len(vertex_uvs)} values for {len(points)} points")
    else:
        positions = points[corner_point]
        triangles = np.arange(len(corner_point)).reshape(-1, 3)
        vertex_normals = (
            None
            if normals is None
            else _per_corner(
                normals.reshape(-1, 3), normal_interp, corner_point, corner_face, corner_index, path, "normals"
            )
        )
        vertex_uvs = (
            None
            if uvs is None
            else _per_corner(
                uvs.reshape(-1, 2), uv_interp, corner_point, corner_face, corner_index, path, "primvars:st"
            )
        )

    world_positions = _transform_points(to_world, positions)
    world_normals = _transform_normals(to_world, vertex_normals) if vertex_normals is not None else None
    mitsuba_uvs = None
    if vertex_uvs is not None:
        mitsuba_uvs = vertex_uvs.copy()
        mitsuba_uvs[:, 1] = 1.0 - mitsuba_uvs[:, 1]  # USD v points up the image; Mitsuba's down
    entry = mesh_entry(path, world_positions, triangles, world_normals, mitsuba_uvs)
    return entry, face_of


def subset_records(prim, entry: MeshShape, triangle_faces: np.ndarray):
    """Split a mesh record by its ``materialBind`` GeomSubsets → list of (record, subset prim or None)."""
    from pxr import UsdShade

    subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
    if not subsets:
        return [(entry, None)]
    assigned = np.zeros(len(triangle_faces), dtype=bool)
    out = []
    for subset in subsets:
        faces = np.asarray(subset.GetIndicesAttr().Get(0) or [], dtype=np.int64)
        mask = np.isin(triangle_faces, faces) & ~assigned
        assigned |= mask
        if mask.any():
            out.append((_select_triangles(entry, mask, f"{entry.name}/{subset.GetPrim().GetName()}"), subset.GetPrim()))
    if (~assigned).any():
        out.append((_select_triangles(entry, ~assigned, entry.name), None))
    return out


def _select_triangles(entry: MeshShape, mask: np.ndarray, name: str) -> MeshShape:
    faces = entry.faces[mask]
    used, remap = np.unique(faces, return_inverse=True)
    return mesh_entry(
        name,
        entry.positions[used],
        remap.reshape(-1, 3),
        entry.normals[used] if entry.normals is not None else None,
        entry.uvs[used] if entry.uvs is not None else None,
    )


# ---- primitives ---------------------------------------------------------------------------------


def _axis_frame(axis: str) -> np.ndarray:
    """Rotation taking a +Z-aligned primitive to the given USD axis token."""
    if axis == "X":
        return np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
    if axis == "Y":
        return np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]], dtype=np.float64)
    return np.eye(3)


def tessellate_cylinder(radius_bottom: float, radius_top: float, height: float, axis: str, segments: int = 48):
    """A capped cylinder or cone along ``axis``, centered on the origin. Returns (positions, faces, normals)."""
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    cos, sin = np.cos(angles), np.sin(angles)
    half = height / 2.0
    bottom = np.stack([radius_bottom * cos, radius_bottom * sin, np.full(segments, -half)], 1)
    top = np.stack([radius_top * cos, radius_top * sin, np.full(segments, half)], 1)
    slope = (radius_bottom - radius_top) / max(height, 1e-12)
    side_normal = np.stack([cos, sin, np.full(segments, slope)], 1)
    side_normal /= np.linalg.norm(side_normal, axis=1, keepdims=True)
    positions = [bottom, top]
    normals = [side_normal, side_normal]
    i = np.arange(segments)
    j = (i + 1) % segments
    faces = [np.stack([i, j, segments + j], 1), np.stack([i, segments + j, segments + i], 1)]
    offset = 2 * segments
    for z, radius, sign in ((-half, radius_bottom, -1.0), (half, radius_top, 1.0)):
        if radius <= 0:
            continue
        rim = np.stack([radius * cos, radius * sin, np.full(segments, z)], 1)
        center = np.array([[0.0, 0.0, z]])
        positions += [rim, center]
        normals += [np.tile([0.0, 0.0, sign], (segments + 1, 1))]
        c = offset + segments
        cap = (
            np.stack([np.full(segments, c), offset + j, offset + i], 1)
            if sign < 0
            else np.stack([np.full(segments, c), offset + i, offset + j], 1)
        )
        faces.append(cap)
        offset += segments + 1
    rotation = _axis_frame(axis)
    positions = np.concatenate(positions) @ rotation.T
    normals = np.concatenate(normals) @ rotation.T
    return positions, np.concatenate(faces), normals


def tessellate_sphere(radius: float, rings: int = 24, segments: int = 48):
    theta = np.linspace(0, np.pi, rings + 1)
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    normals = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    uvs = np.stack([p / (2 * np.pi), t / np.pi], -1).reshape(-1, 2)
    r, s = np.meshgrid(np.arange(rings), np.arange(segments), indexing="ij")
    a = r * (segments + 1) + s
    b = a + segments + 1
    faces = np.concatenate([np.stack([a, b, a + 1], -1).reshape(-1, 3), np.stack([a + 1, b, b + 1], -1).reshape(-1, 3)])
    return normals * radius, faces, normals, uvs


def tessellate_cube(size: float):
    half = size / 2.0
    positions, faces, normals, uvs = [], [], [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            n = np.zeros(3)
            n[axis] = sign
            u_axis, v_axis = [(1, 2), (2, 0), (0, 1)][axis]
            corners = []
            for du, dv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                point = n * half
                point = point.copy()
                point[u_axis] = du * half
                point[v_axis] = dv * half
                corners.append(point)
            base = len(positions) * 4
            corners = np.array(corners)
            # Orient the quad so its winding faces n.
            if np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), n) < 0:
                corners = corners[::-1]
            positions.append(corners)
            normals.append(np.tile(n, (4, 1)))
            uvs.append(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64))
            faces += [[base, base + 1, base + 2], [base, base + 2, base + 3]]
    return np.concatenate(positions), np.array(faces), np.concatenate(normals), np.concatenate(uvs)


def tessellate_plane(width: float, length: float, axis: str):
    w, l = width / 2.0, length / 2.0
    positions = np.array([[-w, -l, 0], [w, -l, 0], [w, l, 0], [-w, l, 0]], dtype=np.float64)
    rotation = _axis_frame(axis)
    positions = positions @ rotation.T
    normals = np.tile(rotation @ np.array([0.0, 0.0, 1.0]), (4, 1))
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64)
    return positions, np.array([[0, 1, 2], [0, 2, 3]]), normals, uvs


def read_primitive(prim, to_world: np.ndarray, warnings: list[str], analytic: bool = True) -> ShapeRecord | None:
    """A UsdGeom Sphere/Cube/Cylinder/Cone/Plane → a mesh or analytic sphere record (or None).

    ``analytic=False`` tessellates a sphere even where an analytic one would do (moving spheres)."""
    from pxr import UsdGeom

    path = str(prim.GetPath())

    def attr(getter, name):
        value = getter().Get(0)
        check_finite(value, path, name)
        return value

    uvs = None
    if prim.IsA(UsdGeom.Sphere):
        radius = float(attr(UsdGeom.Sphere(prim).GetRadiusAttr, "radius"))
        if radius <= 0:
            warnings.append(f"{path}: sphere radius {radius:g}; skipped")
            return None
        scale = np.linalg.norm(to_world[:3, :3], axis=0)
        if analytic and np.allclose(scale, scale[0], rtol=1e-6):
            rotation = to_world[:3, :3] / scale[0]
            if np.linalg.det(rotation) > 0:
                return SphereShape(name=path, center=tuple(to_world[:3, 3].tolist()), radius=radius * float(scale[0]))
        positions, faces, normals, uvs = tessellate_sphere(radius)
    elif prim.IsA(UsdGeom.Cube):
        positions, faces, normals, uvs = tessellate_cube(float(attr(UsdGeom.Cube(prim).GetSizeAttr, "size")))
    elif prim.IsA(UsdGeom.Cylinder):
        cylinder = UsdGeom.Cylinder(prim)
        radius = float(attr(cylinder.GetRadiusAttr, "radius"))
        positions, faces, normals = tessellate_cylinder(
            radius, radius, float(attr(cylinder.GetHeightAttr, "height")), str(cylinder.GetAxisAttr().Get())
        )
    elif prim.IsA(UsdGeom.Cone):
        cone = UsdGeom.Cone(prim)
        positions, faces, normals = tessellate_cylinder(
            float(attr(cone.GetRadiusAttr, "radius")),
            0.0,
            float(attr(cone.GetHeightAttr, "height")),
            str(cone.GetAxisAttr().Get()),
        )
    elif prim.IsA(UsdGeom.Plane):
        plane = UsdGeom.Plane(prim)
        positions, faces, normals, uvs = tessellate_plane(
            float(attr(plane.GetWidthAttr, "width")),
            float(attr(plane.GetLengthAttr, "length")),
            str(plane.GetAxisAttr().Get()),
        )
    else:
        return None
    if uvs is not None:
        uvs = uvs.copy()
        uvs[:, 1] = 1.0 - uvs[:, 1]
    return mesh_entry(path, _transform_points(to_world, positions), faces, _transform_normals(to_world, normals), uvs)


SUPPORTED_PRIMITIVES = ("Sphere", "Cube", "Cylinder", "Cone", "Plane")


def is_transform_animated(prim) -> bool:
    from pxr import UsdGeom

    chain = [prim, *_ancestors(prim)]
    return any(p.IsA(UsdGeom.Xformable) and UsdGeom.Xformable(p).TransformMightBeTimeVarying() for p in chain)


def are_points_animated(prim) -> bool:
    """A mesh whose ``points`` hold more than one time sample (deforming geometry)."""
    from pxr import UsdGeom

    return prim.IsA(UsdGeom.Mesh) and UsdGeom.Mesh(prim).GetPointsAttr().GetNumTimeSamples() > 1


def _ancestors(prim):
    parent = prim.GetParent()
    while parent and not parent.IsPseudoRoot():
        yield parent
        parent = parent.GetParent()


def local_to_world(prim, time: float = 0.0) -> np.ndarray:
    from pxr import UsdGeom

    matrix = to_numpy(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time))
    check_finite(matrix, str(prim.GetPath()), "xformOps")
    return matrix


def area_of(entry: MeshShape | SphereShape) -> float:
    """Surface area of a record (for emitter checks)."""
    if isinstance(entry, SphereShape):
        return 4.0 * math.pi * entry.radius**2
    p = entry.positions.astype(np.float64)
    f = entry.faces
    return float(0.5 * np.linalg.norm(np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]), axis=1).sum())
