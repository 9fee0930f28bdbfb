"""Mitsuba 3 XML scene files as a scene source: ``generate-dataset --mitsuba scene.xml`` (alias ``--xml``).

The file is loaded by Mitsuba itself (``mi.load_file`` with the scene's parameters), and rendered by
the same feature renderer as a translated USD stage
(:func:`~denoisebench.generator.render.frame.render_frame`), which takes a ``mi.Scene``, a
:class:`CameraTrack` and a :class:`RenderPlan`. What this module adds is the camera track and the
effects, read off the loaded scene, and the checks a loaded scene must pass; what Mitsuba's parser
makes of the file (parameters, the files it names, its integrator's transport restriction) and the
dataset's portable copy are :mod:`~denoisebench.generator.mitsuba_xml_structure`.

Notes
-----
* Camera: the scene's first sensor (``perspective``, ``thinlens`` or ``orthographic``; others are
  refused), held still over ``frames`` frames (a static camera track: zero camera motion). Its
  ``to_world`` (Mitsuba's convention, looking down +Z) becomes the track's USD-convention pose by the
  same 180° turn about Y that :meth:`CameraTrack.mitsuba_to_world` undoes; its horizontal field of
  view (``x_fov``), near/far clip, and for ``thinlens`` the aperture radius and focus distance are
  kept. An ``orthographic`` sensor keeps its ``to_world`` scale, which sets the width of the view
  (2 units before scaling, Mitsuba's convention); the track's ``projection`` says so and its
  ``fov_x_deg`` is 0. The image size is the dataset's ``--width``/``--height``, not the file's film:
  with another aspect ratio the vertical framing differs from the file's own render (the horizontal
  field of view, or width, is kept).
* ``auto_camera`` (``--auto-camera``) replaces the sensor, or stands in for a missing one, by the
  orbit USD stages get (:mod:`~denoisebench.generator.contract.orbit`: same lens, distance,
  elevation, start azimuth and 2° per frame) around Mitsuba's bounding box of the loaded scene
  (``scene.bbox()``: every shape, emitting ones included, as USD's bounds include mesh lights).
  Mitsuba scenes have no up axis: +Y is up (the convention of Mitsuba's and Bitterli's scenes), the
  azimuth is measured from +X toward +Z. The file's sensor type and its lens are then not used.
* Effects inferred from the loaded plugins: a ``thinlens`` sensor with a positive aperture →
  ``depth_of_field``; an emitter on a shape → ``area_lights``; an environment emitter
  (``envmap``, ``constant``) → ``environment``; BSDF lobes (Mitsuba's ``BSDFFlags``): glossy →
  ``glossy``, delta → ``specular``, any transmission → ``transmission``; a bitmap texture in a
  BSDF → ``textures``. Effects decide the render plan exactly as for USD stages.
* Transport: the file's integrator is replaced by denoisebench's path tracer; its restriction
  (:mod:`~denoisebench.generator.mitsuba_xml_structure`, Notes) becomes the scene's ``max_depth``
  (plan source ``"stage"``), and an integrator type that is neither a path-space nor a direct one
  gets one warning: full transport is rendered.
* Refusals are one-line :class:`~denoisebench.errors.UserInputError` (exit 2): a missing file, a scene
  Mitsuba will not load, no or an unsupported sensor, no emitter, no shape (and the file's own, see
  :mod:`~denoisebench.generator.mitsuba_xml_structure`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.orbit import orbit
from denoisebench.generator.contract.scene_parts import MitsubaXmlSource
from denoisebench.generator.contract.translated_scene import TranslatedScene
from denoisebench.generator.mitsuba_xml_structure import (
    DIRECT_INTEGRATORS,
    PATH_INTEGRATORS,
    one_line,
    read_structure,
    search_folders,
    searching,
)
from denoisebench.mitsuba_runtime import load_mitsuba

SENSORS = {"PerspectiveCamera": "perspective", "ThinLensCamera": "thinlens", "OrthographicCamera": "orthographic"}
# Mitsuba to_world (looks down +Z, +X left) <-> USD camera pose (looks down -Z): a 180° turn about Y.
_MITSUBA_TO_USD_CAMERA = np.diag([-1.0, 1.0, -1.0, 1.0])


def _param(params, key: str, default: float | None = None) -> float | None:
    if key not in params:
        return default
    value = params[key]
    try:
        return float(value[0]) if hasattr(value, "__len__") else float(value)
    except TypeError:
        return float(value)


def camera_track(mi, sensor, frames: int, path: Path) -> CameraTrack:
    """The static :class:`CameraTrack` of Mitsuba ``sensor`` over ``frames`` frames."""
    kind = sensor.class_name()
    if kind not in SENSORS:
        raise UserInputError(f"{path}: sensor {kind} is not supported (use perspective, thinlens or orthographic)")
    params = mi.traverse(sensor)
    to_world = np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4)
    pose = to_world @ _MITSUBA_TO_USD_CAMERA
    aperture = _param(params, "aperture_radius", 0.0) if kind == "ThinLensCamera" else 0.0
    orthographic = kind == "OrthographicCamera"
    return CameraTrack(
        poses=np.repeat(pose[None], max(1, int(frames)), axis=0),
        fov_x_deg=0.0 if orthographic else _param(params, "x_fov"),
        projection="orthographic" if orthographic else "perspective",
        aperture_radius=aperture,
        focus_distance=_param(params, "focus_distance", 1.0),
        near_clip=_param(params, "near_clip", 0.01),
        far_clip=_param(params, "far_clip", 1.0e4),
        prim_path=f"sensor:{SENSORS[kind]}",
    )


#: ``CameraTrack.prim_path`` of the ``auto_camera`` orbit.
AUTO_CAMERA = "auto_camera:orbit"


def auto_camera_track(scene, frames: int, path: Path) -> CameraTrack:
    """The ``--auto-camera`` orbit (module Notes) around the loaded scene's bounding box."""
    box = scene.bbox()
    low, high = np.array(box.min, dtype=np.float64), np.array(box.max, dtype=np.float64)
    if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high)) and np.all(high >= low)):
        raise UserInputError(f"{path}: --auto-camera: the scene has no bounded geometry to frame")
    track = orbit(low, high, frames)  # Y up, azimuth from +X toward +Z (orbit's defaults)
    return CameraTrack(
        poses=track.poses,
        fov_x_deg=track.fov_x_deg,
        near_clip=track.near_clip,
        far_clip=track.far_clip,
        prim_path=AUTO_CAMERA,
    )


def infer_effects(mi, scene, camera: CameraTrack) -> tuple[str, ...]:
    """Effects read off the loaded scene's plugins (see the module Notes)."""
    found = set()
    if camera.has_depth_of_field:
        found.add("depth_of_field")
    for emitter in scene.emitters():
        if emitter.is_environment():
            found.add("environment")
        if mi.has_flag(emitter.flags(), mi.EmitterFlags.Surface):
            found.add("area_lights")
    flags = mi.BSDFFlags
    for shape in scene.shapes():
        bsdf = shape.bsdf()
        if bsdf is None:
            continue
        bits = bsdf.flags()
        if mi.has_flag(bits, flags.Glossy):
            found.add("glossy")
        if mi.has_flag(bits, flags.Delta):
            found.add("specular")
        if mi.has_flag(bits, flags.Transmission):
            found.add("transmission")
        if any(key.endswith(".data") for key in mi.traverse(bsdf).keys()):
            found.add("textures")
    bound = [m for shape in scene.shapes() for m in (shape.interior_medium(), shape.exterior_medium())]
    bound += [sensor.get_medium() for sensor in scene.sensors()]
    if any(medium is not None for medium in bound):
        found.add("media")  # participating media: the volumetric tracer renders the scene
    return tuple(sorted(found))


def load_mitsuba_xml(
    path: str | Path,
    frames: int = 8,
    auto_camera: bool = False,
    defines: dict[str, str] | None = None,
    search_paths=(),
    confined: bool = False,
) -> tuple[TranslatedScene, object]:
    """``(TranslatedScene, mi.Scene)`` of a Mitsuba XML file; UserInputError (one line) on bad input.

    ``frames``: the camera track's length; ``auto_camera``: the orbit instead of the file's sensor;
    ``defines``: the scene's parameters (``--define NAME=VALUE``; :func:`~denoisebench.generator.mitsuba_xml_structure.parse_defines`);
    ``search_paths``: more folders to find its files in (``--mitsuba-path``, Mitsuba's ``-a``);
    ``confined``: the file is a dataset's copy, whose files must lie in its folder (:func:`read_structure`).

    The TranslatedScene has no shape records of its own (its ``mitsuba_xml`` names the file): render
    the returned ``mi.Scene`` with its ``camera``. Its ``max_depth`` is the scene's own transport
    restriction (module Notes), and ``mitsuba_xml.transport_origin`` says which integrator asked for
    it ("" when none did).
    """

    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"{path}: no such Mitsuba XML file")
    structure = read_structure(path, defines, search_paths, confined=confined)
    mi = load_mitsuba()
    try:
        with searching(mi, search_folders(search_paths)):
            scene = mi.load_file(str(path.resolve()), **structure.parameters)
    except Exception as error:
        raise UserInputError(f"{path}: Mitsuba cannot load the scene ({one_line(error)})") from None
    if not scene.sensors() and not auto_camera:
        raise UserInputError(f"{path}: the scene has no sensor (camera); give --auto-camera to frame it")
    if not scene.emitters():
        raise UserInputError(f"{path}: the scene has no emitter (light)")
    if not scene.shapes():
        raise UserInputError(f"{path}: nothing renderable: the scene has no shape")
    warnings = []
    if len(scene.sensors()) > 1 and not auto_camera:
        warnings.append(f"{path.name}: {len(scene.sensors())} sensors; the first is the camera")
    warnings.extend(f"{path.name}: {note}" for note in structure.notes)
    if structure.integrator not in (None, *PATH_INTEGRATORS, *DIRECT_INTEGRATORS):
        warnings.append(
            f"{path.name}: integrator {structure.integrator!r} is replaced by denoisebench's path tracer "
            "(complete transport)"
        )
    if auto_camera:
        camera = auto_camera_track(scene, frames, path)
    else:
        camera = camera_track(mi, scene.sensors()[0], frames, path)
    translated = TranslatedScene(
        camera=camera,
        mitsuba_xml=MitsubaXmlSource(path=str(path), transport_origin=structure.transport_origin),
        effects_inferred=infer_effects(mi, scene, camera),
        warnings=warnings,
        source=str(path),
        family="mitsuba_xml",
        max_depth=structure.max_depth,
    )
    return translated, scene
