"""Scene list files: third-party test sets named by source, never vendored.

A scene list is a TOML file (read with :mod:`tomllib`) that names scenes by where they lie under a
root the user gives (``generate-dataset --scene-list FILE --root DIR``)::

    name = "mitsuba-data: documentation scenes"
    repository = "https://github.com/mitsuba-renderer/mitsuba-data"   # what to clone as --root
    licence = "see the repository"                                      # default of every scene
    camera = "orbit"               # default: "orbit" (the --auto-camera orbit) or "own"
    default_light = false          # light USD stages that have none (--default-light)

    [[scene]]
    source = "mitsuba"             # or "usd"
    path = "docs/scenes/bsdf_roughconductor_copper.xml"   # relative to --root
    defines = { spp = "4" }        # Mitsuba $parameters (optional)
    camera = "own"                 # optional, per scene: "orbit", "own", or a USD camera prim path
    licence = "..."                # optional, per scene
    url = "https://..."            # optional: where to get this scene

:func:`read_scene_list` checks the file (one-line UserInputError naming what is wrong) and
:func:`resolve_scene_list` finds every scene under the root: a missing file gets one line naming the
repository to clone. :func:`request_fields` turns the list into ``GenerateRequest`` fields, so the
scenes render as ``--usd``/``--mitsuba`` scenes of any other dataset.

Pitfalls: camera, lights and ``--define``s are options of a whole ``generate`` run, so one list's
scenes share one camera choice (mixing "orbit" with "own" is refused: split the list), and two
scenes may not give one ``$parameter`` two values. Paths may not leave the root (``..``, absolute).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from denoisebench.errors import UserInputError

SOURCES = ("usd", "mitsuba")
CAMERAS = ("orbit", "own")
#: Shipped lists: ``denoisebench/scenes/lists/<name>.toml``.
SHIPPED = Path(__file__).resolve().parent.parent / "scenes" / "lists"


@dataclass(frozen=True, kw_only=True)
class ListedScene:
    """One scene of a list: its source kind, path relative to the root, camera, defines, licence, url."""

    source: str
    path: str
    camera: str
    defines: tuple[tuple[str, str], ...] = ()
    licence: str = ""
    url: str = ""


@dataclass(frozen=True, kw_only=True)
class SceneList:
    """A checked scene list: its name, repository (what ``--root`` is a clone of), scenes."""

    file: str
    name: str
    repository: str
    licence: str
    default_light: bool
    scenes: tuple[ListedScene, ...]


def shipped_list(name: str) -> Path:
    """A shipped list by name (``mitsuba_docs``) or the path as given when it is a file."""
    path = Path(name)
    if path.is_file():
        return path
    candidate = SHIPPED / f"{name.removesuffix('.toml')}.toml"
    return candidate if candidate.is_file() else path


def _text(table: dict, key: str, where: str, default: str | None = None) -> str:
    value = table.get(key, default)
    if not isinstance(value, str) or (default is None and not value):
        raise UserInputError(f"{where}: {key!r} must be a non-empty string")
    return value


def _relative(path: str, where: str) -> str:
    posix = PurePosixPath(path)
    if posix.is_absolute() or ".." in posix.parts or "\\" in path:
        raise UserInputError(f"{where}: path {path!r} must be relative to --root and stay under it")
    return posix.as_posix()


def read_scene_list(file: str | Path) -> SceneList:
    """Parse and check a scene list (UserInputError, one line, on anything malformed)."""
    file = shipped_list(str(file))
    if not file.is_file():
        raise UserInputError(f"{file}: no such scene list")
    try:
        data = tomllib.loads(file.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise UserInputError(f"{file}: not a TOML scene list ({str(error).splitlines()[0]})") from None
    repository = _text(data, "repository", str(file))
    licence = _text(data, "licence", str(file), "")
    camera = _text(data, "camera", str(file), "orbit")
    default_light = data.get("default_light", False)
    if not isinstance(default_light, bool):
        raise UserInputError(f"{file}: 'default_light' must be true or false")
    entries = data.get("scene")
    if not isinstance(entries, list) or not entries:
        raise UserInputError(f"{file}: no [[scene]] entries")
    scenes = []
    for i, entry in enumerate(entries, 1):
        where = f"{file}: scene {i}"
        if not isinstance(entry, dict):
            raise UserInputError(f"{where}: must be a table")
        source = _text(entry, "source", where)
        if source not in SOURCES:
            raise UserInputError(f"{where}: source {source!r} is not one of {', '.join(SOURCES)}")
        scene_camera = _text(entry, "camera", where, camera)
        if scene_camera not in CAMERAS and not (source == "usd" and scene_camera.startswith("/")):
            raise UserInputError(f"{where}: camera {scene_camera!r}: orbit, own, or (usd) a camera prim path")
        defines = entry.get("defines", {})
        if not isinstance(defines, dict) or (defines and source != "mitsuba"):
            raise UserInputError(f"{where}: 'defines' is a table of Mitsuba $parameters (mitsuba scenes only)")
        scenes.append(
            ListedScene(
                source=source,
                path=_relative(_text(entry, "path", where), where),
                camera=scene_camera,
                defines=tuple(sorted((str(k), str(v)) for k, v in defines.items())),
                licence=_text(entry, "licence", where, licence),
                url=_text(entry, "url", where, ""),
            )
        )
    return SceneList(
        file=str(file),
        name=_text(data, "name", str(file), file.stem),
        repository=repository,
        licence=licence,
        default_light=default_light,
        scenes=tuple(scenes),
    )


def resolve_scene_list(scene_list: SceneList, root: str | Path) -> list[tuple[ListedScene, Path]]:
    """Every scene with its file under ``root``; a missing root or file is one line naming the clone."""
    root = Path(root)
    if not root.is_dir():
        raise UserInputError(
            f"--root {root}: no such folder; clone {scene_list.repository} there for {Path(scene_list.file).name}"
        )
    out = []
    for scene in scene_list.scenes:
        path = root / scene.path
        if not path.is_file():
            raise UserInputError(
                f"{path}: missing; --root must be a clone of {scene_list.repository} "
                f"(git clone {scene_list.repository})"
            )
        out.append((scene, path))
    return out


def request_fields(scene_list: SceneList, root: str | Path) -> dict:
    """``GenerateRequest`` fields of the list's scenes: ``usd``, ``xml``, ``auto_camera``, ``camera``,
    ``default_light``, ``defines`` (see the module's pitfalls for what one list's scenes must share)."""
    resolved = resolve_scene_list(scene_list, root)
    cameras = sorted({scene.camera for scene, _ in resolved})
    if len(cameras) > 1:
        raise UserInputError(
            f"{scene_list.file}: scenes ask for cameras {', '.join(cameras)}; one generate run has one camera "
            "choice: split the list"
        )
    defines: dict[str, str] = {}
    for scene, _ in resolved:
        for key, value in scene.defines:
            if defines.setdefault(key, value) != value:
                raise UserInputError(f"{scene_list.file}: ${key} is given two values ({defines[key]!r}, {value!r})")
    camera = cameras[0]
    return {
        "usd": tuple(str(path) for scene, path in resolved if scene.source == "usd"),
        "xml": tuple(str(path) for scene, path in resolved if scene.source == "mitsuba"),
        "auto_camera": camera == "orbit",
        "camera": camera if camera.startswith("/") else None,
        "default_light": scene_list.default_light,
        "defines": tuple(sorted(defines.items())),
    }
