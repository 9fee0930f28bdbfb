"""The camera of a translated stage: its pose at every frame and its lens, in Mitsuba's conventions.

Mitsuba 3.9 samples a time per ray but moves nothing with it, so camera motion blur is ours: the
feature renderer asks :meth:`CameraTrack.pose_at` for the pose at a sampled time inside the shutter
interval and builds rays from it. Poses are camera-to-world 4×4 matrices in *Mitsuba world space*
(Y-up, meters after the stage's upAxis and metersPerUnit are applied), looking down −Z with +Y up
as USD cameras do; Mitsuba's perspective sensors look down +Z with +X to the left, so
:meth:`mitsuba_to_world` appends a 180° turn about Y.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Lazy imports: scipy (0.3 s) is imported only where a track is interpolated with rotations,
# so that the contract stays a cheap plain-data module.

# USD cameras look down -Z; Mitsuba's look down +Z (with +X pointing left in the image).
_USD_TO_MITSUBA_CAMERA = np.diag([-1.0, 1.0, -1.0, 1.0])


@dataclass
class CameraTrack:
    """A camera over a sequence of frames.

    Attributes:
        poses: F×4×4 camera-to-world matrices (USD camera convention) at frames 0..F-1.
        fov_x_deg: horizontal field of view in degrees (from focalLength and horizontalAperture).
        aperture_radius: thin-lens radius in meters; 0 for a pinhole.
        focus_distance: distance in meters to the plane in focus (used only with an aperture).
        shutter_open, shutter_close: shutter interval in frames, relative to the frame time
            (USD's ``shutter:open``/``shutter:close``); equal values mean no motion blur.
        near_clip, far_clip: clipping range in meters.
        prim_path: the camera prim this came from.
        projection: ``"perspective"`` (pinhole or thin lens, the default) or ``"orthographic"``
            (Mitsuba's ``orthographic`` sensor: parallel rays along the camera's forward axis; the
            pose's scale sets the view's extent, 2 units wide before scaling; ``fov_x_deg`` unused).
    """

    poses: np.ndarray
    fov_x_deg: float
    aperture_radius: float = 0.0
    focus_distance: float = 1.0
    shutter_open: float = 0.0
    shutter_close: float = 0.0
    near_clip: float = 0.01
    far_clip: float = 1.0e4
    prim_path: str = ""
    extra: dict = field(default_factory=dict)
    projection: str = "perspective"

    @property
    def frames(self) -> int:
        return int(self.poses.shape[0])

    @property
    def has_depth_of_field(self) -> bool:
        return self.aperture_radius > 0.0

    @property
    def is_animated(self) -> bool:
        return self.frames > 1 and not np.allclose(self.poses, self.poses[:1])

    @property
    def has_open_shutter(self) -> bool:
        return self.shutter_close > self.shutter_open

    def pose_at(self, time: float) -> np.ndarray:
        """Camera-to-world at fractional frame ``time``: translation lerped, rotation slerped.

        Times outside [0, F-1] clamp to the end poses (the camera holds still before and after).
        """
        time = float(np.clip(time, 0.0, self.frames - 1))
        lo = int(np.floor(time))
        hi = min(lo + 1, self.frames - 1)
        t = time - lo
        if hi == lo or t == 0.0:
            return self.poses[lo].copy()
        return _interpolate_rigid(self.poses[lo], self.poses[hi], t)

    def mitsuba_to_world(self, time: float) -> np.ndarray:
        """Pose at ``time`` as Mitsuba's sensor ``to_world`` (looks down +Z)."""
        return self.pose_at(time) @ _USD_TO_MITSUBA_CAMERA


def _interpolate_rigid(a: np.ndarray, b: np.ndarray, t: float) -> np.ndarray:
    """Interpolate two similarity transforms: scale and translation linearly, rotation by slerp."""
    from scipy.spatial.transform import Rotation, Slerp

    scale_a = np.linalg.norm(a[:3, :3], axis=0)
    scale_b = np.linalg.norm(b[:3, :3], axis=0)
    rotations = Rotation.from_matrix(np.stack([a[:3, :3] / scale_a, b[:3, :3] / scale_b]))
    rotation = Slerp([0.0, 1.0], rotations)([t]).as_matrix()[0]
    out = np.eye(4)
    out[:3, :3] = rotation * ((1 - t) * scale_a + t * scale_b)
    out[:3, 3] = (1 - t) * a[:3, 3] + t * b[:3, 3]
    return out
