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


def medium_dict(mi, medium: dict) -> dict:
    """The ``mi.load_dict`` dictionary of a translated medium record (generator/usd/media.py documents it)."""
    phase = {"type": "hg", "g": medium["g"]} if medium["g"] != 0.0 else {"type": "isotropic"}
    sigma = np.asarray(medium["sigma_t"], dtype=np.float64)
    if medium["type"] == "homogeneous":
        peak = float(sigma.max())
        unit = (sigma / peak).tolist() if peak > 0 else [0.0, 0.0, 0.0]
        return {
            "type": "homogeneous",
            "sigma_t": {"type": "rgb", "value": unit},
            "scale": peak,
            "albedo": {"type": "rgb", "value": list(medium["albedo"])},
            "phase": phase,
        }
    density = np.asarray(medium["density"], dtype=np.float32)
    if np.allclose(sigma, sigma[0]):
        data = density[..., None] * np.float32(sigma[0])
    else:
        data = density[..., None] * sigma.astype(np.float32)
    return {
        "type": "heterogeneous",
        "sigma_t": {
            "type": "gridvolume",
            "data": mi.TensorXf(np.ascontiguousarray(data, dtype=np.float32)),
            "to_world": mi.ScalarTransform4f(np.asarray(medium["grid_to_world"], dtype=np.float64).tolist()),
        },
        "albedo": {"type": "rgb", "value": list(medium["albedo"])},
        "scale": 1.0,
        "phase": phase,
    }
