"""UsdGeom.Camera → :class:`CameraTrack`.

Units (UsdGeomCamera's own convention): ``focalLength`` and the apertures are in *tenths of a scene
unit* (millimeters on a centimeter stage), ``focusDistance`` and ``clippingRange`` in scene units,
``shutter:open``/``shutter:close`` in frames relative to the frame's time code. The field of view
depends only on the aperture/focal-length ratio; the thin-lens radius is
``focalLength / (2·fStop)`` converted to meters.
"""

from __future__ import annotations

import math

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.usd.stage import check_finite, stage_meters_per_unit, to_numpy

# Lazy imports: pxr, inside the functions that use it (generator/usd/__init__.py says why).


def find_camera(stage, camera_path: str | None = None):
    """The camera prim to render: ``camera_path`` if given, else the first camera in the stage."""
    from pxr import Usd, UsdGeom

    if camera_path:
        prim = stage.GetPrimAtPath(camera_path)
        if not prim or not prim.IsA(UsdGeom.Camera):
            raise UserInputError(f"{camera_path}: no camera prim at this path")
        return prim
    cameras = [p for p in Usd.PrimRange(stage.GetPseudoRoot()) if p.IsA(UsdGeom.Camera) and p.IsActive()]
    if not cameras:
        raise UserInputError(
            f"{stage.GetRootLayer().realPath or 'stage'}: no camera (UsdGeom.Camera) in the stage; "
            "name one with --camera PATH or frame the stage with --auto-camera"
        )
    return cameras[0]


def read_camera(stage, prim, frame_times, to_mitsuba: np.ndarray, warnings: list[str]) -> CameraTrack:
    """Poses at every frame time and the lens of camera ``prim`` in Mitsuba world space."""
    from pxr import UsdGeom

    camera = UsdGeom.Camera(prim)
    path = str(prim.GetPath())
    xformable = UsdGeom.Xformable(prim)
    poses = []
    for time in frame_times:
        local_to_world = to_numpy(xformable.ComputeLocalToWorldTransform(time))
        check_finite(local_to_world, path, "xformOps")
        pose = to_mitsuba @ local_to_world
        rotation = pose[:3, :3]
        scale = np.linalg.norm(rotation, axis=0)
        if np.any(scale < 1e-12):
            raise UserInputError(f"{path}: camera transform is singular at time {time:g}")
        pose[:3, :3] = rotation / scale  # cameras carry no scale; remove units/ancestor scaling
        poses.append(pose)

    def get(attribute, name):
        value = attribute.Get(frame_times[0])
        check_finite(value if value is not None else 0.0, path, name)
        return value

    projection = camera.GetProjectionAttr().Get()
    if projection != UsdGeom.Tokens.perspective:
        raise UserInputError(f"{path}: projection '{projection}' is not supported (perspective only)")
    focal = float(get(camera.GetFocalLengthAttr(), "focalLength"))
    h_aperture = float(get(camera.GetHorizontalApertureAttr(), "horizontalAperture"))
    if focal <= 0 or h_aperture <= 0:
        raise UserInputError(f"{path}: focalLength and horizontalAperture must be positive")
    fov_x = math.degrees(2.0 * math.atan(0.5 * h_aperture / focal))

    meters = stage_meters_per_unit(stage)
    f_stop = float(get(camera.GetFStopAttr(), "fStop") or 0.0)
    focus = float(get(camera.GetFocusDistanceAttr(), "focusDistance") or 0.0)
    aperture_radius = 0.0
    if f_stop > 0:
        if focus <= 0:
            warnings.append(f"{path}: fStop {f_stop:g} with focusDistance {focus:g}; depth of field skipped")
        else:
            focal_m = focal * 0.1 * meters
            aperture_radius = focal_m / (2.0 * f_stop)
    clip = get(camera.GetClippingRangeAttr(), "clippingRange")
    near, far = (float(clip[0]) * meters, float(clip[1]) * meters) if clip is not None else (0.01, 1e4)
    shutter_open = float(get(camera.GetShutterOpenAttr(), "shutter:open") or 0.0)
    shutter_close = float(get(camera.GetShutterCloseAttr(), "shutter:close") or 0.0)
    if shutter_close < shutter_open:
        warnings.append(f"{path}: shutter closes before it opens; motion blur skipped")
        shutter_close = shutter_open
    return CameraTrack(
        poses=np.stack(poses),
        fov_x_deg=fov_x,
        aperture_radius=aperture_radius,
        focus_distance=max(focus * meters, 1e-6),
        shutter_open=shutter_open,
        shutter_close=shutter_close,
        near_clip=max(near, 1e-6),
        far_clip=max(far, near * 2),
        prim_path=path,
    )
