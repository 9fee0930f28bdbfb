"""Resolve a plugin spec (built-in name, entry point, ``MODULE:ATTR``, ``file.py:ATTR``) to a constructed object.

The denoisers' and the samplers' registries (``denoisers/registry.py``, ``sampling/registry.py``) find
their plugins by one grammar, so the resolution lives here once, parametrised by a :class:`PluginKind`
(the noun and error classes of messages, the entry-point group, the built-ins, the method that marks a
ready instance, the arguments of that method, and the protocol check). Spec grammar, first match wins:

``NAME``
    a built-in of ``kind.builtins`` (``name -> ("module:attr", default options)``, imported on first
    use), else an entry point of the group ``kind.group``. Built-ins win over an entry point of the
    same name.
``MODULE:ATTR`` / ``path/to/file.py:ATTR``
    anything importable; ``ATTR`` may be dotted (``pkg.mod:Outer.Inner``). With more than one colon
    the last one splits, so a file path holding a colon still names its file.

The object found may be

* a class or a factory (called with the options);
* a ready instance (an object with a callable ``kind.method``; no options allowed);
* a plain function of the method's arguments (``def denoise(frame)``, ``def sample(budget, rounds)``):
  it becomes the method of a :class:`FunctionPlugin`, with the options bound as keywords, and the
  function's own attributes (``denoise.needs = {"color", "albedo"}``, ``name``, ``temporal``) read as
  the instance's. A function whose required arguments, less the options, are none is a factory; any
  other count is refused with a message that says what to write.

Notes
-----
* Every failure is one line: ``kind.unknown_error`` where the name is nowhere (the message lists the
  known names), ``kind.option_error`` for an option the constructor does not take (so that a typo is
  not silently ignored), ``kind.load_error`` where the plugin was found but failed to import or
  construct. All are :class:`~denoisebench.errors.UserInputError`, so the CLI exits 2.
* A ``file.py`` plugin is imported under a module name made from its resolved path, so two files of
  the same name do not replace each other in ``sys.modules``. Its folder is put first on ``sys.path``
  (as ``python file.py`` does), so that it can import the modules beside it; in the sandbox that folder
  is readable (:func:`denoisebench.plugins.sandbox.readable_paths`) and nothing else of the host is.
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.machinery
import importlib.metadata
import importlib.util
import inspect
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from denoisebench.errors import UserInputError, one_line


@dataclass(frozen=True)
class PluginKind:
    """What differs between the denoisers' and the samplers' plugins (module docstring).

    ``where_prefix`` precedes the origin in a load error (``cannot import {where_prefix}built-in 'x'``);
    ``file_noun`` names a missing ``file.py`` (``no such plugin file``); ``ready_options_error`` is
    raised when options are given to a ready instance (a ``TypeError`` is reported as a load error).
    ``arguments`` are those of ``method`` (a plain function taking exactly these is the method itself).
    """

    noun: str
    group: str
    builtins: Mapping[str, tuple[str, dict[str, Any]]]
    method: str
    validate: Callable[[Any, str], Any]
    unknown_error: type[UserInputError]
    load_error: type[UserInputError]
    option_error: type[UserInputError]
    ready_options_error: type[Exception]
    file_noun: str
    where_prefix: str = ""
    arguments: tuple[str, ...] = ()


class FunctionPlugin:
    """A plugin made of a plain function: the function (options bound) is its ``kind.method``.

    ``name``, ``needs``, ``temporal`` and ``trained_scenes`` are the function's own attributes where it
    has them (``denoise.needs = {"color", "albedo"}``); the protocol's defaults otherwise.
    """

    ATTRIBUTES = ("name", "needs", "temporal", "trained_scenes")

    def __init__(self, method: str, function: Callable, options: Mapping[str, Any]):
        setattr(self, method, functools.partial(function, **options) if options else function)
        self._function = function
        for attribute in self.ATTRIBUTES:
            if hasattr(function, attribute):
                setattr(self, attribute, getattr(function, attribute))

    def __repr__(self) -> str:
        return f"<plugin function {getattr(self._function, '__qualname__', self._function)!r}>"


def entry_points(group: str) -> dict[str, importlib.metadata.EntryPoint]:
    """The installed entry points of ``group`` by name (the first of a name wins)."""
    found: dict[str, importlib.metadata.EntryPoint] = {}
    for entry_point in importlib.metadata.entry_points(group=group):
        found.setdefault(entry_point.name, entry_point)
    return found


def available(kind: PluginKind, points: Mapping[str, importlib.metadata.EntryPoint]) -> dict[str, str]:
    """Every name a spec may use, mapped to where it comes from (nothing is imported)."""
    names = {name: f"built-in ({target})" for name, (target, _) in kind.builtins.items()}
    for name, entry_point in sorted(points.items()):
        if name not in names:
            dist = getattr(entry_point, "dist", None)
            origin = f"{dist.name} {dist.version}" if dist is not None else entry_point.value
            names[name] = f"entry point ({origin}: {entry_point.value})"
    return names


def import_target(kind: PluginKind, target: str) -> Any:
    """The object ``MODULE:ATTR`` or ``file.py:ATTR`` names (``kind.unknown_error`` where nothing has it)."""
    module_name, attr_path = _target(target)
    if not module_name or not attr_path:
        raise kind.unknown_error(f"bad {kind.noun} spec {target!r}: expected NAME or MODULE:ATTR")
    if module_name.endswith(".py"):
        path = Path(module_name)
        if not path.is_file():
            raise kind.unknown_error(f"no such {kind.file_noun} {module_name!r}")
        unique = f"denoisebench_{kind.noun}_{abs(hash(str(path.resolve())))}"
        folder = str(path.resolve().parent)
        if folder not in sys.path:
            sys.path.insert(0, folder)  # its own modules import as they do under `python file.py`
        spec = importlib.util.spec_from_file_location(unique, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[unique] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            sys.modules.pop(unique, None)
            raise
    else:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as error:
            if error.name == module_name or module_name.startswith(f"{error.name}."):
                raise kind.unknown_error(f"no module named {module_name!r} (from spec {target!r})") from None
            raise
    obj: Any = module
    for part in attr_path.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise kind.unknown_error(f"module {module_name!r} has no attribute {attr_path!r}") from None
    return obj


def check_options(
    kind: PluginKind, obj: Any, spec: str, options: Mapping[str, Any], skip: tuple[str, ...] = ()
) -> None:
    """``kind.option_error`` when ``obj`` (class, factory or plain function) takes no keyword named like an option.

    A constructor with ``**kwargs``, or one whose signature cannot be read, accepts anything; ``skip``
    are arguments no option may give (a plain function's ``frame``).
    """
    if not options or not callable(obj):
        return
    try:
        parameters = list(inspect.signature(obj).parameters.values())
    except (TypeError, ValueError):
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return
    known = [p.name for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and p.name not in skip]
    unknown = [key for key in options if key not in known]
    if unknown:
        raise kind.option_error(
            f"{kind.noun} {spec!r} has no option {', '.join(map(repr, unknown))}; "
            f"it takes {', '.join(known) or 'no options'}"
        )


def _required(obj: Any, options: Mapping[str, Any]) -> list[str] | None:
    """The positional arguments ``obj`` (a function) requires that ``options`` do not give; None where unreadable."""
    try:
        parameters = inspect.signature(obj).parameters.values()
    except (TypeError, ValueError):
        return None
    positional = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return [p.name for p in parameters if p.kind in positional and p.default is p.empty and p.name not in options]


def _function_plugin(kind: PluginKind, obj: Any, spec: str, options: Mapping[str, Any]) -> Any | None:
    """A :class:`FunctionPlugin` where ``obj`` is a plain function of ``kind.arguments``; None for a factory.

    TypeError (what to write instead) for a function that is neither.
    """
    if not kind.arguments or isinstance(obj, type) or not callable(obj):
        return None
    required = _required(obj, options)
    if not required:
        return None
    if len(required) == len(kind.arguments):
        check_options(kind, obj, spec, options, skip=tuple(required))
        return FunctionPlugin(kind.method, obj, options)
    wanted = ", ".join(kind.arguments)
    raise TypeError(
        f"{spec!r} requires the arguments ({', '.join(required)}): a {kind.noun} plugin is a function "
        f"{kind.method}({wanted}), a class whose instances have {kind.method}({wanted}), or a factory "
        "that takes only options"
    )


def instantiate(kind: PluginKind, obj: Any, spec: str, options: Mapping[str, Any]) -> Any:
    """``obj`` constructed with ``options`` (a ready instance as it is), named ``spec`` where it has no name."""
    ready = not isinstance(obj, type) and callable(getattr(obj, kind.method, None))
    function = None if ready else _function_plugin(kind, obj, spec, options)
    if ready:
        if options:
            raise kind.ready_options_error(f"{spec!r} is a ready instance; it takes no options ({', '.join(options)})")
        instance = obj
    elif function is not None:
        instance = function
    elif callable(obj):
        check_options(kind, obj, spec, options)
        instance = obj(**options)
    else:
        raise TypeError(f"{spec!r} is a {type(obj).__name__}, not a {kind.noun} class, factory or instance")
    if getattr(instance, "name", None) is None:
        try:
            instance.name = spec
        except Exception:  # noqa: BLE001 - an object that refuses attributes is named by the protocol's fallback
            pass
    kind.validate(instance, spec)  # TypeError for an object that does not speak the protocol
    return instance


def _target(spec: str) -> tuple[str, str]:
    """``(module, attr)`` of a ``MODULE:ATTR`` / ``file.py:ATTR`` spec (the last colon splits where there are more)."""
    module_name, _, attr_path = spec.rpartition(":") if spec.count(":") > 1 else spec.partition(":")
    return module_name, attr_path


def check_spec(kind: PluginKind, spec: str, points: Callable[[], Mapping[str, importlib.metadata.EntryPoint]]) -> None:
    """``kind.unknown_error`` where ``spec`` names nothing, found without importing anything.

    A bare name must be a built-in or an entry point; a ``file.py:ATTR`` spec's file must exist; a
    ``MODULE:ATTR`` spec is left to :func:`load`. So a command refuses a misspelled name before it
    writes anything.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise kind.unknown_error(f"empty {kind.noun} spec")
    spec = spec.strip()
    if spec in kind.builtins:
        return
    if ":" in spec:
        module_name, attr_path = _target(spec)
        if not module_name or not attr_path:
            raise kind.unknown_error(f"bad {kind.noun} spec {spec!r}: expected NAME or MODULE:ATTR")
        if module_name.endswith(".py") and not Path(module_name).is_file():
            raise kind.unknown_error(f"no such {kind.file_noun} {module_name!r}")
        return
    found = points()
    if spec not in found:
        raise kind.unknown_error(_unknown(kind, spec, found))


def _unknown(kind: PluginKind, spec: str, found: Mapping[str, importlib.metadata.EntryPoint]) -> str:
    known = ", ".join(available(kind, found))
    return f"unknown {kind.noun} {spec!r}; known: {known} (or give MODULE:ATTR)"


def load(
    kind: PluginKind,
    spec: str,
    options: Mapping[str, Any],
    points: Callable[[], Mapping[str, importlib.metadata.EntryPoint]],
) -> Any:
    """The plugin ``spec`` names, constructed with ``options`` (module docstring).

    ``points()`` gives the entry points, asked only for a bare name that is no built-in.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise kind.unknown_error(f"empty {kind.noun} spec")
    spec = spec.strip()
    if spec in kind.builtins:
        target, defaults = kind.builtins[spec]
        kwargs, where = {**defaults, **options}, f"built-in {spec!r}"
        loader = lambda: import_target(kind, target)  # noqa: E731
    elif ":" in spec:
        kwargs, where = dict(options), repr(spec)
        loader = lambda: import_target(kind, spec)  # noqa: E731
    else:
        found = points()
        entry_point = found.get(spec)
        if entry_point is None:
            raise kind.unknown_error(_unknown(kind, spec, found))
        kwargs, where = dict(options), f"entry point {spec!r} ({entry_point.value})"
        loader = entry_point.load
    where = f"{kind.where_prefix}{where}"
    try:
        obj = loader()
    except UserInputError:
        raise
    except Exception as error:  # noqa: BLE001 - a broken plugin is a one-line load error
        raise kind.load_error(f"cannot import {where}: {one_line(error)}") from error
    try:
        return instantiate(kind, obj, spec, kwargs)
    except UserInputError:
        raise
    except Exception as error:  # noqa: BLE001
        raise kind.load_error(f"cannot construct {where}: {one_line(error)}") from error


# --------------------------------------------------------------------------------------------------
# code identity


def _module_files(module_name: str) -> list[Path]:
    """The source files of ``module_name``'s top-level package (or of the module alone), found on
    ``sys.path`` without importing anything: a plugin's code is run only where it is isolated."""
    top, *rest = module_name.split(".")
    spec = importlib.machinery.PathFinder.find_spec(top)
    if spec is None or spec.origin in (None, "built-in", "frozen"):
        return []
    if spec.submodule_search_locations:  # a package: every .py file under it
        files: list[Path] = []
        for location in spec.submodule_search_locations:
            files.extend(sorted(p for p in Path(location).rglob("*.py") if "__pycache__" not in p.parts))
        return files
    return [Path(spec.origin)] if not rest else []


def _files_digest(files: list[Path], base: str = "") -> str:
    digest = hashlib.sha256(base.encode())
    for path in files:
        digest.update(f"\0{path.name}\0".encode())
        try:
            digest.update(path.read_bytes())
        except OSError:
            digest.update(b"<unreadable>")
    return digest.hexdigest()[:16]


def code_identity(
    kind: PluginKind, spec: str, points: Callable[[], Mapping[str, importlib.metadata.EntryPoint]]
) -> str | None:
    """A short hash of the code ``spec`` runs, or None for a built-in (its code is the package's,
    recorded with a run as the denoisebench version) and for what cannot be found.

    ``file.py:ATTR``: the file's bytes. ``MODULE:ATTR``: the files of its top-level package (or the
    module's file). An entry point: its distribution's name and version and the files of the package
    its target lies in (an editable install included). Found without importing: hashing a plugin
    must not run it outside its sandbox. A change in any of these files is a new identity, so a
    benchmark run that includes it measures the plugin again instead of resuming.
    """
    spec = spec.strip()
    if spec in kind.builtins:
        return None
    base = ""
    if ":" in spec:
        module_name, _ = _target(spec)
    else:
        entry_point = points().get(spec)
        if entry_point is None:
            return None
        module_name = entry_point.value.partition(":")[0].strip()
        dist = getattr(entry_point, "dist", None)
        base = f"{dist.name} {dist.version}" if dist is not None else entry_point.value
    if module_name == "denoisebench" or module_name.startswith("denoisebench."):
        return None  # the package's own code, as a built-in's
    if module_name.endswith(".py"):
        files = [Path(module_name)] if Path(module_name).is_file() else []
    else:
        files = _module_files(module_name)
    if not files and not base:
        return None
    return _files_digest(files, base)
