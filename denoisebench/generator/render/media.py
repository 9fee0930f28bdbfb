"""Which participating media a Mitsuba scene binds: what decides whether the volumetric tracer runs.

A scene has media when a shape is bound to one (``interior``/``exterior``) or the camera sits in one
(the sensor's ``medium``). :func:`scene_has_media` sets ``KernelOptions.media`` (render/frame.py):
only then does :mod:`~denoisebench.generator.render.volpath` trace the frame; every other scene runs
the surface tracer unchanged (same kernels, same bytes). Media unbound to anything are not rendered
by Mitsuba either and do not count.
"""

from __future__ import annotations

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.scene_parts import MediumRecord, MeshShape, ShapeRecord, SphereShape
from denoisebench.generator.render.motion import ShutterMotionScene


def scene_media(scene) -> list:
    """Every medium the scene binds: shapes' interiors and exteriors and the sensors' media (no duplicates)."""
    found = []
    for shape in scene.shapes():
        for medium in (shape.interior_medium(), shape.exterior_medium()):
            if medium is not None and all(medium is not m for m in found):
                found.append(medium)
    for sensor in scene.sensors():
        medium = sensor.get_medium()
        if medium is not None and all(medium is not m for m in found):
            found.append(medium)
    return found


def scene_has_media(scene) -> bool:
    """True when some shape or sensor of ``scene`` (a ``mi.Scene``) is bound to a participating medium.

    A :class:`ShutterMotionScene` (shapes moving within the shutter) with media is refused (one-line
    UserInputError): the volumetric tracer does not intersect moving shapes."""
    if isinstance(scene, ShutterMotionScene):
        if scene_media(scene.base):
            raise UserInputError(
                "participating media in a scene whose shapes move within the shutter are not supported "
                "(render without motion blur, or without the medium)"
            )
        return False
    return bool(scene_media(scene))


def camera_medium(scene):
    """The medium the camera sits in: the first sensor's (None without sensors or medium)."""
    sensors = scene.sensors()
    return sensors[0].get_medium() if sensors else None


def medium_dict(mi, medium: MediumRecord) -> dict:
    """The ``mi.load_dict`` dictionary of a translated medium record (generator/usd/media.py documents it)."""
    phase = {"type": "hg", "g": medium.g} if medium.g != 0.0 else {"type": "isotropic"}
    sigma = np.asarray(medium.sigma_t, dtype=np.float64)
    if medium.kind == "homogeneous":
        peak = float(sigma.max())
        unit = (sigma / peak).tolist() if peak > 0 else [0.0, 0.0, 0.0]
        return {
            "type": "homogeneous",
            "sigma_t": {"type": "rgb", "value": unit},
            "scale": peak,
            "albedo": {"type": "rgb", "value": list(medium.albedo)},
            "phase": phase,
        }
    density = np.asarray(medium.density, dtype=np.float32)
    if np.allclose(sigma, sigma[0]):
        data = density[..., None] * np.float32(sigma[0])
    else:
        data = density[..., None] * sigma.astype(np.float32)
    return {
        "type": "heterogeneous",
        "sigma_t": {
            "type": "gridvolume",
            "data": mi.TensorXf(np.ascontiguousarray(data, dtype=np.float32)),
            "to_world": mi.ScalarTransform4f(np.asarray(medium.grid_to_world, dtype=np.float64).tolist()),
        },
        "albedo": {"type": "rgb", "value": list(medium.albedo)},
        "scale": 1.0,
        "phase": phase,
    }


def _inside_sphere(point: np.ndarray, record: SphereShape) -> bool:
    return float(np.linalg.norm(point - np.asarray(record.center, dtype=np.float64))) < float(record.radius)


def _inside_mesh(point: np.ndarray, record: MeshShape) -> bool:
    """Ray parity (Möller-Trumbore over every triangle) along a direction no axis-aligned mesh shares."""
    positions = np.asarray(record.positions, dtype=np.float64)
    faces = np.asarray(record.faces, dtype=np.int64).reshape(-1, 3)
    v0, v1, v2 = positions[faces[:, 0]], positions[faces[:, 1]], positions[faces[:, 2]]
    d = np.array([0.5773, 0.5774, 0.5775]) / np.linalg.norm([0.5773, 0.5774, 0.5775])
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = point - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    hits = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
    return bool(np.count_nonzero(hits) % 2)


def _surface_point(record: MeshShape | SphereShape) -> np.ndarray:
    if isinstance(record, SphereShape):
        return np.asarray(record.center, dtype=np.float64) + np.array([0.0, float(record.radius), 0.0])
    return np.asarray(record.positions, dtype=np.float64)[0]


def _box_volume(record: MeshShape | SphereShape) -> float:
    if isinstance(record, SphereShape):
        return (2.0 * float(record.radius)) ** 3
    positions = np.asarray(record.positions, dtype=np.float64)
    return float(np.prod(positions.max(0) - positions.min(0)))


def enclosing_media(records: tuple[ShapeRecord, ...]) -> dict[int, int]:
    """Nested media: for each shape record with a ``medium``, the index of the innermost other medium
    record whose (closed) shape contains it (absent: it sits in no medium).

    A boundary inside another's medium has that medium as its exterior (Mitsuba's ``exterior``), so a
    ray leaving smoke inside fog is in the fog again. Containment is tested at a point of the inner
    boundary's surface (spheres: analytically; meshes: ray parity).
    """
    boundaries = [i for i, r in enumerate(records) if r.medium is not None and isinstance(r, (SphereShape, MeshShape))]
    out = {}
    for i in boundaries:
        point = _surface_point(records[i])
        containers = [
            j
            for j in boundaries
            if j != i
            and (
                _inside_sphere(point, records[j])
                if isinstance(records[j], SphereShape)
                else _inside_mesh(point, records[j])
            )
        ]
        if containers:
            out[i] = min(containers, key=lambda j: _box_volume(records[j]))
    return out
