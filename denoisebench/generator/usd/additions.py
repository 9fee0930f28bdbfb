"""What ``--auto-camera`` and ``--default-light`` author into a stage that lacks a camera or lights.

Both write ordinary USD prims into the edit target the caller chooses (a session layer for
``scenes check/preview``, the copied ``scene.usda`` for ``generate``), so the dataset's stage file
holds exactly the camera and lights that were rendered, and re-translating it needs no option.

``--auto-camera`` (:func:`add_auto_camera`) frames the stage's bounds:

* bounds: ``UsdGeom.BBoxCache`` over the default and render purposes at the first frame, in
  stage units and stage axes; the camera is authored in that same space, so ``upAxis`` and
  ``metersPerUnit`` are honoured by construction (the translator maps both to Mitsuba later).
* lens: 35 mm focal length over a 36 mm horizontal aperture (fov_x ≈ 54.4°; only the ratio
  matters, see usd/camera.py), vertical aperture 36 mm too, no depth of field, no shutter.
* path: a slow orbit around the bounds' centre at the bounding sphere's radius R: distance
  ``R / sin(fov_x / 2) · 1.1`` (the sphere fills the width with 10 % margin; in images wider than
  tall the sphere's top and bottom may be cut), elevation 20° above the up axis' horizon,
  azimuth from 30° (measured in the horizontal plane from the stage's +X toward its forward axis)
  advancing 2° per frame, so the sequence has camera motion (8 frames: 14°); these numbers live in
  ``generator/contract/orbit.py``, shared with Mitsuba XML scenes. One ``xformOp:transform`` time sample per frame; clipping range ``[d/1000, d + 4R]``.
* frames: the stage's own time range when it has one (animated stages keep their timing), else
  ``0 .. frames-1`` authored as the stage's start/end time codes.

``--default-light`` (:func:`add_default_lights`) adds ``/DenoisebenchDefaultLights`` with a uniform
white ``DomeLight`` of intensity :data:`DOME_INTENSITY` (sky fill; every point sees some light) and
a key ``DistantLight`` of intensity :data:`KEY_INTENSITY` (irradiance on a surface facing it) from
45° above the horizon, 45° to the side of the auto-camera's start azimuth, so shading has a
direction and shadows show the shapes.

A stage with nothing to frame (no bounded geometry) cannot get an auto camera: UserInputError.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.orbit import (  # the orbit's numbers, shared with Mitsuba XML scenes
    APERTURE,
    FOCAL_LENGTH,
    ORBIT_START_DEGREES,
    orbit,
)
from denoisebench.generator.usd.stage import frame_range

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).

CAMERA_PATH = "/DenoisebenchAutoCamera"
LIGHTS_PATH = "/DenoisebenchDefaultLights"
DOME_INTENSITY = 0.3
KEY_INTENSITY = 2.5


def _axes(stage):
    """(up, right, forward) unit vectors of the stage's axes: Y-up (x, z) or Z-up (x, -y... ) frames."""
    from pxr import UsdGeom

    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        return np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0])
    return np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


def stage_bounds(stage, time: float = 0.0) -> tuple[np.ndarray, np.ndarray] | None:
    """World-space (stage units) axis-aligned bounds of the renderable geometry, or None if empty."""
    from pxr import Usd, UsdGeom

    cache = UsdGeom.BBoxCache(
        Usd.TimeCode(time), [UsdGeom.Tokens.default_, UsdGeom.Tokens.render], useExtentsHint=False
    )
    lows, highs = [], []
    for prim in stage.Traverse():
        if not prim.IsA(UsdGeom.Gprim):
            continue
        box = cache.ComputeWorldBound(prim).ComputeAlignedRange()
        if box.IsEmpty():
            continue
        low, high = np.array(box.GetMin(), dtype=np.float64), np.array(box.GetMax(), dtype=np.float64)
        if np.all(np.isfinite(low)) and np.all(np.isfinite(high)):
            lows.append(low)
            highs.append(high)
    if not lows:
        return None
    return np.min(lows, 0), np.max(highs, 0)


def _look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray):
    """Gf.Matrix4d (row vectors) of a camera at ``eye`` looking at ``target`` (USD cameras look down −Z)."""
    from pxr import Gf

    back = eye - target
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    rows = [list(right) + [0.0], list(true_up) + [0.0], list(back) + [0.0], list(eye) + [1.0]]
    return Gf.Matrix4d(*[float(v) for row in rows for v in row])


def orbit_frames(stage, frames: int) -> list[float]:
    """The time codes the camera is sampled at (the stage's own range, or 0..frames-1 authored now)."""

    if stage.HasAuthoredTimeCodeRange():
        return frame_range(stage)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(max(frames, 1) - 1)
    return [float(t) for t in range(max(frames, 1))]


def add_auto_camera(stage, frames: int = 8) -> str:
    """Author the orbiting camera of the module docstring; return its prim path."""
    from pxr import Gf, UsdGeom

    times = orbit_frames(stage, frames)
    bounds = stage_bounds(stage, times[0])
    if bounds is None:
        raise UserInputError("--auto-camera: the stage has no bounded geometry to frame")
    path = orbit(*bounds, len(times), *_axes(stage))  # contract/orbit.py: the numbers of the module docstring
    camera = UsdGeom.Camera.Define(stage, CAMERA_PATH)
    camera.CreateFocalLengthAttr(FOCAL_LENGTH)
    camera.CreateHorizontalApertureAttr(APERTURE)
    camera.CreateVerticalApertureAttr(APERTURE)
    camera.CreateClippingRangeAttr(Gf.Vec2f(path.near_clip, path.far_clip))
    op = camera.MakeMatrixXform()
    for pose, time in zip(path.poses, times):
        op.Set(Gf.Matrix4d(*[float(v) for v in pose.T.ravel()]), time)  # Gf stores row vectors
    return CAMERA_PATH


def add_default_lights(stage) -> str:
    """Author the dome + key light of the module docstring; return the lights' parent path."""
    from pxr import Gf, UsdGeom, UsdLux

    UsdGeom.Xform.Define(stage, LIGHTS_PATH)
    dome = UsdLux.DomeLight.Define(stage, f"{LIGHTS_PATH}/Dome")
    dome.CreateIntensityAttr(DOME_INTENSITY)
    dome.CreateColorAttr(Gf.Vec3f(1.0, 1.0, 1.0))
    key = UsdLux.DistantLight.Define(stage, f"{LIGHTS_PATH}/Key")
    key.CreateIntensityAttr(KEY_INTENSITY)
    key.CreateAngleAttr(0.53)
    up, right, forward = _axes(stage)
    azimuth = math.radians(ORBIT_START_DEGREES + 45.0)
    elevation = math.radians(45.0)
    toward_light = (
        math.cos(elevation) * (math.cos(azimuth) * right + math.sin(azimuth) * forward) + math.sin(elevation) * up
    )
    # A DistantLight shines along its local −Z: place its +Z toward the light.
    key.MakeMatrixXform().Set(_look_at(toward_light, np.zeros(3), up))
    return LIGHTS_PATH


def stage_has_light(stage) -> bool:
    from pxr import Usd, UsdLux

    return any(prim.HasAPI(UsdLux.LightAPI) for prim in Usd.PrimRange(stage.GetPseudoRoot()) if prim.IsActive())
