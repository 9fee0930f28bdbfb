"""One shell for untrusted code: spec resolution, the worker process, the sandbox, one proxy.

The denoisers' and the samplers' plugins are found, run and confined the same way; what differs is
their protocol, which stays in ``denoisers/`` and ``sampling/``. The modules:

:mod:`.loading`
    a spec (built-in name, entry point, ``MODULE:ATTR``, ``file.py:ATTR``) to a constructed object,
    parametrised by a :class:`~.loading.PluginKind`.
:mod:`.proxy`
    the harness's side: :class:`~.proxy.PluginProxy` (start, send, receive, close, disable on a
    time-out), :class:`~.proxy.PluginFailure` (the one failure type), the ``--isolation`` policies and
    the command-line options of the limits.
:mod:`.process`
    the worker process (start, plain or sandboxed; watched for exit, memory, time and tasks; ended)
    and its :class:`~.process.Limits`.
:mod:`.worker`
    what runs in the worker: load the plugin, serve the protocol's requests, reply in JSON and bytes.
:mod:`.sandbox`
    the bubblewrap command line.

Imports no stage of the project (only :mod:`denoisebench.errors`); ``denoisers``, ``sampling`` and the benchmark import it.
"""

from denoisebench.plugins.process import DEFAULT_MEMORY_LIMIT_MB, DEFAULT_TIME_LIMIT, Limits, SandboxUnavailableError
from denoisebench.plugins.proxy import POLICIES, PluginFailure, PluginProxy

__all__ = [
    "DEFAULT_MEMORY_LIMIT_MB",
    "DEFAULT_TIME_LIMIT",
    "POLICIES",
    "Limits",
    "PluginFailure",
    "PluginProxy",
    "SandboxUnavailableError",
]
