"""Mitsuba 3 XML scene files as a scene source: ``generate-dataset --mitsuba scene.xml`` (alias ``--xml``).

The file is loaded by Mitsuba itself (``mi.load_file``: its meshes, textures and ``<default>``
parameters resolve relative to the file), and rendered by the same feature renderer as a
translated USD stage (:func:`~denoisebench.generator.render.frame.render_frame`), which takes a
``mi.Scene``, a :class:`CameraTrack` and a :class:`RenderPlan`. What this module adds is the
camera track and the effects, read off the loaded scene, plus the checks a scene file must pass.

Notes
-----
* Camera: the scene's first sensor (``perspective`` or ``thinlens``; others are refused), held still
  over ``frames`` frames (a static camera track: zero camera motion). Its ``to_world`` (Mitsuba's
  convention, looking down +Z) becomes the track's USD-convention pose by the same 180° turn about
  Y that :meth:`CameraTrack.mitsuba_to_world` undoes; its horizontal field of view (``x_fov``),
  near/far clip, and for ``thinlens`` the aperture radius and focus distance are kept. The image
  size is the dataset's ``--width``/``--height``, not the file's film: with another aspect ratio
  the vertical framing differs from the file's own render (the horizontal field of view is kept).
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
* Transport: the file's integrator is replaced by denoisebench's path tracer (Mitsuba's ``path``
  estimator with features). A ``path`` (or ``volpath``) integrator's ``max_depth`` other than −1 is
  the scene's own depth restriction (recorded like a stage's ``maxDepth``); any other integrator
  type gets one warning. Participating media (``<medium>``) cannot be rendered: refused.
* Files: every ``filename`` the scene names, and every file it ``<include>``s (read too, for their
  own files, integrator and media), must lie inside the XML file's folder (they are copied into
  the dataset at the same relative paths, as for USD); anything else is refused, one line.
* Refusals are one-line :class:`~denoisebench.errors.UserInputError` (exit 2): a missing file,
  malformed XML, a root other than ``<scene>``, a scene Mitsuba will not load, no or an unsupported
  sensor, no emitter, media.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.generator.contract.camera_track import CameraTrack
from denoisebench.generator.contract.orbit import orbit
from denoisebench.generator.contract.translated_scene import TranslatedScene
from denoisebench.mitsuba_runtime import load_mitsuba

XML_NAME = "scene.xml"
SENSORS = {"PerspectiveCamera": "perspective", "ThinLensCamera": "thinlens"}
PATH_INTEGRATORS = ("path", "volpath")
# Mitsuba to_world (looks down +Z, +X left) <-> USD camera pose (looks down -Z): a 180° turn about Y.
_MITSUBA_TO_USD_CAMERA = np.diag([-1.0, 1.0, -1.0, 1.0])
_VARIABLE = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")


@dataclass
class XmlStructure:
    """What the file says before Mitsuba loads it (parsed with ElementTree)."""

    integrator: str | None = None
    max_depth: int | None = None  # None: unbounded (-1) or not given
    files: list[str] = field(default_factory=list)  # every "filename" value, as written
    has_media: bool = False


def _short(error: BaseException) -> str:
    return " ".join(str(error).split())[:200]


def _parse(path: Path, shown: Path) -> ElementTree.Element:
    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError as error:
        raise UserInputError(f"{shown}: not well-formed XML ({_short(error)})") from None
    except OSError as error:
        raise UserInputError(f"{shown}: cannot read ({error.strerror or error})") from None
    if root.tag != "scene":
        raise UserInputError(f"{shown}: the root element is <{root.tag}>, not a Mitsuba <scene>")
    return root


def read_structure(path: Path) -> XmlStructure:
    """Parse ``path`` and the files it ``<include>``s (UserInputError when one is not a Mitsuba
    ``<scene>`` document). Included files' paths, like every ``filename``, are relative to ``path``'s
    folder, as Mitsuba resolves them."""
    roots, queue, seen = [], [path], set()
    while queue:
        current = queue.pop(0)
        key = current.resolve()
        if key in seen:
            continue
        seen.add(key)
        root = _parse(current, path if current == path else current)
        roots.append(root)
        queue.extend(path.parent / i.get("filename") for i in root.iter("include") if i.get("filename"))
    defaults = {d.get("name"): d.get("value", "") for root in roots for d in root.iter("default")}

    def resolve(text: str | None) -> str:
        return _VARIABLE.sub(lambda m: defaults.get(m.group(1), m.group(0)), text or "")

    out = XmlStructure()
    out.has_media = any(True for root in roots for _ in root.iter("medium"))
    for root in roots:
        for element in root.iter():
            if element.tag == "include" and element.get("filename"):
                out.files.append(resolve(element.get("filename")))
            elif element.get("name") == "filename" and element.get("value"):
                out.files.append(resolve(element.get("value")))
    integrator = next((root.find("integrator") for root in roots if root.find("integrator") is not None), None)
    while integrator is not None and integrator.find("integrator") is not None:  # e.g. aov/moment wrappers
        integrator = integrator.find("integrator")
    if integrator is not None:
        out.integrator = resolve(integrator.get("type"))
        for item in integrator.findall("integer"):
            if item.get("name") == "max_depth":
                try:
                    depth = int(resolve(item.get("value")))
                except ValueError:
                    raise UserInputError(
                        f"{path}: integrator max_depth {item.get('value')!r} is not an integer"
                    ) from None
                out.max_depth = None if depth < 0 else depth
    return out


def dependencies(path: Path, structure: XmlStructure | None = None) -> list[tuple[Path, str]]:
    """``(absolute file, path relative to the XML's folder)`` of every file the scene names.

    UserInputError for a file outside the folder, a missing one, or one named like the scene file.
    """
    structure = structure or read_structure(path)
    root = path.resolve().parent
    out = []
    for name in structure.files:
        absolute = (root / name).resolve()
        try:
            relative = absolute.relative_to(root).as_posix()
        except ValueError:
            raise UserInputError(
                f"{path}: names {name!r}, outside the scene's folder; move it under {root} to generate from it"
            ) from None
        if not absolute.is_file():
            raise UserInputError(f"{path}: names {name!r}, which does not exist ({absolute})")
        if relative == XML_NAME:
            raise UserInputError(f"{path}: a file it names is called {XML_NAME}, which the dataset reserves")
        out.append((absolute, relative))
    return sorted(set(out), key=lambda item: item[1])


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
        raise UserInputError(f"{path}: sensor {kind} is not supported (use perspective or thinlens)")
    params = mi.traverse(sensor)
    to_world = np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4)
    pose = to_world @ _MITSUBA_TO_USD_CAMERA
    aperture = _param(params, "aperture_radius", 0.0) if kind == "ThinLensCamera" else 0.0
    return CameraTrack(
        poses=np.repeat(pose[None], max(1, int(frames)), axis=0),
        fov_x_deg=_param(params, "x_fov"),
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
    return tuple(sorted(found))


def load_mitsuba_xml(path: str | Path, frames: int = 8, auto_camera: bool = False) -> tuple[TranslatedScene, object]:
    """``(TranslatedScene, mi.Scene)`` of a Mitsuba XML file; UserInputError (one line) on bad input.

    ``frames``: the camera track's length; ``auto_camera``: the orbit instead of the file's sensor.

    The TranslatedScene has no shapes of its own (``scene_dict["mitsuba_xml"]`` names the file):
    render the returned ``mi.Scene`` with its ``camera``.
    """

    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"{path}: no such Mitsuba XML file")
    structure = read_structure(path)
    if structure.has_media:
        raise UserInputError(f"{path}: participating media (<medium>) are not supported by denoisebench's renderer")
    dependencies(path, structure)
    mi = load_mitsuba()
    try:
        scene = mi.load_file(str(path.resolve()))
    except Exception as error:
        raise UserInputError(f"{path}: Mitsuba cannot load the scene ({_short(error)})") from None
    if not scene.sensors() and not auto_camera:
        raise UserInputError(f"{path}: the scene has no sensor (camera); give --auto-camera to frame it")
    if not scene.emitters():
        raise UserInputError(f"{path}: the scene has no emitter (light)")
    if not scene.shapes():
        raise UserInputError(f"{path}: nothing renderable: the scene has no shape")
    warnings = []
    if len(scene.sensors()) > 1 and not auto_camera:
        warnings.append(f"{path.name}: {len(scene.sensors())} sensors; the first is the camera")
    if structure.integrator not in (None, *PATH_INTEGRATORS):
        warnings.append(
            f"{path.name}: integrator {structure.integrator!r} is replaced by denoisebench's path tracer "
            "(complete transport)"
        )
    if auto_camera:
        camera = auto_camera_track(scene, frames, path)
    else:
        camera = camera_track(mi, scene.sensors()[0], frames, path)
    translated = TranslatedScene(
        scene_dict={"bsdfs": {}, "shapes": [], "emitters": [], "mitsuba_xml": str(path)},
        camera=camera,
        effects_inferred=infer_effects(mi, scene, camera),
        warnings=warnings,
        source=str(path),
        family="mitsuba_xml",
        max_depth=structure.max_depth if structure.integrator in PATH_INTEGRATORS else None,
    )
    return translated, scene
