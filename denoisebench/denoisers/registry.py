"""Find a denoiser by spec: a built-in name, an entry point, or ``module:attr``.

Spec grammar (first match wins):

``NAME``
    a built-in (see :data:`BUILTINS`: ``identity``, ``cross_bilateral``, ``cross_bilateral_fast``,
    ``cross_bilateral_high``, ``rpf``, ``rpf_fast``, ``nlmeans``, ``oidn``, ``oidn_balanced``, ``oidn_fast``, and the
    learned ``dpcn``, ``kpcn``, ``rae``, ``lbf``), else
    an entry point of the group ``denoisebench.denoisers`` (a plugin package declares
    ``[project.entry-points."denoisebench.denoisers"] my_denoiser = "my_pkg:MyDenoiser"``).
    Built-ins win over an entry point of the same name.
``MODULE:ATTR`` / ``path/to/file.py:ATTR``
    anything importable; ``ATTR`` may be dotted (``pkg.mod:Outer.Inner``).

The object found may be a class (called with the options), a factory function (called with the
options) or a ready instance (no options allowed). Presets are separate names (``cross_bilateral_fast``)
and constructor options are keyword arguments: ``load_denoiser("cross_bilateral", radius=7)`` or, on
the command line, ``--option radius=7``.

Failures are :class:`UnknownDenoiserError` (the name is nowhere; the message lists the known names)
or :class:`DenoiserLoadError` (found but it failed to import or construct, e.g. OIDN without
``pyoidn``): both one-line :class:`~denoisebench.errors.UserInputError`, so the CLI exits 2.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import inspect
import sys
from pathlib import Path
from typing import Any

from denoisebench.denoisers.protocol import describe
from denoisebench.errors import UserInputError, one_line

ENTRY_POINT_GROUP = "denoisebench.denoisers"

#: Built-in name -> ("module:attr", default keyword arguments). Imported lazily, on first use.
BUILTINS: dict[str, tuple[str, dict[str, Any]]] = {
    "identity": ("denoisebench.baselines.identity:Identity", {}),
    "cross_bilateral": ("denoisebench.baselines.cross_bilateral:CrossBilateral", {"preset": "balanced"}),
    "cross_bilateral_fast": ("denoisebench.baselines.cross_bilateral:CrossBilateral", {"preset": "fast"}),
    "cross_bilateral_high": ("denoisebench.baselines.cross_bilateral:CrossBilateral", {"preset": "high"}),
    "rpf": ("denoisebench.baselines.rpf:RandomParameterFilter", {}),
    "rpf_fast": ("denoisebench.baselines.rpf:RandomParameterFilter", {"preset": "fast"}),
    "nlmeans": ("denoisebench.baselines.nlmeans:NLMeans", {}),
    "oidn": ("denoisebench.baselines.oidn:OIDN", {"quality": "high"}),
    "oidn_balanced": ("denoisebench.baselines.oidn:OIDN", {"quality": "balanced"}),
    "oidn_fast": ("denoisebench.baselines.oidn:OIDN", {"quality": "fast"}),
    "dpcn": ("denoisebench.models.denoisers:DPCN", {}),
    "kpcn": ("denoisebench.models.denoisers:KPCN", {}),
    "rae": ("denoisebench.models.denoisers:RAE", {}),
    "lbf": ("denoisebench.models.denoisers:LBFDenoiser", {}),
}


class UnknownDenoiserError(UserInputError):
    """No built-in, entry point or importable ``module:attr`` has this name."""


class DenoiserLoadError(UserInputError):
    """The denoiser was found but failed to import or construct."""


class UnknownOptionError(UserInputError):
    """An option the denoiser's constructor does not take (a typo must not turn into "not run")."""


class DenoiserUnavailableError(RuntimeError):
    """Raised by a built-in whose optional dependency is missing (caught and re-raised as a load error)."""


def _entry_points() -> dict[str, importlib.metadata.EntryPoint]:
    found: dict[str, importlib.metadata.EntryPoint] = {}
    for entry_point in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        found.setdefault(entry_point.name, entry_point)
    return found


def available_denoisers() -> dict[str, str]:
    """Every name a spec may use, mapped to where it comes from (nothing is imported)."""
    names = {name: f"built-in ({target})" for name, (target, _) in BUILTINS.items()}
    for name, entry_point in sorted(_entry_points().items()):
        if name not in names:
            dist = getattr(entry_point, "dist", None)
            origin = f"{dist.name} {dist.version}" if dist is not None else entry_point.value
            names[name] = f"entry point ({origin}: {entry_point.value})"
    return names


def _import_target(target: str) -> Any:
    module_name, _, attr_path = target.partition(":")
    if not module_name or not attr_path:
        raise UnknownDenoiserError(f"bad denoiser spec {target!r}: expected NAME or MODULE:ATTR")
    if module_name.endswith(".py"):
        path = Path(module_name)
        if not path.is_file():
            raise UnknownDenoiserError(f"no such plugin file {module_name!r}")
        unique = f"denoisebench_plugin_{abs(hash(str(path.resolve())))}"
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
                raise UnknownDenoiserError(f"no module named {module_name!r} (from spec {target!r})") from None
            raise
    obj: Any = module
    for part in attr_path.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise UnknownDenoiserError(f"module {module_name!r} has no attribute {attr_path!r}") from None
    return obj


def check_options(obj: Any, spec: str, options: dict[str, Any]) -> None:
    """UnknownOptionError when ``obj`` (class or factory) takes no keyword named like an option.

    A constructor with ``**kwargs``, or one whose signature cannot be read, accepts anything.
    """
    if not options or not callable(obj):
        return
    try:
        parameters = inspect.signature(obj).parameters.values()
    except (TypeError, ValueError):
        return
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters):
        return
    known = [
        p.name
        for p in parameters
        if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    ]
    unknown = [key for key in options if key not in known]
    if unknown:
        raise UnknownOptionError(
            f"denoiser {spec!r} has no option {', '.join(map(repr, unknown))}; it takes {', '.join(known) or 'no options'}"
        )


def _instantiate(obj: Any, spec: str, options: dict[str, Any]) -> Any:
    if isinstance(obj, type) or not callable(getattr(obj, "denoise", None)):
        check_options(obj, spec, options)
    if isinstance(obj, type):
        instance = obj(**options)
    elif callable(getattr(obj, "denoise", None)):
        if options:
            raise TypeError(f"{spec!r} is a ready instance; it takes no options ({', '.join(options)})")
        instance = obj
    elif callable(obj):
        instance = obj(**options)
    else:
        raise TypeError(f"{spec!r} is a {type(obj).__name__}, not a denoiser class, factory or instance")
    if getattr(instance, "name", None) is None:
        try:
            instance.name = spec
        except Exception:  # noqa: BLE001 - an object that refuses attributes keeps describe()'s default
            pass
    describe(instance, fallback_name=spec)  # raises TypeError for a non-denoiser
    return instance


def load_denoiser(spec: str, **options: Any):
    """The denoiser ``spec`` names, constructed with ``options``. See the module docstring."""
    if not isinstance(spec, str) or not spec.strip():
        raise UnknownDenoiserError("empty denoiser spec")
    spec = spec.strip()
    if spec in BUILTINS:
        target, defaults = BUILTINS[spec]
        kwargs = {**defaults, **options}
        where = f"built-in {spec!r}"
        loader = lambda: _import_target(target)  # noqa: E731
    elif ":" in spec:
        kwargs = dict(options)
        where = f"{spec!r}"
        loader = lambda: _import_target(spec)  # noqa: E731
    else:
        entry_point = _entry_points().get(spec)
        if entry_point is None:
            known = ", ".join(available_denoisers())
            raise UnknownDenoiserError(f"unknown denoiser {spec!r}; known: {known} (or give MODULE:ATTR)")
        kwargs = dict(options)
        where = f"entry point {spec!r} ({entry_point.value})"
        loader = entry_point.load
    try:
        obj = loader()
    except UserInputError:
        raise
    except Exception as error:  # noqa: BLE001 - a broken plugin is a one-line load error
        raise DenoiserLoadError(f"cannot import {where}: {one_line(error)}") from error
    try:
        return _instantiate(obj, spec, kwargs)
    except UserInputError:
        raise
    except Exception as error:  # noqa: BLE001
        raise DenoiserLoadError(f"cannot construct {where}: {one_line(error)}") from error
