"""The scenes of a dataset: names, seeds, and the stage files under ``OUT/<scene>/``.

A family scene is authored straight into its folder (``scene.usda`` + ``textures/``); a user's
own USD file is copied there with the files it depends on (:func:`copy_user_stage`). Either way
the folder then holds everything needed to render the scene, listed by :class:`SceneSpec`'s
``stage_files``, so a Ray worker on another machine can rebuild it from those bytes alone.

Names and seeds are deterministic:

* family scenes are ``<family>_<scene seed:03d>``, with scene seeds ``seed, seed+1, ...`` (the
  same stage ``denoisebench scenes make FAMILY --seed S`` writes);
* a user's stage is ``usd_<file stem>`` (other characters become ``_``; a second file with the
  same stem gets ``_2``, in argument order), a Mitsuba XML scene ``xml_<file stem>``: copied as
  ``scene.xml`` with every file it names, wherever Mitsuba finds them (rewritten only where the copy
  must be: generator/mitsuba_xml.py ``portable_files``; byte for byte otherwise), plus
  ``camera.json`` (its camera's frame count, and ``"auto_camera": true`` for the ``--auto-camera``
  orbit), :func:`copy_xml_scene`;
* every scene renders with its own ``render_seed``, a hash of the dataset seed and the scene name,
  so no two scenes share random numbers and a scene's pixels do not depend on which others exist.

Notes:
    ``--camera``/``--auto-camera``/``--default-light`` (:data:`StageOptions`) are written into the
    copied ``scene.usda`` (the camera path as ``customLayerData["denoisebench"]["camera"]``, the
    auto camera and default lights as prims, see usd/additions.py), so the dataset's stage is
    exactly what was rendered. A ``.usdz`` package is copied whole as ``package.usdz`` and
    ``scene.usda`` sublayers it, repeating its root layer's upAxis, metersPerUnit, time codes and
    default prim (sublayers do not carry those).

    A stage whose dependencies (textures, sublayers, references, payloads) all lie inside its own
    folder is copied as it is: each file at the same relative path, byte for byte, so the stage's
    relative asset paths still resolve. A stage laid out as production assets are (usd-wg's Mini Car
    Kit: ``ambulance/asset/ambulanceFullAsset.usda`` references ``../geo/ambulanceGeo.usd`` and
    ``../../../wheels/...``) has dependencies outside its folder: then every dependency is copied to
    ``files/<its path below the dependencies' common folder>`` (:data:`FILES_DIR`), which keeps their
    relative paths to one another, and only the root layer's asset paths (and any absolute path in a
    dependency layer) are rewritten to the copies (:func:`relocated_layer_text`). Either way the copy
    is checked to resolve only inside ``OUT/<scene>`` (datasets are untrusted files: a copied stage
    never reaches out of its folder). A binary root layer (``.usdc``/``.usd``) is written out as text
    ``scene.usda`` by USD's own ``Sdf.Layer.Export``.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path

from denoisebench.dataset import layout
from denoisebench.dataset.atomic import atomic_write_bytes
from denoisebench.errors import UserInputError
from denoisebench.generator.mitsuba_xml import load_mitsuba_xml
from denoisebench.generator.mitsuba_xml_structure import XML_NAME, portable_files
from denoisebench.generator.usd.materialx import document_files
from denoisebench.generator.usd.stage import FRAME_TIMES_KEY, own_time_codes
from denoisebench.generator.usd.translate import apply_additions, translate_usd
from denoisebench.scenes.effects import METADATA_KEY

# Lazy imports: pxr is imported only where a stage is authored or copied, so that Ray workers
# and Mitsuba XML runs do not load USD.

USD_SUFFIXES = (".usda", ".usdc", ".usd", ".usdz")
PACKAGE_NAME = "package.usdz"
#: Where a stage's dependencies go when some lie outside its folder (``files/<path below their common folder>``).
FILES_DIR = "files"


def stage_options(
    camera: str | None = None,
    auto_camera: bool = False,
    default_light: bool = False,
    frames: int = 8,
    *,
    time_range: tuple[float, float] | None = None,
    stage_frames: int | None = None,
) -> dict:
    """What ``generate`` applies to every ``--usd`` stage: the keywords of ``translate_usd``, and
    (only when given) the choice among the stage's own time codes (:data:`SELECTION_KEYS`,
    :func:`select_frame_times`)."""
    options = {
        "camera_path": camera,
        "auto_camera": bool(auto_camera),
        "default_light": bool(default_light),
        "frames": int(frames),
    }
    if time_range is not None:
        options["time_range"] = (float(time_range[0]), float(time_range[1]))
    if stage_frames is not None:
        options["stage_frames"] = int(stage_frames)
    return options


#: stage_options keys that choose among a stage's own time codes (not ``translate_usd`` keywords).
SELECTION_KEYS = ("time_range", "stage_frames")
#: A stage with more time codes than this, rendered whole, gets a note (``--frames``, ``--time-range``).
LONG_STAGE_FRAMES = 300


def select_frame_times(
    times: list[float], stage_frames: int | None = None, time_range: tuple[float, float] | None = None
) -> list[float]:
    """The time codes to render of a stage's own ``times``: those within ``time_range`` (inclusive),
    then ``stage_frames`` of them evenly spaced, first and last included (all where there are no more).

    UserInputError where the window holds none of them.
    """
    chosen = list(times)
    if time_range is not None:
        start, end = time_range
        chosen = [t for t in chosen if start <= t <= end]
        if not chosen:
            raise UserInputError(
                f"--time-range {start:g}:{end:g} holds none of the stage's time codes "
                f"({times[0]:g}..{times[-1]:g}, {len(times)} of them)"
            )
    if stage_frames is not None and len(chosen) > stage_frames:
        if stage_frames == 1:
            return [chosen[0]]
        step = (len(chosen) - 1) / (stage_frames - 1)
        chosen = [chosen[round(k * step)] for k in range(stage_frames)]
    return chosen


def _translate_keywords(options: dict | None) -> dict:
    return {k: v for k, v in (options or {}).items() if k not in SELECTION_KEYS}


@dataclass(frozen=True)
class SceneSpec:
    """One scene to render (plain data: picklable, sent to executors).

    Attributes:
        name: the scene's folder and manifest name.
        family: the scene family, or ``"usd"`` for a user's stage.
        seed: the authoring seed (0 for a user's stage).
        source: the family name, or the user's USD file as given.
        stage_dir: absolute ``OUT/<scene>``.
        stage_files: paths relative to ``stage_dir`` of the stage (first, ``scene.usda``) and of
            every file it depends on.
        render_seed: the seed of every render of this scene.
    """

    name: str
    family: str
    seed: int
    source: str
    stage_dir: str
    stage_files: tuple[str, ...]
    render_seed: int

    @property
    def usd_path(self) -> Path:
        """The scene file: ``scene.usda``, or ``scene.xml`` for a Mitsuba XML scene (``stage_files[0]``)."""
        return Path(self.stage_dir) / self.stage_files[0]


def render_seed(dataset_seed: int, scene: str) -> int:
    """32-bit render seed of ``scene``: BLAKE2b of the dataset seed and the scene name."""
    data = struct.pack("<q", int(dataset_seed)) + scene.encode("utf-8")
    return int.from_bytes(hashlib.blake2b(data, digest_size=4).digest(), "little")


def family_scene_names(families: list[str], count: int, seed: int) -> list[tuple[str, int, str]]:
    """``(family, scene seed, name)`` of ``count`` scenes of each family."""
    return [(family, seed + i, f"{family}_{seed + i:03d}") for family in families for i in range(count)]


def user_scene_names(paths: list[str], taken: set[str], prefix: str = "usd_") -> list[str]:
    """``usd_<stem>`` (``prefix``) names for the user's files, unique among themselves and ``taken``."""
    names = []
    used = set(taken)
    for path in paths:
        base = prefix + (re.sub(r"[^A-Za-z0-9._-]", "_", Path(path).stem) or "stage")
        name, k = base, 2
        while name in used:
            name, k = f"{base}_{k}", k + 1
        used.add(name)
        names.append(name)
    return names


def stage_digest(stage_dir: str | Path, files: tuple[str, ...]) -> str:
    """sha256 over the stage files' relative paths and contents (what a render depends on)."""
    digest = hashlib.sha256()
    for relative in files:
        digest.update(relative.encode("utf-8") + b"\0")
        digest.update(hashlib.sha256((Path(stage_dir) / relative).read_bytes()).digest())
    return digest.hexdigest()


def read_stage_files(spec: SceneSpec) -> dict[str, bytes]:
    """The bytes of every stage file of ``spec`` (what a remote worker gets)."""
    return {relative: (Path(spec.stage_dir) / relative).read_bytes() for relative in spec.stage_files}


def _relative_files(folder: Path, paths) -> tuple[str, ...]:
    return tuple(sorted({Path(p).resolve().relative_to(folder.resolve()).as_posix() for p in paths}))


def author_family_scene(family, scene_dir: Path, seed: int, frames: int, width: int, height: int) -> tuple[str, ...]:
    """Author ``family`` into ``scene_dir``; return its stage files (``scene.usda`` first)."""
    from pxr import UsdUtils

    stage = family.author(scene_dir, seed=seed, frames=frames, width=width, height=height)
    _, assets, _ = UsdUtils.ComputeAllDependencies(str(stage))
    others = tuple(f for f in _relative_files(scene_dir, assets) if f != layout.SCENE_USD)
    return (layout.SCENE_USD,) + others


def user_stage_dependencies(path: Path) -> list[tuple[Path, str]]:
    """``(absolute file, path relative to the copy's folder)`` of every file the stage needs.

    Inside the stage's folder: the same relative path. When any lies outside it: every one under
    ``files/`` at its path below the common folder of the stage and its dependencies (the module's
    Notes). A dependency named ``scene.usda`` at the folder's top is a UserInputError (the dataset
    reserves it). Unresolvable asset paths are left to the translator (it warns about missing textures).
    """
    from pxr import UsdUtils

    if path.suffix.lower() == ".usdz":
        return []  # a package is self-contained; it is copied whole
    root = path.resolve().parent
    # USD's own messages about unresolved assets are caught here: the translator reports them once per prim.
    quiet = UsdUtils.CoalescingDiagnosticDelegate()
    layers, assets, _unresolved = UsdUtils.ComputeAllDependencies(str(path))
    quiet.TakeCoalescedDiagnostics()
    del quiet
    # usd-core cannot open .mtlx documents: their textures are found by reading them.
    assets = list(assets) + [f for a in assets if str(a).lower().endswith(".mtlx") for f in document_files(a)]
    files = sorted({Path(f).resolve() for f in [layer.realPath for layer in layers[1:]] + list(assets)})
    if all(f.is_relative_to(root) for f in files):
        out = [(f, f.relative_to(root).as_posix()) for f in files]
    else:
        base = Path(os.path.commonpath([root, *files]))
        out = [(f, f"{FILES_DIR}/{f.relative_to(base).as_posix()}") for f in files]
    for absolute, relative in out:
        if relative == layout.SCENE_USD:
            raise UserInputError(
                f"{path}: a dependency is named {layout.SCENE_USD}, which the dataset reserves for the stage"
            )
    return sorted(set(out), key=lambda item: item[1])


def _rewritten(layer, origin: Path, new_place: str, mapping: dict[Path, str], only_absolute: bool) -> bool:
    """Rewrite ``layer``'s asset paths (in memory) that resolve, from ``origin`` (its file), to a copied
    file: to that copy's path relative to ``new_place`` (the layer's own path in the copy); with
    ``only_absolute`` just the absolute ones. True when any path changed."""
    from pxr import UsdUtils

    changed = []

    def move(asset: str) -> str:
        if not asset or "://" in asset or (only_absolute and not os.path.isabs(asset)):
            return asset
        target = Path(os.path.normpath(asset if os.path.isabs(asset) else origin.parent / asset))
        try:
            target = target.resolve()
        except OSError:
            return asset
        if target not in mapping:
            return asset
        relative = os.path.relpath(mapping[target], os.path.dirname(new_place) or ".")
        moved = "./" + Path(relative).as_posix() if not relative.startswith("..") else Path(relative).as_posix()
        if moved != asset:
            changed.append(asset)
        return moved

    UsdUtils.ModifyAssetPaths(layer, move)
    return bool(changed)


def relocated_layer_text(
    path: Path, new_place: str, mapping: dict[Path, str], only_absolute: bool = False
) -> str | None:
    """The text of ``path``'s layer with its asset paths pointing at the copies ``mapping`` names
    (absolute file → path in the copy), as it will lie at ``new_place``; None when nothing changes.
    The user's layer is not modified (an anonymous copy is)."""
    from pxr import Sdf

    source = Sdf.Layer.FindOrOpen(str(path))
    if source is None:
        raise UserInputError(f"{path}: cannot open USD layer")
    copy = Sdf.Layer.CreateAnonymous(".usda")
    copy.TransferContent(source)
    return copy.ExportToString() if _rewritten(copy, Path(path), new_place, mapping, only_absolute) else None


def check_confined(scene_dir: Path) -> None:
    """UserInputError unless every file the copied ``scene_dir/scene.usda`` depends on lies inside ``scene_dir``."""
    from pxr import Sdf, UsdUtils

    stage_path = scene_dir / layout.SCENE_USD
    for relative in (stage_path,):
        cached = Sdf.Layer.Find(str(relative))
        if cached is not None:
            cached.Reload(force=True)
    quiet = UsdUtils.CoalescingDiagnosticDelegate()
    layers, assets, _ = UsdUtils.ComputeAllDependencies(str(stage_path))
    quiet.TakeCoalescedDiagnostics()
    del quiet
    folder = scene_dir.resolve()
    for f in [layer.realPath for layer in layers] + list(assets):
        if f and not Path(f).resolve().is_relative_to(folder):
            raise UserInputError(f"{stage_path}: the copy still depends on {f}, outside its folder {folder}")


def _package_wrapper(path: Path) -> str:
    """Text of a ``scene.usda`` that sublayers ``package.usdz`` and repeats its stage metadata."""
    from pxr import Sdf

    source = Sdf.Layer.FindOrOpen(str(path))
    if source is None:
        raise UserInputError(f"{path}: cannot open USD package")
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.subLayerPaths.append(f"./{PACKAGE_NAME}")
    for key in (
        "upAxis",
        "metersPerUnit",
        "startTimeCode",
        "endTimeCode",
        "timeCodesPerSecond",
        "framesPerSecond",
        "defaultPrim",
        "customLayerData",
    ):
        if source.pseudoRoot.HasInfo(key):
            layer.pseudoRoot.SetInfo(key, source.pseudoRoot.GetInfo(key))
    return layer.ExportToString()


def copy_user_stage(path: str | Path, scene_dir: Path, options: dict | None = None) -> tuple[str, ...]:
    """Copy a user's stage to ``scene_dir/scene.usda`` (text) with its dependencies; return the files.

    ``options``: :func:`stage_options` to write into the copy (camera choice, auto camera, lights)."""
    from pxr import Sdf

    path = Path(path)
    dependencies = user_stage_dependencies(path)
    scene_dir.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".usdz":
        atomic_write_bytes(scene_dir / PACKAGE_NAME, path.read_bytes())
        dependencies_out: tuple[str, ...] = (PACKAGE_NAME,)
        text = _package_wrapper(path)
    else:
        layer = Sdf.Layer.FindOrOpen(str(path))
        if layer is None:
            raise UserInputError(f"{path}: cannot open USD stage")
        # ExportToString keeps the authored (relative) asset paths; the bytes go through our atomic write.
        text = layer.ExportToString()
        mapping = {absolute: relative for absolute, relative in dependencies}
        relocated = any(relative.startswith(FILES_DIR + "/") for relative in mapping.values())
        # dependencies outside the stage's folder: the root layer points at their copies (else only
        # an absolute path to a copied file is rewritten; a stage without one keeps its bytes)
        text = relocated_layer_text(path.resolve(), layout.SCENE_USD, mapping, only_absolute=not relocated) or text
        for absolute, relative in dependencies:
            data = absolute.read_bytes()
            if absolute.suffix.lower() in (".usda", ".usd", ".usdc"):
                rewritten = relocated_layer_text(absolute, relative, mapping, only_absolute=True)
                data = data if rewritten is None else rewritten.encode("utf-8")
            atomic_write_bytes(scene_dir / relative, data)
        dependencies_out = tuple(relative for _, relative in dependencies)
    atomic_write_bytes(scene_dir / layout.SCENE_USD, text.encode("utf-8"))
    if options and any(options.get(k) for k in ("camera_path", "auto_camera", "default_light", *SELECTION_KEYS)):
        atomic_write_bytes(
            scene_dir / layout.SCENE_USD, _with_additions(scene_dir / layout.SCENE_USD, options).encode("utf-8")
        )
    if path.suffix.lower() != ".usdz":
        check_confined(scene_dir)
    return (layout.SCENE_USD,) + dependencies_out


def _with_additions(stage_path: Path, options: dict) -> str:
    """The copied root layer's text with the camera choice, auto camera and default lights authored into it."""
    from pxr import Sdf, Usd, UsdUtils, Vt

    cached = Sdf.Layer.Find(str(stage_path))
    if cached is not None:
        cached.Reload(force=True)  # USD keeps open layers by path: read the bytes just written
    # USD's own messages (e.g. the .mtlx references usd-core cannot open) are the translator's to report.
    quiet = UsdUtils.CoalescingDiagnosticDelegate()
    stage = Usd.Stage.Open(str(stage_path))
    quiet.TakeCoalescedDiagnostics()
    del quiet
    layer = stage.GetRootLayer()
    stage.SetEditTarget(layer)
    camera = apply_additions(
        stage,
        options.get("camera_path"),
        bool(options.get("auto_camera")),
        bool(options.get("default_light")),
        int(options.get("frames", 8)),
    )
    data = dict(layer.customLayerData)
    meta = dict(data.get(METADATA_KEY, {}) or {})
    if camera:
        meta["camera"] = camera
    if any(options.get(k) is not None for k in SELECTION_KEYS):
        own = own_time_codes(stage)
        chosen = select_frame_times(own, options.get("stage_frames"), options.get("time_range"))
        if chosen != own:  # recorded in the copy (the dataset's stage is what was rendered) and the manifest
            meta[FRAME_TIMES_KEY] = Vt.DoubleArray(chosen)  # typed: USD stores no mixed lists
            record = {"stageFirst": float(own[0]), "stageLast": float(own[-1]), "stageCount": len(own)}
            if options.get("time_range"):
                record["timeRange"] = Vt.DoubleArray(list(options["time_range"]))
            if options.get("stage_frames"):
                record["frames"] = int(options["stage_frames"])
            meta[SELECTION_RECORD_KEY] = record
    if meta:
        data[METADATA_KEY] = meta
        layer.customLayerData = data
    return layer.ExportToString()


#: Key of the record of a time-code choice in the copy's denoisebench metadata (also in the manifest).
SELECTION_RECORD_KEY = "frameSelection"


def frame_selection(stage_path: str | Path) -> dict | None:
    """The time codes a dataset's copy of a user stage renders of its own, and why
    (``{"stage_time_codes": [first, last, count], "time_range": ..., "frames": ..., "times": [...]}``),
    or None where it renders them all."""
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(stage_path))
    meta = (dict(layer.customLayerData).get(METADATA_KEY, {}) or {}) if layer is not None else {}
    if meta.get(FRAME_TIMES_KEY) is None or not len(meta[FRAME_TIMES_KEY]):
        return None
    record = dict(meta.get(SELECTION_RECORD_KEY, {}) or {})
    selection = {
        "stage_time_codes": [float(record.get("stageFirst", 0.0)), float(record.get("stageLast", 0.0))],
        "stage_frames": int(record.get("stageCount", 0)),
    }
    if "timeRange" in record:
        selection["time_range"] = [float(t) for t in record["timeRange"]]
    if "frames" in record:
        selection["frames"] = int(record["frames"])
    return {**selection, "times": [float(t) for t in meta[FRAME_TIMES_KEY]]}


def check_user_stage(path: str | Path, options: dict | None = None):
    """Open, check and translate a user's stage before anything is written; return the translation.

    A missing or malformed file, a stage without a camera (unless ``options`` give one), without a
    light (unless ``default_light``), or with nothing renderable is a UserInputError (one line
    naming the file).
    """
    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"{path}: no such USD file")
    if path.suffix.lower() not in USD_SUFFIXES:
        raise UserInputError(f"{path}: expected a {'/'.join(USD_SUFFIXES)} file")
    translated = translate_usd(path, **_translate_keywords(options), strict=True)
    user_stage_dependencies(path)
    if options and any(options.get(k) is not None for k in SELECTION_KEYS):
        select_frame_times(stage_time_codes(path), options.get("stage_frames"), options.get("time_range"))
    return translated


def stage_time_codes(path: str | Path) -> list[float]:
    """The stage's own time codes (:func:`~denoisebench.generator.usd.stage.own_time_codes`)."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise UserInputError(f"{path}: cannot open USD stage")
    return own_time_codes(stage)


# --------------------------------------------------------------------------- Mitsuba XML scenes

#: Beside a copied ``scene.xml``: the frame count of its static camera track (the XML has none).
XML_CAMERA = "camera.json"


def load_scene_file(path: str | Path):
    """``(TranslatedScene, mi.Scene or None)`` of a dataset's scene file: ``scene.usda`` translated by
    USD (None: ``build_mitsuba_scene`` makes the Mitsuba scene), ``scene.xml`` loaded by Mitsuba,
    confined to its folder (a dataset's files are untrusted: no ``<path>``, no file outside it)."""
    path = Path(path)
    if path.suffix.lower() == ".xml":
        return load_mitsuba_xml(path, **xml_camera(path), confined=True)

    return translate_usd(path), None


def translate_scene_file(path: str | Path):
    """The TranslatedScene of a dataset's scene file (:func:`load_scene_file`)."""
    return load_scene_file(path)[0]


def xml_camera(path: Path) -> dict:
    """Keywords of ``load_mitsuba_xml`` from a copied XML scene's ``camera.json``: ``frames`` (1 without
    one) and ``auto_camera`` (False unless it says so; files written before it existed lack it)."""
    sidecar = Path(path).parent / XML_CAMERA
    record = json.loads(sidecar.read_text()) if sidecar.is_file() else {"frames": 1}
    return {"frames": int(record["frames"]), "auto_camera": bool(record.get("auto_camera", False))}


def check_xml_scene(
    path: str | Path, frames: int, auto_camera: bool = False, defines: dict | None = None, search_paths=()
):
    """Load and check a Mitsuba XML scene before anything is written (UserInputError, one line);
    ``defines``: its parameters (``--define``); ``search_paths``: ``--mitsuba-path`` folders."""
    path = Path(path)
    if path.suffix.lower() != ".xml":
        raise UserInputError(f"{path}: expected a Mitsuba .xml scene file")
    translated, _ = load_mitsuba_xml(
        path, frames=frames, auto_camera=auto_camera, defines=defines, search_paths=search_paths
    )
    return translated


def copy_xml_scene(
    path: str | Path,
    scene_dir: Path,
    frames: int,
    auto_camera: bool = False,
    defines: dict | None = None,
    search_paths=(),
) -> tuple[str, ...]:
    """Copy a Mitsuba XML scene to ``scene_dir/scene.xml`` with every file it names (``portable_files``:
    loadable on another machine with no options, ``defines`` written into it), and ``camera.json``
    (its camera: frame count, auto camera or not); return the stage files, ``scene.xml`` first.

    Without ``auto_camera`` the sidecar holds what it held before the option existed (same bytes, so
    datasets made then keep their stage digests)."""
    path = Path(path)
    scene_dir.mkdir(parents=True, exist_ok=True)
    copy = portable_files(path, defines, search_paths)
    files = []
    for relative, data in sorted(copy.items()):
        if relative != XML_NAME:
            atomic_write_bytes(scene_dir / relative, data)
            files.append(relative)
    camera = {"frames": int(frames), "camera": "the first sensor of scene.xml, static"}
    if auto_camera:
        camera = {
            "frames": int(frames),
            "camera": "orbit around the scene's bounding box (generator/contract/orbit.py)",
            "auto_camera": True,
        }
    atomic_write_bytes(scene_dir / XML_CAMERA, (json.dumps(camera, sort_keys=True) + "\n").encode())
    atomic_write_bytes(scene_dir / XML_NAME, copy[XML_NAME])
    return (XML_NAME, XML_CAMERA, *files)
