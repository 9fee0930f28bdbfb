"""A Mitsuba 3 XML scene file's structure as Mitsuba's own parser reads it, and the portable copy a
dataset keeps of it.

:func:`read_structure` parses the file (its includes, parameters and ``<path>`` directives), finds every
file it names as Mitsuba's file resolver does and reads its integrator's transport restriction
(:class:`XmlStructure`); :func:`portable_files` is the dataset's copy. Loading the scene, its camera and
its effects is :mod:`~denoisebench.generator.mitsuba_xml`.

Notes
-----
* Parsing: Mitsuba's own parser (``mi.parser.parse_file``) reads the file, its ``<include>``\\ s,
  ``<default>`` parameters and ``<path>`` directives; ``defines`` (``--define NAME=VALUE``, Mitsuba's
  ``-D``) set parameters and win over ``<default>``. An undefined parameter is a one-line error that
  names it and the flag, except those in :data:`AUTO_PARAMETERS` (``$spp`` and the film size
  ``$res``/``$resx``/``$resy``): denoisebench sets its own sample counts and image size, so an
  undefined one gets a placeholder value. A ``--define`` the scene never uses is refused (as
  Mitsuba's ``-D`` is).
* Files: every ``filename`` the scene names (an element ``<string name="filename" ...>`` or a
  ``filename`` attribute: includes, spectra) is found as Mitsuba finds it: its file resolver searches
  the ``<path>`` folders (relative to the scene file, the last one first), then the scene file's
  folder, then ``search_paths`` (``--mitsuba-path DIR``, Mitsuba's ``-a``: for scenes written to be
  loaded with one, such as Mitsuba's ``sensor_orthographic.xml``), then Mitsuba's defaults (the
  working directory, Mitsuba's own data). The user's scene may
  name files anywhere; a name that resolves to no file is a one-line error. Pitfall: an included
  file's names resolve like the main file's (relative to the main file's folder, not the include's),
  as Mitsuba does.
* The dataset copy (:func:`portable_files`): ``scene.xml`` plus every file, each at its name as
  written when that name is relative and stays inside the folder (so the copy resolves it from its
  own folder), else at ``files/<basename>`` (numbered on a clash). The copy differs from the user's
  file only where it must: ``<path>`` directives removed, moved names rewritten, and the parameters
  that were defined (``--define`` and the placeholders) written as ``<default>``\\ s, so the copy
  loads on another machine with no options and renders the same scene. A file that needs none of
  that is copied byte for byte. The user's own file is never changed.
* Confinement protects datasets (untrusted files), not the user's own input: a dataset's copy is
  loaded ``confined`` (no ``<path>``, no include or file outside its folder; one-line refusal).
* Transport: the file's integrator is replaced by denoisebench's path tracer (Mitsuba's ``path``
  estimator with features), but its restriction is honoured. Wrappers that hold one integrator
  (``moment``, ``aov``, ...) are read through. A path-space integrator of :data:`PATH_INTEGRATORS`
  with a ``max_depth`` other than −1 restricts the depth; ``direct`` (:data:`DIRECT_INTEGRATORS`)
  is direct illumination only: emission plus one bounce of light, the expectation of ``path`` at
  ``max_depth`` 2, which is what is rendered. Either is recorded like a stage's ``maxDepth`` (plan
  source ``"stage"``, with :attr:`XmlStructure.transport_origin` saying which integrator asked);
  ``--max-depth`` still wins. Any other integrator type gets one warning: full transport is
  rendered. Pitfalls: ``direct``'s sample counts are not honoured (they change noise, not the
  expectation); ``hide_emitters`` (any integrator) is not honoured either, with one warning, since
  it changes the image. Participating media (``<medium>``
  bound to shapes or the sensor) are rendered by the volumetric tracer (render/volpath.py) and
  add the ``media`` effect.
* Refusals are one-line :class:`~denoisebench.errors.UserInputError` (exit 2): malformed XML, a root
  other than ``<scene>``, an undefined parameter, an unused ``--define``, a named file that does not
  exist, a confined copy that reaches outside its folder.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ElementTree
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from denoisebench.errors import UserInputError
from denoisebench.mitsuba_runtime import load_mitsuba

XML_NAME = "scene.xml"
#: Names of the dataset's scene folder that a copied file may not take.
RESERVED_NAMES = (XML_NAME, "camera.json")
#: Folder of the copy for files whose names leave the scene's folder (``../x.ply``, absolute names).
MOVED_FOLDER = "files"
#: Integrators that estimate the full path-space image (up to their ``max_depth``), as ``path`` does.
PATH_INTEGRATORS = ("path", "volpath", "volpathmis", "prb", "prb_basic", "prbvolpath", "ptracer")
#: Integrators of direct illumination only: rendered as ``path`` at ``max_depth`` 2.
DIRECT_INTEGRATORS = ("direct", "direct_projective")
DIRECT_MAX_DEPTH = 2
#: Parameters denoisebench sets itself (sample count, film size): undefined ones get these placeholders.
AUTO_PARAMETERS = {"spp": "16", "res": "128", "resx": "128", "resy": "128"}
_VARIABLE = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_UNDEFINED = re.compile(r"undefined parameter:? *\$([A-Za-z_][A-Za-z0-9_]*)")
_UNUSED = re.compile(r"unused parameters?:?\s*-?\s*\$([A-Za-z_][A-Za-z0-9_]*)", re.IGNORECASE)


def parse_defines(items) -> dict[str, str]:
    """``--define NAME=VALUE`` items (repeatable) as a dict; UserInputError (one line) on a malformed one."""
    out: dict[str, str] = {}
    for item in items or ():
        name, equals, value = str(item).partition("=")
        name = name.strip()
        if not equals or not _NAME.match(name):
            raise UserInputError(f"--define expects NAME=VALUE, like --define spp=16 (got {item!r})")
        out[name] = value
    return out


@dataclass
class XmlStructure:
    """What Mitsuba's parser makes of the file (with its includes, parameters and ``<path>``\\ s)."""

    integrator: str | None = None  # the innermost integrator's type (through wrappers)
    wrappers: tuple[str, ...] = ()  # wrapper integrators read through, outermost first
    max_depth: int | None = None  # the scene's own restriction (None: unbounded / full transport)
    transport_origin: str = ""  # which integrator asked for max_depth, e.g. "integrator 'direct' in 'moment'"
    notes: list[str] = field(default_factory=list)  # integrator settings that are not honoured (become warnings)
    files: list[str] = field(default_factory=list)  # every file name as written (parameters substituted)
    resolved: dict[str, Path] = field(default_factory=dict)  # name as written -> the file Mitsuba loads
    documents: list[Path] = field(default_factory=list)  # the XML files read: the scene first, then includes
    search_paths: list[Path] = field(default_factory=list)  # resolver folders, searched in this order
    parameters: dict[str, str] = field(default_factory=dict)  # passed to Mitsuba: defines + placeholders
    placeholders: tuple[str, ...] = ()  # names in parameters that are AUTO_PARAMETERS placeholders
    has_media: bool = False


def one_line(error: BaseException) -> str:
    return " ".join(str(error).split())[:200]


def _parse(path: Path, shown: Path) -> ElementTree.Element:
    try:
        parser = ElementTree.XMLParser(target=ElementTree.TreeBuilder(insert_comments=True))
        root = ElementTree.parse(path, parser=parser).getroot()
    except ElementTree.ParseError as error:
        raise UserInputError(f"{shown}: not well-formed XML ({one_line(error)})") from None
    except OSError as error:
        raise UserInputError(f"{shown}: cannot read ({error.strerror or error})") from None
    if root.tag != "scene":
        raise UserInputError(f"{shown}: the root element is <{root.tag}>, not a Mitsuba <scene>")
    return root


@contextmanager
def searching(mi, folders):
    """Mitsuba's thread file resolver with ``folders`` in front (Mitsuba's ``-a``), restored afterwards,
    also of what the parser prepends to it (``<path>`` directives)."""
    resolver = mi.file_resolver()
    saved = [str(p) for p in resolver]
    try:
        for folder in reversed(list(folders)):
            resolver.prepend(str(folder))
        yield resolver
    finally:
        resolver.clear()
        for folder in saved:
            resolver.append(folder)


def search_folders(folders, shown: str = "--mitsuba-path") -> list[Path]:
    """``--mitsuba-path`` folders as absolute paths; UserInputError (one line) for one that is no folder."""
    out = []
    for folder in folders or ():
        if not Path(folder).is_dir():
            raise UserInputError(f"{shown} {folder}: no such folder")
        out.append(Path(folder).resolve())
    return out


def _mitsuba_parse(mi, path: Path, defines: dict[str, str], search: list[Path] = ()):
    """``(ParserState, parameters, placeholders, <path> folders)`` from Mitsuba's own parser.

    Mitsuba's ``parse_file`` prepends the ``<path>`` folders to the thread's file resolver and leaves
    them there; they are read off and the resolver is restored. ``search``: ``--mitsuba-path``
    folders, searched after the scene's own folder (as Mitsuba's ``-a``)."""
    parameters = dict(defines)
    placeholders: list[str] = []
    while True:
        try:
            with searching(mi, search) as resolver:
                before = len(resolver)
                state = mi.parser.parse_file(mi.parser.ParserConfig(mi.variant()), str(path), **parameters)
                now = [str(p) for p in resolver]
        except Exception as error:  # noqa: BLE001 - Mitsuba raises RuntimeError with its parser's message
            text = " ".join(str(error).split())
            undefined = _UNDEFINED.search(text)
            if undefined and undefined.group(1) in AUTO_PARAMETERS and undefined.group(1) not in parameters:
                parameters[undefined.group(1)] = AUTO_PARAMETERS[undefined.group(1)]
                placeholders.append(undefined.group(1))
                continue
            if undefined:
                name = undefined.group(1)
                raise UserInputError(
                    f"{path}: undefined parameter ${name} (no <default>); give --define {name}=VALUE"
                ) from None
            unused = _UNUSED.search(text)
            if unused:
                raise UserInputError(
                    f"{path}: --define {unused.group(1)}=...: the scene has no parameter ${unused.group(1)}"
                ) from None
            raise UserInputError(f"{path}: Mitsuba cannot parse the scene ({one_line(error)})") from None
        added = now[: max(0, len(now) - before)]
        return state, parameters, tuple(placeholders), [Path(p) for p in added]


def _integrator_chain(mi, state) -> list:
    """The scene's integrator nodes, outermost first, read through wrappers that hold integrators."""
    nodes = state.nodes
    root = nodes[0].props

    def children(props):
        out = []
        for key in props.keys():
            if props.type(key) == props.Type.ResolvedReference:
                node = nodes[props[key].index()]
                if node.type == mi.ObjectType.Integrator:
                    out.append(node)
        return out

    chain = []
    found = children(root)
    while found:
        chain.append(found[0])
        found = children(found[0].props)
    return chain


def _transport(structure: XmlStructure, chain, path: Path) -> None:
    if not chain:
        return
    names = [node.props.plugin_name() for node in chain]
    structure.integrator, structure.wrappers = names[-1], tuple(names[:-1])
    inner = chain[-1].props
    where = f"integrator {names[-1]!r}" + "".join(f" in {w!r}" for w in reversed(names[:-1]))
    if "hide_emitters" in inner.keys() and bool(inner["hide_emitters"]):
        structure.notes.append(f"{where}: hide_emitters is not honoured (emitters seen by the camera are rendered)")
    if names[-1] in DIRECT_INTEGRATORS:
        structure.max_depth, structure.transport_origin = DIRECT_MAX_DEPTH, f"{where}: direct illumination only"
    elif names[-1] in PATH_INTEGRATORS and "max_depth" in inner.keys():
        try:
            depth = int(inner["max_depth"])
        except (TypeError, ValueError):
            raise UserInputError(f"{path}: integrator max_depth {inner['max_depth']!r} is not an integer") from None
        if depth == 0:
            raise UserInputError(f"{path}: integrator max_depth 0 renders nothing (give >= 1, or -1 for unbounded)")
        if depth > 0:
            structure.max_depth, structure.transport_origin = depth, f"{where}: max_depth {depth}"


def _substitute(text: str | None, parameters: dict[str, str]) -> str:
    return _VARIABLE.sub(lambda m: parameters.get(m.group(1), m.group(0)), text or "")


def _defaults(roots) -> dict[str, str]:
    out: dict[str, str] = {}
    for root in roots:
        for item in root.iter("default"):
            out.setdefault(item.get("name"), item.get("value", ""))
    return out


def _file_elements(root):
    """``(element, attribute)`` of every file name in one document: ``<include filename>``, a
    ``filename`` attribute (spectra), ``<... name="filename" value>``."""
    for element in root.iter():
        if not isinstance(element.tag, str):
            continue  # comments
        if element.get("filename") is not None:
            yield element, "filename"
        elif element.get("name") == "filename" and element.get("value") is not None:
            yield element, "value"


def _resolve(mi, name: str, search_paths: list[Path]) -> Path | None:
    resolver = mi.FileResolver()
    resolver.clear()
    for folder in search_paths:
        resolver.append(str(folder))
    found = Path(str(resolver.resolve(name)))
    return found.resolve() if found.is_file() else None


def _outside(file: Path, folder: Path) -> bool:
    try:
        file.relative_to(folder)
    except ValueError:
        return True
    return False


def read_structure(
    path: Path, defines: dict[str, str] | None = None, search_paths=(), confined: bool = False
) -> XmlStructure:
    """Parse ``path`` with Mitsuba's parser (``defines``: ``--define`` parameters; ``search_paths``:
    ``--mitsuba-path`` folders, Mitsuba's ``-a``) and find every file it names as Mitsuba's file
    resolver does (module Notes); UserInputError (one line) on bad input.

    ``confined``: ``path`` is a dataset's copy (an untrusted file): it may have no ``<path>``
    directives and name no file outside its own folder (a portable copy never does).
    """
    path = Path(path)
    root = _parse(path, path)  # well-formed, a <scene>: the clear messages first
    folder = path.resolve().parent
    if confined:
        if search_paths or any(True for _ in root.iter("path")):
            raise UserInputError(f"{path}: a dataset's scene file has a <path> directive (its copy never does)")
        for include in root.iter("include"):
            name = include.get("filename") or ""
            if _kept_name(name) is None and "$" not in name:
                raise UserInputError(f"{path}: includes {name!r}, outside the dataset's scene folder")
    mi = load_mitsuba()
    search = search_folders(search_paths)
    state, parameters, placeholders, added = _mitsuba_parse(mi, path.resolve(), dict(defines or {}), search)
    defaults = [Path(str(p)) for p in mi.file_resolver()]
    out = XmlStructure(parameters=parameters, placeholders=placeholders)
    out.search_paths = [*added, folder, *search, *defaults]
    out.documents = [Path(str(f)).resolve() for f in state.files] or [path.resolve()]
    out.has_media = any(node.type == mi.ObjectType.Medium for node in state.nodes)
    _transport(out, _integrator_chain(mi, state), path)
    roots = [_parse(document, document) for document in out.documents]
    values = {**_defaults(roots), **parameters}
    for root in roots:
        for element, attribute in _file_elements(root):
            name = _substitute(element.get(attribute), values)
            if name in out.resolved:
                continue
            found = _resolve(mi, name, out.search_paths)
            if found is None:
                searched = ", ".join(str(p) for p in out.search_paths[: len(added) + 1 + len(search)])
                raise UserInputError(f"{path}: names {name!r}, which does not exist (searched {searched})")
            out.files.append(name)
            out.resolved[name] = found
    if confined:
        for file in [*out.documents, *out.resolved.values()]:
            if _outside(file, folder):
                raise UserInputError(f"{path}: names {file}, outside the dataset's scene folder")
    return out


def _kept_name(name: str) -> str | None:
    """``name`` as a path inside the copy's folder when it can stay as written, else None."""
    if not name or "\\" in name or name.startswith("/"):
        return None
    parts = PurePosixPath(name).parts
    if any(part in ("..", "") for part in parts) or ":" in parts[0]:
        return None
    kept = PurePosixPath(*[p for p in parts if p != "."]).as_posix()
    return None if kept in RESERVED_NAMES or kept == "." else kept


def copy_names(structure: XmlStructure) -> dict[Path, str]:
    """Where each file goes in the copy: absolute file -> path relative to the copy's folder."""
    out: dict[Path, str] = {structure.documents[0]: XML_NAME}
    taken = {XML_NAME, *RESERVED_NAMES}
    moved = []
    for name in structure.files:
        absolute = structure.resolved[name]
        if absolute in out:
            continue
        kept = _kept_name(name)
        if kept is None or kept in taken:
            moved.append(absolute)
            continue
        out[absolute] = kept
        taken.add(kept)
    for absolute in moved:
        if absolute in out:
            continue
        stem, suffix, k = Path(absolute.name).stem, Path(absolute.name).suffix, 1
        relative = f"{MOVED_FOLDER}/{absolute.name}"
        while relative in taken:
            k += 1
            relative = f"{MOVED_FOLDER}/{stem}_{k}{suffix}"
        out[absolute] = relative
        taken.add(relative)
    return out


def dependencies(
    path: Path, structure: XmlStructure | None = None, defines=None, search_paths=()
) -> list[tuple[Path, str]]:
    """``(absolute file, path relative to the copy's folder)`` of every file the scene names (the
    scene file itself excluded), sorted by the relative path (:func:`copy_names`)."""
    structure = structure or read_structure(path, defines, search_paths)
    names = copy_names(structure)
    return sorted(((a, r) for a, r in names.items() if r != XML_NAME), key=lambda item: item[1])


def _rewritten(root, structure: XmlStructure, names: dict[Path, str], values: dict[str, str], top: bool) -> bool:
    """Rewrite one document of the copy in place; True when anything changed."""
    changed = False
    for parent in list(root.iter()):
        for child in list(parent):
            if child.tag == "path":
                parent.remove(child)
                changed = True
    for element, attribute in _file_elements(root):
        name = _substitute(element.get(attribute), values)
        target = names[structure.resolved[name]]
        if target != name:
            element.set(attribute, target)
            changed = True
    if top and structure.parameters:
        existing = {item.get("name"): item for item in root.findall("default")}
        for k, (name, value) in enumerate(sorted(structure.parameters.items())):
            if name in existing:
                if existing[name].get("value") != value:
                    existing[name].set("value", value)
                    changed = True
            else:
                item = ElementTree.Element("default", {"name": name, "value": value})
                item.tail = "\n    "
                root.insert(k, item)
                changed = True
    return changed


def portable_files(path: Path, defines: dict[str, str] | None = None, search_paths=()) -> dict[str, bytes]:
    """The dataset copy of a scene: ``{path relative to the copy's folder: bytes}``, ``scene.xml``
    first (module Notes). XML documents are rewritten only where they must be; every other file is
    copied byte for byte. The copy needs none of ``defines`` and ``search_paths`` to load."""
    path = Path(path)
    structure = read_structure(path, defines, search_paths)
    names = copy_names(structure)
    documents = set(structure.documents)
    roots = {document: _parse(document, document) for document in structure.documents}
    values = {**_defaults(list(roots.values())), **structure.parameters}
    out: dict[str, bytes] = {}
    for absolute, relative in sorted(names.items(), key=lambda item: item[1] != XML_NAME):
        data = absolute.read_bytes()
        if absolute in documents:
            root = roots[absolute]
            if _rewritten(root, structure, names, values, top=relative == XML_NAME):
                data = ElementTree.tostring(root, encoding="unicode").encode("utf-8") + b"\n"
        out[relative] = data
    return out
