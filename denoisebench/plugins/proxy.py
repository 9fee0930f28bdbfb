"""The harness's side of an isolated plugin: one proxy base, one failure type, the isolation policies.

:class:`PluginProxy` owns a plugin's worker (:class:`~denoisebench.plugins.process.WorkerProcess`):
:meth:`~PluginProxy.start` starts it and loads the plugin there, :meth:`~PluginProxy.send` and
:meth:`~PluginProxy.receive` carry one message each way under the :class:`~denoisebench.plugins.process.Limits`,
:meth:`~PluginProxy.close` stops it. Every breach (an exit, a crash, the memory or the time limit, a
malformed message) ends the worker and raises :class:`PluginFailure` with the one-line reason; a breach
of the time limit also **disables** the proxy for the rest of this process (every later call fails at
once with the same reason), so a hanging plugin costs one time limit per run, not one per frame. The
next :meth:`~PluginProxy.start` after any other failure loads the plugin afresh.

Each protocol subclasses it with what is its own: the denoisers'
(:class:`denoisebench.denoisers.isolation.IsolatedDenoiser`) and the samplers'
(:class:`denoisebench.sampling.isolation.IsolatedSampler`) proxies, each naming its worker side
(:attr:`PluginProxy.service`) and its load errors.

Policies (``--isolation``, the same names for denoisers and samplers): ``plugins`` (everything but the
built-ins runs in a sandboxed worker, the default), ``all`` (built-ins too), ``process`` (plugins in
plain worker processes, without the sandbox: for machines where none starts, and recorded), ``none``
(everything in the harness's process: trusted code only).
"""

from __future__ import annotations

import logging
import traceback as tb
from collections.abc import Collection, Mapping
from typing import ClassVar

from denoisebench.errors import UserInputError
from denoisebench.plugins import process
from denoisebench.plugins.process import DEFAULT_MEMORY_LIMIT_MB, DEFAULT_TIME_LIMIT, Limits, WorkerGone

#: Who runs in a worker (module docstring).
POLICIES = ("plugins", "all", "process", "none")
#: The policies whose workers run in the sandbox.
SANDBOXED_POLICIES = ("plugins", "all")
DEFAULT_POLICY = "plugins"


class PluginFailure(RuntimeError):
    """An isolated plugin's call failed; the message is the one-line reason recorded for it.

    ``traceback``: the plugin's own traceback (text) where the plugin raised, else None (the worker
    exited, was killed, or broke a limit).
    """

    def __init__(self, reason: str, traceback: str | None = None):
        super().__init__(reason)
        self.traceback = traceback


#: Where a raising plugin's traceback is logged (a warning: stderr where logging is not configured).
LOG = logging.getLogger("denoisebench.plugins")
#: The most tracebacks logged for one plugin in one process (distinct errors each).
LOG_PER_PLUGIN = 3
_LOGGED: set[tuple[str, str]] = set()


def log_failure(noun: str, label: str, where: str, reason: str, error: BaseException) -> str | None:
    """The plugin's traceback behind ``error`` (the worker's, for a :class:`PluginFailure`), or None.

    The first time a plugin fails with ``reason`` it is logged on :data:`LOG` with its traceback (at
    most :data:`LOG_PER_PLUGIN` distinct reasons per plugin), so that its author sees where it raised.
    """
    if isinstance(error, PluginFailure):
        text = error.traceback
    else:
        text = "".join(tb.format_exception(type(error), error, error.__traceback__))
    seen = sum(other == label for other, _ in _LOGGED)
    if text and (label, reason) not in _LOGGED and seen < LOG_PER_PLUGIN:
        _LOGGED.add((label, reason))
        LOG.warning("%s %s failed on %s: %s\n%s", noun, label, where, reason, text.rstrip())
    return text or None


def failure_from(header: Mapping, default: str) -> PluginFailure:
    """The :class:`PluginFailure` a worker's failed reply describes (its ``error`` and ``traceback``)."""
    trace = header.get("traceback")
    return PluginFailure(str(header.get("error") or default), str(trace) if trace else None)


class PluginProxy:
    """A plugin living in a worker process of its own (module docstring).

    Subclasses set :attr:`noun`, :attr:`service` (``"module:Class"`` of the worker side, see
    :mod:`denoisebench.plugins.worker`), :attr:`load_errors` (the worker's ``error_type`` names that
    come back as themselves) and :attr:`load_error` (every other load failure).
    ``sandboxed``: the worker runs in the sandbox of :mod:`denoisebench.plugins.sandbox` (refused with
    :class:`~denoisebench.plugins.process.SandboxUnavailableError` where none starts); False is a plain
    worker process.
    """

    noun: ClassVar[str] = "plugin"
    service: ClassVar[str] = ""
    load_errors: ClassVar[Mapping[str, type[Exception]]] = {}
    load_error: ClassVar[type[Exception]] = UserInputError
    #: The largest JSON header the worker may send.
    header_bytes: ClassVar[int] = 1 << 20

    def __init__(self, spec: str, options: dict | None = None, limits: Limits | None = None, *, sandboxed: bool = True):
        self.spec = spec
        self.options = dict(options or {})
        self.limits = limits or Limits()
        self.sandboxed = bool(sandboxed)
        if self.sandboxed:
            process.require_sandbox(spec)
        self._worker: process.WorkerProcess | None = None
        self._disabled: str | None = None  # reason, after a time-limit kill

    @property
    def running(self) -> bool:
        """Whether a worker is there to serve requests."""
        return self._worker is not None and self._worker.conn is not None

    def start(self, args: tuple[str, ...] = (), fds: tuple[int, ...] = ()) -> dict:
        """Start a worker (``args``, ``fds`` passed on to the worker side) and load the plugin there.

        Returns the load reply's header (what the worker's instance declared); raises the protocol's
        load error where the plugin does not load (its ``traceback`` attribute: the worker's, where the
        plugin raised), or the worker fails meanwhile.
        """
        self.close()
        self._worker = process.WorkerProcess(
            self.service,
            noun=self.noun,
            sandboxed=self.sandboxed,
            limits=self.limits,
            spec=self.spec,
            options=self.options,
            args=args,
            fds=fds,
        )
        try:
            self.send(self._worker.load_message())
            header, _ = self.receive("load")
        except PluginFailure as failure:
            raise self.load_error(f"cannot load {self.noun} {self.spec!r} in its worker: {failure}") from None
        if not header.get("ok"):
            self.close()
            kind, message = str(header.get("error_type", "")), str(header.get("error", "load failed"))
            if kind in self.load_errors:
                error = self.load_errors[kind](message.removeprefix(f"{kind}: "))
            else:
                error = self.load_error(f"cannot load {self.noun} {self.spec!r}: {message}")
            error.traceback = str(header["traceback"]) if header.get("traceback") else None
            raise error
        return header

    def check_enabled(self) -> None:
        """PluginFailure where a time-limit breach has disabled this plugin for the process."""
        if self._disabled:
            raise PluginFailure(self._disabled)

    def _failed(self, gone: WorkerGone) -> PluginFailure:
        """The worker has ended (it is killed on every breach): forget it; disable on a time-out."""
        self._worker = None
        if gone.timed_out:
            self._disabled = str(gone)
        return PluginFailure(str(gone))

    def kill(self, reason: str) -> PluginFailure:
        """End the worker at once (a message the harness refuses); the failure to raise."""
        if self._worker is not None:
            self._worker.kill(reason)
            self._worker = None
        return PluginFailure(reason)

    def send(self, message: tuple) -> None:
        """Send a (pickled) message to the worker; PluginFailure where it has gone."""
        if self._worker is None:
            raise PluginFailure(f"the {self.noun}'s worker is not running (closed, or ended by an earlier failure)")
        try:
            self._worker.send(message)
        except WorkerGone as gone:
            raise self._failed(gone) from None

    def receive(self, what: str, max_bytes: int = 0) -> tuple[dict, bytes | None]:
        """The worker's next header and, where it has one, payload (at most ``max_bytes``), under the limits.

        :meth:`check_payload` is asked before a payload is read. PluginFailure on any breach.
        """
        worker, limits = self._worker, self.limits
        try:
            header = worker.receive_header(what, limits.time_limit, limits.memory_limit_mb, self.header_bytes)
            payload = None
            if header.get("payload"):
                refused = self.check_payload(header, max_bytes)
                if refused:
                    raise self.kill(refused)
                payload = worker.receive_payload(max_bytes)
        except WorkerGone as gone:
            raise self._failed(gone) from None
        return header, payload

    def check_payload(self, header: dict, max_bytes: int) -> str | None:
        """Why the payload ``header`` announces is refused unread (the worker is then killed), or None."""
        return None

    def close(self) -> None:
        """Stop the worker (the next :meth:`start` starts a new one)."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.spec!r}, name={getattr(self, 'name', '?')!r})"


def check_policy(policy: str) -> str:
    """``policy`` where it is one of :data:`POLICIES`; UserInputError (exit 2) otherwise."""
    if policy not in POLICIES:
        raise UserInputError(f"--isolation must be one of {', '.join(POLICIES)} (got {policy!r})")
    return policy


def isolated(spec: str, policy: str, builtins: Collection[str]) -> bool:
    """Whether ``spec`` runs in a worker under ``policy`` (``builtins``: the names that are code of this package)."""
    check_policy(policy)
    if policy == "none":
        return False
    return policy == "all" or spec.strip() not in builtins


def sandboxed(policy: str = DEFAULT_POLICY) -> bool:
    """Whether ``policy`` puts isolated plugins into the sandbox (every policy but process/none)."""
    return policy in SANDBOXED_POLICIES


def isolation_text(config: dict, versions: dict) -> str:
    """The report's sentence on how a run's plugins were confined (from its config and versions)."""
    policy = config.get("isolation", DEFAULT_POLICY)
    if policy == "none":
        return "Isolation: none (--isolation none): every denoiser ran in the harness's process, trusted code only."
    if policy == "process":
        return (
            "Isolation: plugins ran in plain worker processes, not sandboxed (--isolation process): "
            "they could read the user's files and reach the network."
        )
    who = "every denoiser" if policy == "all" else "plugins (every non-built-in)"
    if "bubblewrap" not in versions:
        return f"Isolation: {who} ran in plain worker processes, not sandboxed (a run made before the sandbox)."
    return (
        f"Isolation: {who} ran sandboxed (bubblewrap {versions['bubblewrap']}: no network, own PID namespace, "
        "the dataset, the store and the user's files out of sight, private scratch, resource limits)."
    )


def add_arguments(parser) -> None:
    """``--isolation``, ``--time-limit`` and ``--memory-limit`` on a command's parser."""
    parser.add_argument(
        "--isolation",
        choices=POLICIES,
        default=DEFAULT_POLICY,
        help="which denoisers and samplers run in a sandboxed worker process of their own: plugins (every "
        "non-built-in, default), all; process: plugins in plain worker processes without the sandbox (where none "
        "starts; recorded); none (trusted code only)",
    )
    parser.add_argument(
        "--time-limit",
        type=float,
        default=DEFAULT_TIME_LIMIT,
        metavar="SECONDS",
        help=f"per-call time limit of an isolated denoiser or sampler (default {DEFAULT_TIME_LIMIT:g})",
    )
    parser.add_argument(
        "--memory-limit",
        type=int,
        default=DEFAULT_MEMORY_LIMIT_MB,
        metavar="MIB",
        help=f"resident-memory limit of an isolated plugin's worker in MiB (default {DEFAULT_MEMORY_LIMIT_MB})",
    )


def limits_from_args(args) -> Limits:
    """The :class:`~denoisebench.plugins.process.Limits` of ``--time-limit`` and ``--memory-limit``."""
    return Limits(float(args.time_limit), int(args.memory_limit))
