"""Object motion blur: rigid shapes that move *during* the shutter, intersected at each ray's own time.

Mitsuba 3.9 has no animated shape transforms, so moving shapes are kept out of the main scene: each
moving shape (one per mesh record with a ``shutter_motion``, see
:class:`~denoisebench.generator.contract.scene_parts.ShutterMotion`) lives in a Mitsuba scene of
its own, in its *object space*, and a ray meets it by being carried into that space with the inverse of
the shape's pose at the ray's time. The nearer of the main scene's hit and every moving shape's hit
wins. Camera rays, bounce rays and shadow rays all go through :meth:`MovingShapes.ray_intersect` and
:meth:`MovingShapes.sample_emitter_direction`, so each sample sees the geometry at its own time: the
estimator stays unbiased for the time-averaged image (tests/generator/render/test_motion.py checks it against
the average of static sub-frame renders by Mitsuba's ``path``).

Conventions and pitfalls:

* Poses: the translator samples a shape's world-from-object matrix ``W(τ)`` at ``SHUTTER_SUBSTEPS`` keys
  per frame (``τ`` in frames, as ray times are) covering every frame's shutter. Between keys the pose
  is interpolated as the camera's is: translation and stretch linearly, rotation by slerp (of the
  polar decomposition ``W = T·R·S``). That is exactly what USD does for translate, scale, orient and
  single-axis rotate ops; for several Euler angles changing at once it is within the key spacing.
  Times outside the keys clamp to the end keys (USD holds values beyond its last sample).
  :func:`pose_matrices` is the same interpolation on the host (sub-frame renders, tests).
* Object space is the shape's USD local space: the record's frame-0 world positions mapped back by
  ``from_record`` (the inverse of the frame-0 pose), once, in float64.
* A surface interaction found in object space is carried back to world space: point, geometric normal
  (cofactor transform, so mirrored poses keep the baked mesh's orientation), shading frame,
  ``dp_du``/``dp_dv``; ``t`` is the world ray's (the direction is carried by the linear map, not
  renormalised), ``wi`` is recomputed from the world ray.
* A cheap bounding-sphere test per shape and ray masks the lanes that cannot hit it (it never rejects
  a true hit: the sphere bounds the shape at every pose, its radius scaled by the largest stretch).
* Motion vectors of a sample whose first hit is a moving shape are defined at the **shutter's
  centre** ``t_c``: the object point at ``t_c - 1`` seen by the camera at ``t_c - 1`` minus the
  point at ``t_c`` seen by the camera at ``t_c``. Hits on static geometry keep the renderer's
  convention (the ray's own time).
* Moving *emitters* are not supported: the translator keeps emissive shapes at each frame's pose (no
  shutter motion) and says so in one warning; light sampling therefore never meets a moving emitter.
* Shadow rays towards infinite emitters (environment, constant, directional) are unbounded here.
  Mitsuba's own test ends them ``2 R`` beyond the shading point (``R`` the main scene's
  bounding-sphere radius, which leaves the moving shapes out), so a moving shape further out than
  that, or static geometry seen from a point on a moving shape outside the sphere, would cast no
  shadow in next-event estimation (tests/generator/render/test_motion_shadows.py).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from denoisebench.generator.contract.scene_parts import MeshShape, ShutterMotion
from denoisebench.generator.contract.translated_scene import SHUTTER_SUBSTEPS as SUBSTEPS

# Lazy imports: Dr.Jit is imported inside the functions, after mitsuba_runtime has picked
# Mitsuba's variant.

#: Hit-object index of a sample whose hit is not on a moving shape.
NO_OBJECT = 0xFFFFFFFF


# ------------------------------------------------------------------------------------------- host side
def _quaternion(rotation: np.ndarray) -> np.ndarray:
    """(x, y, z, w) unit quaternion of a proper rotation matrix."""
    m = rotation
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q)


def _rotation(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def decompose(matrices: np.ndarray) -> dict:
    """K×4×4 world-from-object keys → ``translation`` K×3, ``rotation`` K×4 (x, y, z, w; consecutive
    keys in one hemisphere), ``stretch`` K×3×3 (polar decomposition ``A = R S``; a mirroring pose keeps
    its reflection in ``S``), and per key interval the slerp angle ``theta`` (K-1)."""
    matrices = np.asarray(matrices, dtype=np.float64)
    count = len(matrices)
    translation = matrices[:, :3, 3].copy()
    rotation = np.zeros((count, 4))
    stretch = np.zeros((count, 3, 3))
    for k, matrix in enumerate(matrices):
        u, _, vt = np.linalg.svd(matrix[:3, :3])
        r = u @ vt
        if np.linalg.det(r) < 0:
            r = u @ np.diag([1.0, 1.0, -1.0]) @ vt
        rotation[k] = _quaternion(r)
        if k and np.dot(rotation[k], rotation[k - 1]) < 0:
            rotation[k] = -rotation[k]
        stretch[k] = r.T @ matrix[:3, :3]
    cos = np.clip(np.sum(rotation[:-1] * rotation[1:], axis=1), -1.0, 1.0)
    return {"translation": translation, "rotation": rotation, "stretch": stretch, "theta": np.arccos(cos)}


def _slerp_weights(theta, w):
    """Weights of the two end quaternions (lerp where the angle is tiny), as the kernel computes them."""
    sin = np.sin(theta)
    small = sin < 1e-5
    safe = np.where(small, 1.0, sin)
    wa = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / safe)
    wb = np.where(small, w, np.sin(w * theta) / safe)
    return wa, wb


def _key_and_weight(times: np.ndarray, tau):
    lo, count = float(times[0]), len(times)
    u = np.clip((np.asarray(tau, dtype=np.float64) - lo) * SUBSTEPS, 0.0, count - 1.0)
    k = np.minimum(np.floor(u), count - 2).astype(np.int64)
    return k, u - k


def pose_matrices(motion: ShutterMotion, tau) -> np.ndarray:
    """World-from-object 4×4 pose(s) of a shape's shutter motion at time(s) ``tau`` (frames).

    The host twin of the kernel's interpolation (:class:`MovingShapes`), for sub-frame renders and tests."""
    parts = decompose(motion.to_world)
    taus = np.atleast_1d(np.asarray(tau, dtype=np.float64))
    k, w = _key_and_weight(np.asarray(motion.times), taus)
    wa, wb = _slerp_weights(parts["theta"][k], w)
    out = np.zeros((len(taus), 4, 4))
    for i in range(len(taus)):
        q = parts["rotation"][k[i]] * wa[i] + parts["rotation"][k[i] + 1] * wb[i]
        q /= np.linalg.norm(q)
        s = parts["stretch"][k[i]] * (1 - w[i]) + parts["stretch"][k[i] + 1] * w[i]
        out[i, :3, :3] = _rotation(q) @ s
        out[i, :3, 3] = parts["translation"][k[i]] * (1 - w[i]) + parts["translation"][k[i] + 1] * w[i]
        out[i, 3, 3] = 1.0
    return out if np.ndim(tau) else out[0]


def _apply(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _apply_normals(matrix: np.ndarray, normals: np.ndarray) -> np.ndarray:
    out = normals @ np.linalg.inv(matrix[:3, :3])
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-20)


def _moved(record: MeshShape, matrix: np.ndarray) -> MeshShape:
    """``record`` with its positions and normals carried by ``matrix``, its motion dropped (a static mesh)."""
    return replace(
        record,
        positions=_apply(matrix, record.positions.astype(np.float64)).astype(np.float32),
        normals=None
        if record.normals is None
        else _apply_normals(matrix, record.normals.astype(np.float64)).astype(np.float32),
        frame_positions=None,
        frame_normals=None,
        shutter_motion=None,
    )


def object_space(record: MeshShape) -> MeshShape:
    """A shutter-moving mesh in object space (float32 positions and normals), without its motion."""
    return _moved(record, np.asarray(record.shutter_motion.from_record, dtype=np.float64))


def translated_at(translated, tau: float):
    """A copy of ``translated`` with every shutter-moving shape frozen at time ``tau`` (frames).

    Its Mitsuba scene (``build_mitsuba_scene``) is the static sub-frame whose average over the
    shutter the blurred frame converges to; moving shapes lose ``frame_positions`` too."""
    shapes = []
    for record in translated.shapes:
        if isinstance(record, MeshShape) and record.shutter_motion is not None:
            record = _moved(object_space(record), pose_matrices(record.shutter_motion, float(tau)))
        shapes.append(record)
    return replace(translated, shapes=tuple(shapes), warnings=list(translated.warnings))


# ----------------------------------------------------------------------------------------- device side
#: Moving shapes per layout scene (one candidate bit mask of 32 bits each).
GROUP = 32


def plan_layout(bounds: list[tuple], motions: list[ShutterMotion]) -> tuple[list[list[int]], np.ndarray, np.ndarray]:
    """Slots of the moving shapes in their layout scenes: ``(groups, offsets, reach)``.

    Each shape's object-space mesh is moved so that its bounding sphere's centre sits at ``offsets[j]``
    (a cubic grid per group, centred on the origin, cells far enough apart that no ray segment clipped
    to one shape's sphere can reach another's). ``reach[j]`` bounds how far such a segment strays from
    the centre in object space: the radius times (largest / smallest stretch over the keys)."""
    reach = np.zeros(len(bounds))
    for j, ((_, radius), motion) in enumerate(zip(bounds, motions)):
        values = [np.linalg.svd(m[:3, :3], compute_uv=False) for m in np.asarray(motion.to_world)]
        ratio = max(v.max() for v in values) / max(min(v.min() for v in values), 1e-12)
        reach[j] = radius * ratio * (1.0 + 1e-3) + 1e-4
    groups = [list(range(g, min(g + GROUP, len(bounds)))) for g in range(0, len(bounds), GROUP)]
    offsets = np.zeros((len(bounds), 3))
    for members in groups:
        side = int(np.ceil(len(members) ** (1.0 / 3.0) - 1e-9))
        cell = 2.0 * reach[members].max() * 1.01
        for slot, j in enumerate(members):
            cube = np.array([slot % side, (slot // side) % side, slot // (side * side)], dtype=np.float64)
            offsets[j] = (cube - 0.5 * (side - 1)) * cell
    return groups, offsets, reach


class MovingShapes:
    """Shapes that move within the shutter: object-space meshes in layout scenes, with pose tables.

    Built by :func:`~denoisebench.generator.render.scene.build_mitsuba_scene`; the feature integrator
    calls :meth:`at`, :meth:`ray_intersect`, :meth:`sample_emitter_direction` and :meth:`centre_motion`.

    Notes:
        One Mitsuba scene per shape would cost one Embree call per shape and query, masked or not
        (8 shapes made frames 2.5x slower). Instead a query first tests the ray against every shape's
        bounding sphere (arithmetic on per-sample poses), then loops over the candidates only, each
        iteration one Embree call on the group's *layout* scene (every shape of the group at its own
        slot, :func:`plan_layout`) with the ray carried into that shape's slot and clipped to its
        sphere, so that it cannot meet a neighbour. Most rays meet no candidate and make no call.

        Frozen passes (``dr.freeze``, render/frame.py): :data:`DRJIT_STRUCT` names every Dr.Jit value
        the kernels read (layout scenes, pose tables, bounds, the first key's time), so that they
        are inputs of a recording, never constants baked into it (Dr.Jit refuses to record a read of
        an evaluated array that is not an input). The Python numbers (key count, shape count, bounding
        radii and centres, whether poses are rigid) shape the code and are literals of the kernels:
        recordings are kept for one scene object only.
    """

    #: What a frozen pass traverses as its inputs (Dr.Jit PyTree fields; the types are not used).
    DRJIT_STRUCT = {
        "layouts": object,
        "q": object,
        "t": object,
        "slerp": object,
        "s": object,
        "centre_table": object,
        "radius_table": object,
        "shift_table": object,
        "time0_opaque": object,
    }

    def __init__(self, mi, layouts: list, groups: list, motions: list[ShutterMotion], bounds: list[tuple], offsets):
        import drjit as dr

        self.mi, self.dr = mi, dr
        self.layouts, self.groups = layouts, groups
        times = np.asarray(motions[0].times, dtype=np.float64)
        for motion in motions:
            if len(motion.times) != len(times) or not np.allclose(motion.times, times):
                raise ValueError("moving shapes must share one key schedule (shutter_keys)")
        self.count = len(times)
        self.shapes_count = len(motions)
        self.time0 = float(times[0])
        parts = [decompose(m.to_world) for m in motions]
        self.rigid = all(np.allclose(p["stretch"], np.eye(3), atol=1e-6) for p in parts)

        def table(kind, rows):
            # Columns copied into Dr.Jit's own memory (lists, never mapped NumPy buffers: a frozen
            # pass's input layout includes each buffer's alignment) and evaluated: frozen-pass inputs.
            rows = np.concatenate(rows).astype(np.float32)
            out = kind(*[mi.Float(rows[:, c].tolist()) for c in range(rows.shape[1])])
            dr.make_opaque(out)
            return out

        self.q = table(mi.Vector4f, [p["rotation"] for p in parts])
        self.t = table(mi.Vector3f, [p["translation"] for p in parts])
        # Per interval: slerp angle and 1/sin (0 where the angle is tiny: lerp); padded to K rows.
        slerp = []
        for p in parts:
            theta = np.append(p["theta"], 0.0)
            sin = np.sin(theta)
            slerp.append(np.stack([theta, np.where(sin < 1e-5, 0.0, 1.0 / np.where(sin < 1e-5, 1.0, sin))], 1))
        self.slerp = table(mi.Vector2f, slerp)
        self.s = []
        if not self.rigid:
            self.s = [table(mi.Vector3f, [p["stretch"][:, :, c] for p in parts]) for c in range(3)]
        centres, radii = [], []
        for part, (centre, radius) in zip(parts, bounds):
            largest = max(np.linalg.svd(s, compute_uv=False).max() for s in part["stretch"])
            centres.append(np.asarray(centre, dtype=np.float64))
            radii.append(radius * largest * (1.0 + 1e-4) + 1e-5)
        self.centres = [tuple(float(v) for v in c) for c in centres]  # literals of the kernel
        self.radii = [float(r) for r in radii]
        self.centre_table = table(mi.Vector3f, [c[None] for c in centres])
        self.radius_table = mi.Float([float(np.float32(r)) for r in radii])
        dr.make_opaque(self.radius_table)
        self.time0_opaque = dr.opaque(mi.Float, self.time0)
        # Object space → layout space: + (offset - centre).
        self.shift_table = table(mi.Vector3f, [(np.asarray(offsets[j]) - centres[j])[None] for j in range(len(parts))])

    # ------------------------------------------------------------------ poses
    def _key(self, time):
        dr, mi = self.dr, self.mi
        u = dr.clip((time - self.time0_opaque) * SUBSTEPS, 0.0, float(self.count - 1))
        k = mi.UInt32(dr.minimum(dr.floor(u), float(self.count - 2)))
        return k, u - mi.Float(k)

    def pose(self, index, key):
        """Per-lane pose ``(columns of R, translation, stretch columns or None)`` of shape ``index`` at ``key``."""
        dr, mi = self.dr, self.mi
        k, w = key
        row = mi.UInt32(index) * self.count + k
        qa = dr.gather(mi.Vector4f, self.q, row)
        qb = dr.gather(mi.Vector4f, self.q, row + 1)
        angle = dr.gather(mi.Vector2f, self.slerp, row)
        small = angle.y == 0.0
        wa = dr.select(small, 1.0 - w, dr.sin((1.0 - w) * angle.x) * angle.y)
        wb = dr.select(small, w, dr.sin(w * angle.x) * angle.y)
        q = dr.normalize(qa * wa + qb * wb)
        x, y, z, s = q.x, q.y, q.z, q.w
        c0 = mi.Vector3f(1 - 2 * (y * y + z * z), 2 * (x * y + z * s), 2 * (x * z - y * s))
        c1 = mi.Vector3f(2 * (x * y - z * s), 1 - 2 * (x * x + z * z), 2 * (y * z + x * s))
        c2 = mi.Vector3f(2 * (x * z + y * s), 2 * (y * z - x * s), 1 - 2 * (x * x + y * y))
        t = dr.lerp(dr.gather(mi.Vector3f, self.t, row), dr.gather(mi.Vector3f, self.t, row + 1), w)
        stretch = None
        if not self.rigid:
            stretch = tuple(
                dr.lerp(dr.gather(mi.Vector3f, col, row), dr.gather(mi.Vector3f, col, row + 1), w) for col in self.s
            )
        return (c0, c1, c2), t, stretch

    def _to_world_point(self, pose, p):
        (c0, c1, c2), t, stretch = pose
        if stretch is not None:
            p = stretch[0] * p.x + stretch[1] * p.y + stretch[2] * p.z
        return self.mi.Point3f(c0 * p.x + c1 * p.y + c2 * p.z + t)

    def _to_world_vector(self, pose, v):
        (c0, c1, c2), _, stretch = pose
        if stretch is not None:
            v = stretch[0] * v.x + stretch[1] * v.y + stretch[2] * v.z
        return self.mi.Vector3f(c0 * v.x + c1 * v.y + c2 * v.z)

    def _stretch_inverse(self, stretch):
        """Columns of ``S⁻¹`` and ``det S`` (the adjugate over the determinant)."""
        dr = self.dr
        a, b, c = stretch
        det = dr.dot(a, dr.cross(b, c))
        inv = dr.rcp(det)
        # Rows of the inverse are the cross products of the columns; return it as columns.
        r0, r1, r2 = dr.cross(b, c) * inv, dr.cross(c, a) * inv, dr.cross(a, b) * inv
        mi = self.mi
        return (mi.Vector3f(r0.x, r1.x, r2.x), mi.Vector3f(r0.y, r1.y, r2.y), mi.Vector3f(r0.z, r1.z, r2.z)), det

    def _to_object_vector(self, pose, v):
        """``A⁻¹ v = S⁻¹ Rᵀ v``."""
        dr, mi = self.dr, self.mi
        (c0, c1, c2), _, stretch = pose
        local = mi.Vector3f(dr.dot(c0, v), dr.dot(c1, v), dr.dot(c2, v))
        if stretch is not None:
            (i0, i1, i2), _ = self._stretch_inverse(stretch)
            local = i0 * local.x + i1 * local.y + i2 * local.z
        return local

    def _to_world_normal(self, pose, n):
        """``A⁻ᵀ n`` normalised (``R S⁻ᵀ n``), and ``det A`` (1 for rigid poses)."""
        dr, mi = self.dr, self.mi
        (c0, c1, c2), _, stretch = pose
        det = mi.Float(1.0)
        if stretch is not None:
            (i0, i1, i2), det = self._stretch_inverse(stretch)
            n = mi.Vector3f(dr.dot(i0, n), dr.dot(i1, n), dr.dot(i2, n))  # S⁻ᵀ n
        return dr.normalize(c0 * n.x + c1 * n.y + c2 * n.z), det

    def _sphere_interval(self, centre, radius, ray):
        """Ray parameters ``(t_in, t_out)`` of a bounding sphere (``t_in > t_out``: missed)."""
        dr = self.dr
        oc = centre - ray.o
        inv_dd = dr.rcp(dr.squared_norm(ray.d))
        b = dr.dot(oc, ray.d) * inv_dd  # ray parameter of the closest approach
        gap2 = dr.squared_norm(oc) - dr.square(b) * dr.squared_norm(ray.d)
        half = dr.sqrt(dr.maximum(radius * radius - gap2, 0.0) * inv_dd)
        missed = gap2 > radius * radius
        return dr.select(missed, dr.inf, b - half), dr.select(missed, -dr.inf, b + half)

    def _candidates(self, members, poses: PosesAt, ray, maxt, active):
        """Bit mask of the group's shapes whose bounding sphere the segment ``[0, maxt]`` meets."""
        dr, mi = self.dr, self.mi
        mask = mi.UInt32(0)
        for bit, j in enumerate(members):
            t_in, t_out = self._sphere_interval(poses.centres[j], self.radii[j], ray)
            near = mi.Bool(active) & (t_in <= t_out) & (t_out >= 0.0) & (t_in <= maxt)
            mask |= dr.select(near, mi.UInt32(1 << bit), mi.UInt32(0))
        return mask

    def _layout_ray(self, index, key, ray, maxt):
        """Shape ``index``'s layout-space ray, clipped to its bounding sphere and ``maxt``.

        Returns ``(ray, t0, live)``: the layout ray starts at world parameter ``t0``."""
        dr, mi = self.dr, self.mi
        pose = self.pose(index, key)
        centre = self._to_world_point(pose, dr.gather(mi.Vector3f, self.centre_table, index))
        t_in, t_out = self._sphere_interval(centre, dr.gather(mi.Float, self.radius_table, index), ray)
        t0 = dr.maximum(t_in, 0.0)
        t1 = dr.minimum(maxt, t_out)
        o = self._to_object_vector(pose, ray.o - pose[1]) + dr.gather(mi.Vector3f, self.shift_table, index)
        d = self._to_object_vector(pose, ray.d)
        live = t1 > t0
        span = dr.select(live, t1 - t0, 0.0)
        return mi.Ray3f(mi.Point3f(o + d * dr.select(live, t0, 0.0)), d, span, ray.time, ray.wavelengths), t0, live

    # ------------------------------------------------------------- queries
    def at(self, time) -> PosesAt:
        """Every moving shape's bounding-sphere centre at per-lane ``time`` (and the pose key): computed
        once per sample, since all rays of a path (camera, bounces, shadow rays) share its time."""
        key = self._key(time)
        centres = [
            self._to_world_point(self.pose(j, key), self.mi.Point3f(*self.centres[j])) for j in range(self.shapes_count)
        ]
        return PosesAt(key, centres)

    def ray_intersect(self, base, ray, coherent: bool, active=True, poses: PosesAt | None = None):
        """Nearest hit of ``ray`` in ``base`` or on a moving shape at ``ray.time``.

        ``poses``: :meth:`at` of ``ray.time`` (computed here when not given). Returns
        ``(si, index, p_object)``: the world-space interaction, the moving shape hit
        (:data:`NO_OBJECT` otherwise) and the hit point in that shape's object space."""
        dr, mi = self.dr, self.mi
        flags = mi.RayFlags.All
        si = base.ray_intersect(ray, flags, coherent, active)
        best = dr.select(si.is_valid(), si.t, ray.maxt)
        poses = poses if poses is not None else self.at(ray.time)
        key = poses.key
        index = mi.UInt32(NO_OBJECT)
        pi = dr.zeros(mi.PreliminaryIntersection3f, dr.width(best))
        for members, layout in zip(self.groups, self.layouts):
            first = members[0]
            mask = self._candidates(members, poses, ray, best, active)

            def cond(mask, best, index, pi):
                return mask != 0

            def body(mask, best, index, pi, layout=layout, first=first):
                j = dr.tzcnt(mask) + first
                mask = mask & (mask - 1)
                local, t0, live = self._layout_ray(j, key, ray, best)
                pi_j = layout.ray_intersect_preliminary(local, coherent, live)
                t_hit = pi_j.t + t0
                hit = live & pi_j.is_valid() & (t_hit < best)
                pi_j.t = t_hit
                return mask, dr.select(hit, t_hit, best), dr.select(hit, j, index), dr.select(hit, pi_j, pi)

            mask, best, index, pi = dr.while_loop(
                (mask, best, index, pi), cond, body, label="denoisebench moving shapes"
            )
        moving = index != NO_OBJECT
        safe = dr.select(moving, index, 0)
        pose = self.pose(safe, key)
        # The winner's surface interaction, in layout space (the unclipped layout ray: t is the world's).
        o = self._to_object_vector(pose, ray.o - pose[1]) + dr.gather(mi.Vector3f, self.shift_table, safe)
        local = mi.Ray3f(mi.Point3f(o), self._to_object_vector(pose, ray.d), ray.maxt, ray.time, ray.wavelengths)
        found = pi.compute_surface_interaction(local, flags, moving)
        p_object = found.p - dr.gather(mi.Vector3f, self.shift_table, safe)
        world = self._to_world(found, pose, ray, p_object)
        return dr.select(moving, world, si), index, mi.Point3f(p_object)

    def _to_world(self, si, pose, ray, p_object):
        dr, mi = self.dr, self.mi
        out = mi.SurfaceInteraction3f(si)
        out.p = self._to_world_point(pose, p_object)
        n, det = self._to_world_normal(pose, si.n)
        out.n = mi.Normal3f(dr.select(det < 0.0, -n, n))
        sh_n, _ = self._to_world_normal(pose, si.sh_frame.n)
        s = self._to_world_vector(pose, si.sh_frame.s)
        s = dr.normalize(s - sh_n * dr.dot(sh_n, s))
        out.sh_frame = mi.Frame3f(s, dr.cross(sh_n, s), sh_n)
        out.dp_du = self._to_world_vector(pose, si.dp_du)
        out.dp_dv = self._to_world_vector(pose, si.dp_dv)
        out.dn_du = self._to_world_vector(pose, si.dn_du)
        out.dn_dv = self._to_world_vector(pose, si.dn_dv)
        out.wi = out.sh_frame.to_local(-ray.d)
        out.time = ray.time
        return out

    def ray_test(self, ray, active=True, poses: PosesAt | None = None):
        """Whether ``ray`` meets a moving shape (at ``ray.time``) before ``ray.maxt``."""
        dr, mi = self.dr, self.mi
        poses = poses if poses is not None else self.at(ray.time)
        key = poses.key
        blocked = mi.Bool(False)
        for members, layout in zip(self.groups, self.layouts):
            first = members[0]
            mask = self._candidates(members, poses, ray, ray.maxt, mi.Bool(active) & ~blocked)

            def cond(mask, blocked):
                return (mask != 0) & ~blocked

            def body(mask, blocked, layout=layout, first=first):
                j = dr.tzcnt(mask) + first
                mask = mask & (mask - 1)
                local, _, live = self._layout_ray(j, key, ray, ray.maxt)
                return mask, blocked | (live & layout.ray_test(local, live))

            mask, blocked = dr.while_loop((mask, blocked), cond, body, label="denoisebench moving shadows")
        return blocked

    def sample_emitter_direction(self, base, si, sample, active, poses: PosesAt | None = None):
        """``base.sample_emitter_direction`` with its visibility test extended to the moving shapes."""
        dr, mi = self.dr, self.mi
        ds, weight = base.sample_emitter_direction(si, sample, False, active)
        live = active & (dr.max(weight) != 0.0)
        # Infinite emitters (environment, constant, directional) put ds.p 2 R beyond the shading point,
        # R the *main* scene's bounding radius: moving shapes (and static geometry, seen from a point
        # on a moving shape outside that sphere) can lie further out. Their shadow rays are unbounded.
        infinite = live & mi.has_flag(ds.emitter.flags(), mi.EmitterFlags.Infinite)
        shadow = dr.select(infinite, si.spawn_ray(ds.d), si.spawn_ray_to(ds.p))
        blocked = base.ray_test(shadow, live)
        blocked |= self.ray_test(shadow, live & ~blocked, poses)
        return ds, dr.select(blocked, 0.0, weight)

    def centre_motion(self, camera, index, p_object, active):
        """Motion (pixels) of an object point at the shutter's centre: previous frame minus now."""
        dr = self.dr
        centre = camera.sample_time(0.5)
        safe = dr.select(active, index, 0)
        now = self._to_world_point(self.pose(safe, self._key(centre)), p_object)
        was = self._to_world_point(self.pose(safe, self._key(centre - 1.0)), p_object)
        now_xy, front_now = camera.project(camera.current_pose(centre), now, 1.0)
        prev_xy, front_prev = camera.project(camera.previous_pose(centre), was, 1.0)
        return prev_xy - now_xy, front_now & front_prev


class PosesAt:
    """:meth:`MovingShapes.at`: the pose key (index, weight) and every shape's bounding-sphere centre at one time."""

    def __init__(self, key, centres: list):
        self.key, self.centres = key, centres


class ShutterMotionScene:
    """A Mitsuba scene plus the shapes that move within the shutter (what ``render_frame`` takes).

    ``base`` is the ``mi.Scene`` of everything static (and of lights); :meth:`shapes` lists both kinds
    so that the renderer's scans (delta and null BSDFs, previous positions) see every shape.

    Notes
    -----
    Passes over such a scene are frozen like any other (``dr.freeze``, render/frame.py): the scene
    is a Dr.Jit PyTree (:data:`DRJIT_STRUCT`: the base scene and :class:`MovingShapes`), so its
    scenes, shapes, BSDFs and pose tables are inputs of the recording. Attribute reads other than
    these fields fall through to ``base``.
    """

    #: What a frozen pass traverses as its inputs (Dr.Jit PyTree fields; the types are not used).
    DRJIT_STRUCT = {"base": object, "moving": object}

    def __init__(self, base, moving: MovingShapes):
        self.base = base
        self.moving = moving

    def shapes(self):
        out = list(self.base.shapes())
        for scene in self.moving.layouts:
            out += list(scene.shapes())
        return out

    def __getattr__(self, name):
        return getattr(self.base, name)
