"""Ray generation for the feature renderer: pinhole / thin lens, camera motion blur, reprojection.

Mitsuba 3.9 samples a time per ray but moves nothing with it, so the renderer builds its own camera
rays (docs/architecture.md, "Effects and the render plan"). Conventions, shared with Mitsuba's ``perspective``
and ``thinlens`` sensors so that both render the same image:

* Pixel ``(i, j)`` (row ``i`` from the top, column ``j`` from the left) takes samples at film
  position ``(j + u, i + v)`` with ``u, v`` uniform in [0, 1): a one-pixel box filter.
* Camera frame: Mitsuba's (``CameraTrack.mitsuba_to_world``): local +Z forward, +Y up, +X to the
  *left* of the image. Horizontal field of view ``camera.fov_x_deg``; the vertical one follows from
  the image aspect.
* Thin lens: aperture radius ``camera.aperture_radius * plan.aperture_scale``, focus distance
  ``camera.focus_distance``, lens point ``square_to_uniform_disk_concentric(lens_uv)``; rays aim at
  the point of the focal plane that the pinhole ray through the film position would hit.
* Rays start on the near clipping plane and end on the far one, like Mitsuba's sensors.
* Orthographic (``camera.projection == "orthographic"``, Mitsuba's ``orthographic`` sensor): every
  ray runs along the camera's forward axis from the point ``(-ndc_x, -ndc_y * height / width,
  near)`` of the camera frame (``ndc`` in [-1, 1]), scaled and placed by the pose, so the view is 2
  units wide before the pose's scale; it ends ``far - near`` further on. Depth is the distance from
  the camera plane; motion vectors project points by dropping the depth. Pitfall: a miss (a
  direction, not a point) has no film position under this projection, so its motion is zero.
* Time (motion blur only): a ray's time is ``frame + m + (s - 1/2) * (close - open) * shutter_scale``
  with ``s`` uniform in [0, 1) and ``m = (open + close) / 2``: the shutter interval scaled about its
  midpoint. The camera pose at that time interpolates the two bracketing frame poses exactly as
  :meth:`CameraTrack.pose_at` does (translation and scale lerped, rotation slerped), per ray, in
  Dr.Jit. Without time sampling every ray uses the pose at ``t = frame``.

All numbers that vary between frames (pose, lens, time) enter the kernels as *opaque* Dr.Jit values,
so a new frame reuses the compiled kernel instead of baking new literals into a new one, and they are
copied into Dr.Jit's own memory, never mapped NumPy buffers, so a frozen pass replays its recording
for every frame and reference round (:func:`_owned_floats`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.render_plan import RenderPlan

# Lazy imports: Dr.Jit only after mitsuba_runtime has picked Mitsuba's variant, and scipy (0.3 s)
# only where rotations are interpolated; both inside the functions that need them.


@dataclass(frozen=True)
class CameraSetup:
    """Host-side description of the camera for one frame (plain numbers and small tables)."""

    width: int
    height: int
    tan_half_x: float
    tan_half_y: float
    thin_lens: bool
    aperture_radius: float
    focus_distance: float
    near_clip: float
    far_clip: float
    time_sampling: bool
    frame: int
    time_center: float  # frame + shutter midpoint (frames); used only with time sampling
    time_span: float  # (close - open) * shutter_scale (frames); used only with time sampling
    static_pose: np.ndarray | None  # 4×4 Mitsuba to_world used by every ray, or None: per-ray poses
    prev_pose: np.ndarray | None  # 4×4 Mitsuba to_world of the previous frame (static case), or None
    has_previous: bool  # frame > 0: motion vectors are computed (else they are zero)
    # Per-ray pose tables (time sampling with an animated camera), one entry per frame interval k:
    # quaternion (x, y, z, w) at frame k and k+1 (same hemisphere), translation, column scales.
    quat_a: np.ndarray | None = None
    quat_b: np.ndarray | None = None
    trans: np.ndarray | None = None
    scale: np.ndarray | None = None
    frames: int = 1
    orthographic: bool = False  # tan_half_x/y are then the half extents of the view (1, height/width)


def camera_setup(camera: CameraTrack, frame: int, plan: RenderPlan, width: int, height: int) -> CameraSetup:
    """Collect everything ray generation needs for ``frame`` (no Dr.Jit involved)."""
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive (got {width}×{height})")
    if not 0 <= frame < camera.frames:
        raise ValueError(f"frame {frame} outside the camera track (0..{camera.frames - 1})")
    orthographic = camera.projection == "orthographic"
    if camera.projection not in ("perspective", "orthographic"):
        raise ValueError(f"unknown camera projection {camera.projection!r}")
    tan_half_x = 1.0 if orthographic else math.tan(math.radians(camera.fov_x_deg) / 2.0)
    thin_lens = plan.camera_model == "thin_lens"
    if plan.camera_model not in ("pinhole", "thin_lens"):
        raise ValueError(f"unknown camera model {plan.camera_model!r}")
    span = (camera.shutter_close - camera.shutter_open) * plan.shutter_scale if plan.time_sampling else 0.0
    center = frame + 0.5 * (camera.shutter_open + camera.shutter_close) if plan.time_sampling else float(frame)
    per_ray = plan.time_sampling and camera.is_animated and span > 0.0
    common = dict(
        width=width,
        height=height,
        tan_half_x=tan_half_x,
        tan_half_y=tan_half_x * height / width,
        thin_lens=thin_lens,
        aperture_radius=float(camera.aperture_radius * plan.aperture_scale) if thin_lens else 0.0,
        focus_distance=float(camera.focus_distance),
        near_clip=float(camera.near_clip),
        far_clip=float(camera.far_clip),
        time_sampling=bool(plan.time_sampling),
        frame=int(frame),
        time_center=float(center),
        time_span=float(span),
        has_previous=frame > 0,
        frames=camera.frames,
        orthographic=orthographic,
    )
    if not per_ray:
        # One pose for every ray: the pose at the (center) time; the previous frame's one second earlier.
        time = center if plan.time_sampling else float(frame)
        return CameraSetup(
            static_pose=camera.mitsuba_to_world(time),
            prev_pose=camera.mitsuba_to_world(time - 1.0) if frame > 0 else None,
            **common,
        )
    quat_a, quat_b, trans, scale = _pose_tables(camera)
    return CameraSetup(
        static_pose=None, prev_pose=None, quat_a=quat_a, quat_b=quat_b, trans=trans, scale=scale, **common
    )


def _pose_tables(camera: CameraTrack):
    """Quaternions, translations and scales of every frame's Mitsuba pose, for per-ray slerp."""
    from scipy.spatial.transform import Rotation

    mats = np.stack([camera.mitsuba_to_world(float(k)) for k in range(camera.frames)])
    scale = np.linalg.norm(mats[:, :3, :3], axis=1)  # column norms, F×3
    rot = mats[:, :3, :3] / scale[:, None, :]
    quats = Rotation.from_matrix(rot).as_quat()  # (x, y, z, w)
    quat_a = quats[:-1].copy()
    quat_b = quats[1:].copy()
    flip = np.sum(quat_a * quat_b, axis=1) < 0  # shortest arc, as scipy's Slerp
    quat_b[flip] *= -1.0
    return quat_a, quat_b, mats[:, :3, 3].copy(), scale


#: Fewest rows of a per-ray pose table (see :func:`_table`).
MIN_TABLE_ROWS = 64

#: Per-frame numbers of the camera, in the order of the packed ``scalars`` array of :func:`camera_values`.
_SCALARS = (
    "tan_x",
    "tan_y",
    "inv_w",
    "inv_h",
    "width",
    "height",
    "aperture",
    "focus",
    "near",
    "far",
    "time_center",
    "time_span",
    "frame_time",
    "last_frame",
)


@dataclass(frozen=True)
class CameraSwitches:
    """What about the camera changes the kernel's code (hashable: part of a compiled pass's key)."""

    thin_lens: bool
    time_sampling: bool
    has_previous: bool  # frame > 0: motion vectors are computed
    per_ray_pose: bool  # animated camera under time sampling: poses slerped per ray from tables
    orthographic: bool = False  # parallel rays (CameraTrack.projection "orthographic")


def camera_switches(setup: CameraSetup) -> CameraSwitches:
    return CameraSwitches(
        thin_lens=setup.thin_lens,
        time_sampling=setup.time_sampling,
        has_previous=setup.has_previous,
        per_ray_pose=setup.static_pose is None,
        orthographic=setup.orthographic,
    )


def camera_values(mi, setup: CameraSetup) -> dict:
    """Every number of the frame's camera as Dr.Jit arrays: what a compiled pass takes as input.

    Notes:
        The per-frame numbers (field of view, clipping, lens, time, static poses) travel as *one*
        array, read in the kernel by gathers at fixed positions: as separate opaque scalars, each
        was its own memset task on Dr.Jit's thread pool (~40 per frame), and as literals each new
        value would compile a new kernel.
    """
    scalars = {
        "tan_x": setup.tan_half_x,
        "tan_y": setup.tan_half_y,
        "inv_w": 1.0 / setup.width,
        "inv_h": 1.0 / setup.height,
        "width": setup.width,
        "height": setup.height,
        "aperture": setup.aperture_radius,
        "focus": setup.focus_distance,
        "near": setup.near_clip,
        "far": setup.far_clip,
        "time_center": setup.time_center,
        "time_span": setup.time_span,
        "frame_time": float(setup.frame),
        "last_frame": float(setup.frames - 1),
    }
    packed = [float(scalars[name]) for name in _SCALARS]
    if setup.static_pose is not None:
        # Columns 0..3 (three axes and the translation), rows 0..2, for this frame and the previous one.
        for pose in (setup.static_pose, setup.prev_pose if setup.prev_pose is not None else setup.static_pose):
            packed += [float(pose[r, c]) for c in range(4) for r in range(3)]
        return {"scalars": _owned_floats(mi, packed)}
    return {
        "scalars": _owned_floats(mi, packed),
        "qa": _table(mi, mi.Vector4f, setup.quat_a),
        "qb": _table(mi, mi.Vector4f, setup.quat_b),
        "tr": _table(mi, mi.Vector3f, setup.trans),
        "sc": _table(mi, mi.Vector3f, setup.scale),
    }


def _owned_floats(mi, values):
    """``values`` as a Dr.Jit ``Float`` in memory that Dr.Jit allocated (a copy, never a view).

    Notes:
        ``mi.Float(numpy_array)`` does not copy: it maps the NumPy buffer (writing to the array
        afterwards changes the Dr.Jit one). A frozen pass keys its recordings on the layout of its
        inputs, and that includes whether each mapped buffer is aligned; NumPy's small buffers come
        at varying alignments, so a frame whose camera arrays landed differently from the last one
        was recorded again instead of replayed: a motion-blurred scene (14 table columns, fresh every
        frame and every reference round) re-recorded on nearly every pass. Built from a list, the
        values are copied into an aligned Dr.Jit allocation, the same bits every time.
    """
    return mi.Float(np.asarray(values, dtype=np.float32).tolist())


def _table(mi, kind, rows: np.ndarray):
    """A per-frame table as a Dr.Jit array (one entry per row), padded to :data:`MIN_TABLE_ROWS`.

    Notes:
        Tiny tables break kernel caching: a one-entry array becomes a literal (new code for
        every camera), and small buffers came back with varying alignment, which Dr.Jit writes
        into the kernel (``align 1`` / ``align 4``), so every frame compiled anew (~2.5 s).
        Padding rows (copies of the last) are never gathered.
    """
    import drjit as dr

    padded = np.concatenate([rows, np.repeat(rows[-1:], max(0, MIN_TABLE_ROWS - len(rows)), axis=0)])
    columns = [_owned_floats(mi, padded[:, c]) for c in range(padded.shape[1])]
    table = kind(*columns)
    dr.make_opaque(table)
    return table


class DrCamera:
    """The camera of one frame in Dr.Jit; builds rays and reprojects points.

    Built from :func:`camera_switches` (Python switches that shape the code) and
    :func:`camera_values` (Dr.Jit arrays), so that a compiled pass can take the values as inputs.
    """

    def __init__(self, mi, switches: CameraSwitches, values: dict):
        import drjit as dr

        self.mi = mi
        self.dr = dr
        self.switches = switches
        scalars = values["scalars"]

        def scalar(i: int):
            return dr.gather(mi.Float, scalars, mi.UInt32(i))

        for i, name in enumerate(_SCALARS):
            setattr(self, name, scalar(i))
        if not switches.per_ray_pose:
            base = len(_SCALARS)

            def pose(at: int):
                return tuple(mi.Vector3f(*[scalar(at + 3 * c + r) for r in range(3)]) for c in range(4))

            self.static = pose(base)
            self.prev_static = pose(base + 12) if switches.has_previous else None
        else:
            self.static = self.prev_static = None
            self.qa, self.qb, self.tr, self.sc = values["qa"], values["qb"], values["tr"], values["sc"]

    # ------------------------------------------------------------------ poses
    def pose_at(self, time):
        """Per-ray pose (three scaled rotation columns and translation) at fractional frame ``time``."""
        dr, mi = self.dr, self.mi
        t = dr.clip(time, 0.0, self.last_frame)
        k = mi.UInt32(dr.minimum(dr.floor(t), dr.maximum(self.last_frame - 1.0, 0.0)))
        w = t - mi.Float(k)
        qa = dr.gather(mi.Vector4f, self.qa, k)
        qb = dr.gather(mi.Vector4f, self.qb, k)
        k1 = k + 1
        ta = dr.gather(mi.Vector3f, self.tr, k)
        tb = dr.gather(mi.Vector3f, self.tr, k1)
        sa = dr.gather(mi.Vector3f, self.sc, k)
        sb = dr.gather(mi.Vector3f, self.sc, k1)
        cos_theta = dr.minimum(dr.dot(qa, qb), 1.0)
        theta = dr.acos(cos_theta)
        sin_theta = dr.sin(theta)
        small = sin_theta < 1e-5
        inv_sin = dr.rcp(dr.select(small, 1.0, sin_theta))
        wa = dr.select(small, 1.0 - w, dr.sin((1.0 - w) * theta) * inv_sin)
        wb = dr.select(small, w, dr.sin(w * theta) * inv_sin)
        q = dr.normalize(qa * wa + qb * wb)
        x, y, z, s = q.x, q.y, q.z, q.w
        c0 = mi.Vector3f(1 - 2 * (y * y + z * z), 2 * (x * y + z * s), 2 * (x * z - y * s))
        c1 = mi.Vector3f(2 * (x * y - z * s), 1 - 2 * (x * x + z * z), 2 * (y * z + x * s))
        c2 = mi.Vector3f(2 * (x * z + y * s), 2 * (y * z - x * s), 1 - 2 * (x * x + y * y))
        scale = dr.lerp(sa, sb, w)
        return (c0 * scale.x, c1 * scale.y, c2 * scale.z, dr.lerp(ta, tb, w))

    def sample_time(self, s):
        return self.time_center + (s - 0.5) * self.time_span

    def current_pose(self, time):
        return self.static if self.static is not None else self.pose_at(time)

    def previous_pose(self, time):
        """Pose one frame before the ray's time (``None`` at frame 0: no previous frame)."""
        if not self.switches.has_previous:
            return None
        return self.prev_static if self.static is not None else self.pose_at(time - 1.0)

    # ------------------------------------------------------------------- rays
    def generate_ray(self, film_xy, lens_uv, time):
        """World-space ray through film position ``film_xy`` (pixels); returns (ray, pose)."""
        dr, mi = self.dr, self.mi
        ndc_x = film_xy.x * self.inv_w * 2.0 - 1.0
        ndc_y = film_xy.y * self.inv_h * 2.0 - 1.0
        near_p = mi.Vector3f(-ndc_x * self.tan_x, -ndc_y * self.tan_y, 1.0)  # +X left, +Y up in camera space
        pose = self.current_pose(time)
        c0, c1, c2, origin = pose
        if self.switches.orthographic:
            o = origin + c0 * near_p.x + c1 * near_p.y + c2 * self.near
            d = dr.normalize(c2)
            ray = mi.Ray3f(o, d, self.far - self.near, time, mi.Color0f())
            return ray, pose
        if self.switches.thin_lens:
            lens = mi.warp.square_to_uniform_disk_concentric(lens_uv) * self.aperture
            d_local = dr.normalize(near_p * self.focus - mi.Vector3f(lens.x, lens.y, 0.0))
            o = origin + c0 * lens.x + c1 * lens.y
        else:
            d_local = dr.normalize(near_p)
            o = origin
        d = dr.normalize(c0 * d_local.x + c1 * d_local.y + c2 * d_local.z)
        inv_z = dr.rcp(d_local.z)
        near_t = self.near * inv_z
        ray = mi.Ray3f(o + d * near_t, d, self.far * inv_z - near_t, time, mi.Color0f())
        return ray, pose

    @staticmethod
    def forward(pose):
        return pose[2]

    def to_local(self, pose, p, w):
        """Camera-space coordinates of world point ``p`` (``w = 1``) or direction (``w = 0``)."""
        dr = self.dr
        c0, c1, c2, origin = pose
        q = p - origin * w
        return (
            dr.dot(c0, q) / dr.squared_norm(c0),
            dr.dot(c1, q) / dr.squared_norm(c1),
            dr.dot(c2, q) / dr.squared_norm(c2),
        )

    def project(self, pose, p, w):
        """Film position (pixels, x right, y down) of a point/direction, and whether it is in front."""
        dr, mi = self.dr, self.mi
        x, y, z = self.to_local(pose, p, w)
        if self.switches.orthographic:  # a point's film position drops its depth; a direction has none
            front = z > 1e-6
            front = front if isinstance(w, (int, float)) and w > 0.5 else front & (w > 0.5)
            px = (1.0 - x / self.tan_x) * 0.5 * self.width
            py = (1.0 - y / self.tan_y) * 0.5 * self.height
            return mi.Point2f(px, py), front
        front = z > 1e-6
        inv_z = dr.rcp(dr.select(front, z, 1.0))
        px = (1.0 - x * inv_z / self.tan_x) * 0.5 * self.width
        py = (1.0 - y * inv_z / self.tan_y) * 0.5 * self.height
        return mi.Point2f(px, py), front
