"""Find a sampler by spec: a built-in name, an entry point, or ``module:attr`` / ``file.py:attr``.

The same grammar as the denoisers' registry (``denoisebench/denoisers/registry.py``): ``NAME`` is a
built-in (:data:`BUILTINS`: ``uniform``, ``ci_stop``, ``dual_buffer``, ``hachisuka2008``, ``mdas``), else an
entry point of the group ``denoisebench.samplers`` (a plugin package declares
``[project.entry-points."denoisebench.samplers"] my_sampler = "my_pkg:MySampler"``); built-ins win
over an entry point of the same name. ``MODULE:ATTR`` and ``path/to/file.py:ATTR`` name anything
importable. The object may be a class or a factory (called with the options) or a ready instance.

Notes
-----
* The resolution itself is :mod:`denoisebench.plugins.loading`'s, shared with the denoisers' registry
  (the layering keeps ``sampling`` from importing ``denoisers``); this module holds the group, the
  built-ins and the error classes.
* Failures are :class:`UnknownSamplerError` and :class:`SamplerLoadError`, one-line
  :class:`~denoisebench.errors.UserInputError` (the CLI exits 2).
"""

from __future__ import annotations

import importlib.metadata
from typing import Any

from denoisebench.errors import UserInputError
from denoisebench.plugins import loading
from denoisebench.sampling.protocol import sampler_name

ENTRY_POINT_GROUP = "denoisebench.samplers"

#: Built-in name -> ("module:attr", default keyword arguments); imported on first use.
BUILTINS: dict[str, tuple[str, dict[str, Any]]] = {
    "uniform": ("denoisebench.sampling.uniform:Uniform", {}),
    "ci_stop": ("denoisebench.sampling.ci_stop:ConfidenceStop", {}),
    "dual_buffer": ("denoisebench.sampling.dual_buffer:DualBuffer", {}),
    "hachisuka2008": ("denoisebench.sampling.hachisuka:Hachisuka2008", {}),
    "mdas": ("denoisebench.sampling.mdas:MDAS", {}),
}


class UnknownSamplerError(UserInputError):
    """No built-in, entry point or importable ``module:attr`` has this name."""


class SamplerLoadError(UserInputError):
    """The sampler was found but failed to import or construct (or takes no such option)."""


def _entry_points() -> dict[str, importlib.metadata.EntryPoint]:
    return loading.entry_points(ENTRY_POINT_GROUP)


KIND = loading.PluginKind(
    noun="sampler",
    group=ENTRY_POINT_GROUP,
    builtins=BUILTINS,
    method="sample",
    validate=sampler_name,
    unknown_error=UnknownSamplerError,
    load_error=SamplerLoadError,
    option_error=SamplerLoadError,
    ready_options_error=SamplerLoadError,
    file_noun="sampler file",
    where_prefix="sampler ",
    arguments=("budget", "rounds"),
)


def available_samplers() -> dict[str, str]:
    """Every name a spec may use, mapped to where it comes from (nothing is imported)."""
    return loading.available(KIND, _entry_points())


def load_sampler(spec: str, **options: Any):
    """The sampler ``spec`` names, constructed with ``options`` (module docstring)."""
    return loading.load(KIND, spec, options, _entry_points)


def check_sampler_spec(spec: str) -> None:
    """:class:`UnknownSamplerError` where ``spec`` names no sampler, found without importing anything (a bare name
    that is no built-in or entry point, a ``file.py`` that does not exist)."""
    loading.check_spec(KIND, spec, _entry_points)
