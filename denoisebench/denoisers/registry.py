"""Find a denoiser by spec: a built-in name, an entry point, or ``module:attr``.

Spec grammar (first match wins):

``NAME``
    a built-in (see :data:`BUILTINS`: ``identity``, ``cross_bilateral``, ``cross_bilateral_fast``,
    ``cross_bilateral_high``, ``rpf``, ``rpf_fast``, ``lightfield``, ``nlmeans``, ``oidn``, ``oidn_balanced``, ``oidn_fast``, and the
    learned ``dpcn``, ``kpcn``, ``rae``, ``lbf``), else
    an entry point of the group ``denoisebench.denoisers`` (a plugin package declares
    ``[project.entry-points."denoisebench.denoisers"] my_denoiser = "my_pkg:MyDenoiser"``).
    Built-ins win over an entry point of the same name.
``MODULE:ATTR`` / ``path/to/file.py:ATTR``
    anything importable; ``ATTR`` may be dotted (``pkg.mod:Outer.Inner``).

The object found may be a class (called with the options), a factory function (called with the
options), a ready instance (no options allowed), or a plain function ``denoise(frame)`` (its attributes
``needs``, ``temporal``, ``name`` declare the rest; options are bound as keywords). Presets are separate names (``cross_bilateral_fast``)
and constructor options are keyword arguments: ``load_denoiser("cross_bilateral", radius=7)`` or, on
the command line, ``--option radius=7``.

Failures are :class:`UnknownDenoiserError` (the name is nowhere; the message lists the known names)
or :class:`DenoiserLoadError` (found but it failed to import or construct, e.g. OIDN without
``pyoidn``): both one-line :class:`~denoisebench.errors.UserInputError`, so the CLI exits 2.

Notes
-----
The resolution itself is :mod:`denoisebench.plugins.loading`'s, shared with the samplers' registry;
this module holds what is the denoisers' own: the group, the built-ins, the error classes.
"""

from __future__ import annotations

import importlib.metadata
from typing import Any

from denoisebench.denoisers.protocol import describe
from denoisebench.errors import UserInputError
from denoisebench.plugins import loading

ENTRY_POINT_GROUP = "denoisebench.denoisers"

#: Built-in name -> ("module:attr", default keyword arguments). Imported lazily, on first use.
BUILTINS: dict[str, tuple[str, dict[str, Any]]] = {
    "identity": ("denoisebench.baselines.identity:Identity", {}),
    "cross_bilateral": ("denoisebench.baselines.cross_bilateral:CrossBilateral", {"preset": "balanced"}),
    "cross_bilateral_fast": ("denoisebench.baselines.cross_bilateral:CrossBilateral", {"preset": "fast"}),
    "cross_bilateral_high": ("denoisebench.baselines.cross_bilateral:CrossBilateral", {"preset": "high"}),
    "rpf": ("denoisebench.baselines.rpf:RandomParameterFilter", {}),
    "rpf_fast": ("denoisebench.baselines.rpf:RandomParameterFilter", {"preset": "fast"}),
    "lightfield": ("denoisebench.baselines.lightfield:LightField", {}),
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
    return loading.entry_points(ENTRY_POINT_GROUP)


KIND = loading.PluginKind(
    noun="denoiser",
    group=ENTRY_POINT_GROUP,
    builtins=BUILTINS,
    method="denoise",
    validate=lambda instance, spec: describe(instance, fallback_name=spec),
    unknown_error=UnknownDenoiserError,
    load_error=DenoiserLoadError,
    option_error=UnknownOptionError,
    ready_options_error=TypeError,
    file_noun="plugin file",
    arguments=("frame",),
)


def available_denoisers() -> dict[str, str]:
    """Every name a spec may use, mapped to where it comes from (nothing is imported)."""
    return loading.available(KIND, _entry_points())


def load_denoiser(spec: str, **options: Any):
    """The denoiser ``spec`` names, constructed with ``options``. See the module docstring."""
    return loading.load(KIND, spec, options, _entry_points)


def check_denoiser_spec(spec: str) -> None:
    """:class:`UnknownDenoiserError` where ``spec`` names no denoiser, found without importing anything (a bare name
    that is no built-in or entry point, a ``file.py`` that does not exist)."""
    loading.check_spec(KIND, spec, _entry_points)


def denoiser_code_identity(spec: str) -> str | None:
    """A short hash of the code a plugin ``spec`` runs (None for a built-in): see
    :func:`denoisebench.plugins.loading.code_identity`."""
    return loading.code_identity(KIND, spec, _entry_points)
