"""Find a sampler by spec: a built-in name, an entry point, or ``module:attr`` / ``file.py:attr``.

The same grammar as the denoisers' registry (``denoisebench/denoisers/registry.py``): ``NAME`` is a
built-in (:data:`BUILTINS`: ``uniform``, ``ci_stop``, ``dual_buffer``, ``hachisuka2008``), else an
entry point of the group ``denoisebench.samplers`` (a plugin package declares
``[project.entry-points."denoisebench.samplers"] my_sampler = "my_pkg:MySampler"``); built-ins win
over an entry point of the same name. ``MODULE:ATTR`` and ``path/to/file.py:ATTR`` name anything
importable. The object may be a class or a factory (called with the options) or a ready instance.

Notes
-----
* The layering (``tests/test_architecture.py``) keeps ``sampling`` from importing ``denoisers``, so
  the few lines that import a target are this module's own, not the denoisers' registry's.
* Failures are :class:`UnknownSamplerError` and :class:`SamplerLoadError`, one-line
  :class:`~denoisebench.errors.UserInputError` (the CLI exits 2).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import inspect
import sys
from pathlib import Path
from typing import Any

from denoisebench.errors import UserInputError, one_line
from denoisebench.sampling.protocol import sampler_name

ENTRY_POINT_GROUP = "denoisebench.samplers"

#: Built-in name -> ("module:attr", default keyword arguments); imported on first use.
BUILTINS: dict[str, tuple[str, dict[str, Any]]] = {
    "uniform": ("denoisebench.sampling.uniform:Uniform", {}),
    "ci_stop": ("denoisebench.sampling.ci_stop:ConfidenceStop", {}),
    "dual_buffer": ("denoisebench.sampling.dual_buffer:DualBuffer", {}),
    "hachisuka2008": ("denoisebench.sampling.hachisuka:Hachisuka2008", {}),
}


class UnknownSamplerError(UserInputError):
    """No built-in, entry point or importable ``module:attr`` has this name."""


class SamplerLoadError(UserInputError):
    """The sampler was found but failed to import or construct (or takes no such option)."""


def _entry_points() -> dict[str, importlib.metadata.EntryPoint]:
    found: dict[str, importlib.metadata.EntryPoint] = {}
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(entry_point.name, entry_point)
    return found


def available_samplers() -> dict[str, str]:
    """Every name a spec may use, mapped to where it comes from (nothing is imported)."""
    names = {name: f"built-in ({target})" for name, (target, _) in BUILTINS.items()}
    for name, entry_point in sorted(_entry_points().items()):
        if name not in names:
            names[name] = f"entry point ({entry_point.value})"
    return names


def _import_target(target: str) -> Any:
    module_name, _, attr_path = target.rpartition(":") if target.count(":") > 1 else target.partition(":")
    if not module_name or not attr_path:
        raise UnknownSamplerError(f"bad sampler spec {target!r}: expected NAME or MODULE:ATTR")
    if module_name.endswith(".py"):
        path = Path(module_name)
        if not path.is_file():
            raise UnknownSamplerError(f"no such sampler file {module_name!r}")
        unique = f"denoisebench_sampler_{abs(hash(str(path.resolve())))}"
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
                raise UnknownSamplerError(f"no module named {module_name!r} (from spec {target!r})") from None
            raise
    obj: Any = module
    for part in attr_path.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise UnknownSamplerError(f"module {module_name!r} has no attribute {attr_path!r}") from None
    return obj


def _check_options(obj: Any, spec: str, options: dict[str, Any]) -> None:
    if not options:
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
        raise SamplerLoadError(
            f"sampler {spec!r} has no option {', '.join(map(repr, unknown))}; it takes {', '.join(known) or 'no options'}"
        )


def _instantiate(obj: Any, spec: str, options: dict[str, Any]) -> Any:
    ready = not isinstance(obj, type) and callable(getattr(obj, "sample", None))
    if ready:
        if options:
            raise SamplerLoadError(f"{spec!r} is a ready instance; it takes no options ({', '.join(options)})")
        instance = obj
    elif callable(obj):
        _check_options(obj, spec, options)
        instance = obj(**options)
    else:
        raise TypeError(f"{spec!r} is a {type(obj).__name__}, not a sampler class, factory or instance")
    if getattr(instance, "name", None) is None:
        try:
            instance.name = spec
        except Exception:  # noqa: BLE001 - an object that refuses attributes is named by sampler_name's fallback
            pass
    sampler_name(instance, spec)  # TypeError for a non-sampler
    return instance


def load_sampler(spec: str, **options: Any):
    """The sampler ``spec`` names, constructed with ``options`` (module docstring)."""
    if not isinstance(spec, str) or not spec.strip():
        raise UnknownSamplerError("empty sampler spec")
    spec = spec.strip()
    if spec in BUILTINS:
        target, defaults = BUILTINS[spec]
        kwargs, where = {**defaults, **options}, f"built-in {spec!r}"
        loader = lambda: _import_target(target)  # noqa: E731
    elif ":" in spec:
        kwargs, where = dict(options), repr(spec)
        loader = lambda: _import_target(spec)  # noqa: E731
    else:
        entry_point = _entry_points().get(spec)
        if entry_point is None:
            known = ", ".join(available_samplers())
            raise UnknownSamplerError(f"unknown sampler {spec!r}; known: {known} (or give MODULE:ATTR)")
        kwargs, where = dict(options), f"entry point {spec!r} ({entry_point.value})"
        loader = entry_point.load
    try:
        obj = loader()
    except UserInputError:
        raise
    except Exception as error:  # noqa: BLE001 - a broken plugin is a one-line load error
        raise SamplerLoadError(f"cannot import sampler {where}: {one_line(error)}") from error
    try:
        return _instantiate(obj, spec, kwargs)
    except UserInputError:
        raise
    except Exception as error:  # noqa: BLE001
        raise SamplerLoadError(f"cannot construct sampler {where}: {one_line(error)}") from error
