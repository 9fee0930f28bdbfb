"""The ``--auto-camera`` orbit as numbers: lens, distance and poses that frame an axis-aligned box.

One definition for both scene sources: ``generator/usd/additions.py`` authors these poses into a
USD stage (in the stage's own units and axes), and ``generator/mitsuba_xml.py`` builds the
:class:`~denoisebench.generator.contract.camera_track.CameraTrack` of a Mitsuba XML scene from them
(in Mitsuba world space), so that ``--auto-camera`` frames a scene the same way whatever its format.

Notes
-----
* lens: :data:`FOCAL_LENGTH` mm over a :data:`APERTURE` mm horizontal aperture (fov_x ≈ 54.4°),
  no depth of field, no shutter.
* path: a slow orbit around the box's centre at its bounding sphere's radius R: distance
  ``R / sin(fov_x / 2) · 1.1`` (the sphere fills the width with 10 % margin; in images wider than
  tall its top and bottom may be cut), elevation :data:`ORBIT_ELEVATION_DEGREES` above the up axis'
  horizon, azimuth from :data:`ORBIT_START_DEGREES` (in the horizontal plane, from ``right``
  toward ``forward``) advancing :data:`ORBIT_DEGREES_PER_FRAME` per frame; clipping range
  ``[d/1000, d + 4R]``. A degenerate (point) box gets R = 1e-6.
* poses: camera-to-world 4×4 matrices in the column-vector convention of :class:`CameraTrack`
  (translation in the last column), looking down their −Z axis with +Y up, as USD cameras do.
  USD's ``Gf.Matrix4d`` stores the transpose (row vectors).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ORBIT_DEGREES_PER_FRAME = 2.0
ORBIT_START_DEGREES = 30.0
ORBIT_ELEVATION_DEGREES = 20.0
FOCAL_LENGTH = 35.0
APERTURE = 36.0


@dataclass(frozen=True)
class Orbit:
    """The orbit framing a box: ``poses`` (F×4×4, module Notes), horizontal field of view, clip range."""

    poses: np.ndarray
    fov_x_deg: float
    near_clip: float
    far_clip: float


def fov_x_radians() -> float:
    """Horizontal field of view of the orbit's lens."""
    return 2.0 * math.atan(0.5 * APERTURE / FOCAL_LENGTH)


def look_at(eye, target, up) -> np.ndarray:
    """Camera-to-world (column vectors) of a camera at ``eye`` looking at ``target`` down its −Z axis."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = right, true_up, back, eye
    return pose


def orbit(low, high, frames: int, up=(0.0, 1.0, 0.0), right=(1.0, 0.0, 0.0), forward=(0.0, 0.0, 1.0)) -> Orbit:
    """The orbit of the module Notes around the box ``[low, high]`` over ``frames`` frames (at least 1)."""
    low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    up, right, forward = (np.asarray(v, dtype=np.float64) for v in (up, right, forward))
    center = 0.5 * (low + high)
    radius = max(0.5 * float(np.linalg.norm(high - low)), 1e-6)
    fov_x = fov_x_radians()
    distance = radius / math.sin(0.5 * fov_x) * 1.1
    elevation = math.radians(ORBIT_ELEVATION_DEGREES)
    poses = []
    for index in range(max(int(frames), 1)):
        azimuth = math.radians(ORBIT_START_DEGREES + ORBIT_DEGREES_PER_FRAME * index)
        direction = (
            math.cos(elevation) * (math.cos(azimuth) * right + math.sin(azimuth) * forward) + math.sin(elevation) * up
        )
        poses.append(look_at(center + distance * direction, center, up))
    return Orbit(np.stack(poses), math.degrees(fov_x), distance / 1000.0, distance + 4.0 * radius)
