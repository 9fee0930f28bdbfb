"""Resolve a plugin spec (built-in name, entry point, ``MODULE:ATTR``, ``file.py:ATTR``) to a constructed object.

The denoisers' and the samplers' registries (``denoisers/registry.py``, ``sampling/registry.py``) find
their plugins by one grammar, so the resolution lives here once, parametrised by a :class:`PluginKind`
(the noun and error classes of messages, the entry-point group, the built-ins, the method that marks a
ready instance, and the protocol check). Spec grammar, first match wins:

``NAME``
    a built-in of ``kind.builtins`` (``name -> ("module:attr", default options)``, imported on first
    use), else an entry point of the group ``kind.group``. Built-ins win over an entry point of the
    same name.
``MODULE:ATTR`` / ``path/to/file.py:ATTR``
    anything importable; ``ATTR`` may be dotted (``pkg.mod:Outer.Inner``). With more than one colon
    the last one splits, so a file path holding a colon still names its file.

The object found may be a class or a factory (called with the options) or a ready instance (an object
with a callable ``kind.method``; no options allowed).

Notes
-----
* Every failure is one line: ``kind.unknown_error`` where the name is nowhere (the message lists the
  known names), ``kind.option_error`` for an option the constructor does not take (so that a typo is
  not silently ignored), ``kind.load_error`` where the plugin was found but failed to import or
  construct. All are :class:`~denoisebench.errors.UserInputError`, so the CLI exits 2.
* A ``file.py`` plugin is imported under a module name made from its resolved path, so two files of
  the same name do not replace each other in ``sys.modules``.
"""

from __future__ import annotations

import importlib
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
    module_name, _, attr_path = target.rpartition(":") if target.count(":") > 1 else target.partition(":")
    if not module_name or not attr_path:
        raise kind.unknown_error(f"bad {kind.noun} spec {target!r}: expected NAME or MODULE:ATTR")
    if module_name.endswith(".py"):
        path = Path(module_name)
        if not path.is_file():
            raise kind.unknown_error(f"no such {kind.file_noun} {module_name!r}")
        unique = f"denoisebench_{kind.noun}_{abs(hash(str(path.resolve())))}"
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


def check_options(kind: PluginKind, obj: Any, spec: str, options: Mapping[str, Any]) -> None:
    """``kind.option_error`` when ``obj`` (class or factory) takes no keyword named like an option.

    A constructor with ``**kwargs``, or one whose signature cannot be read, accepts anything.
    """
    if not options or not callable(obj):
        return
    try:
        parameters = list(inspect.signature(obj).parameters.values())
    except (TypeError, ValueError):
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return
    known = [p.name for p in parameters if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
    unknown = [key for key in options if key not in known]
    if unknown:
        raise kind.option_error(
            f"{kind.noun} {spec!r} has no option {', '.join(map(repr, unknown))}; "
            f"it takes {', '.join(known) or 'no options'}"
        )


def instantiate(kind: PluginKind, obj: Any, spec: str, options: Mapping[str, Any]) -> Any:
    """``obj`` constructed with ``options`` (a ready instance as it is), named ``spec`` where it has no name."""
    ready = not isinstance(obj, type) and callable(getattr(obj, kind.method, None))
    if ready:
        if options:
            raise kind.ready_options_error(f"{spec!r} is a ready instance; it takes no options ({', '.join(options)})")
        instance = obj
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
            known = ", ".join(available(kind, found))
            raise kind.unknown_error(f"unknown {kind.noun} {spec!r}; known: {known} (or give MODULE:ATTR)")
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
