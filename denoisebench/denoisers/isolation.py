"""Run untrusted denoisers in worker processes of their own, with a time and a memory limit.

:func:`load` is how the benchmark and ``check-plugin`` construct denoisers. Under the default
policy (:data:`DEFAULT_POLICY` = ``"plugins"``) a built-in (:data:`~.registry.BUILTINS`, code of
this package) is constructed in this process, and everything else (an entry point, a
``module:attr`` or ``file.py:attr`` spec) in an :class:`IsolatedDenoiser`: a proxy that speaks
the Denoiser protocol and forwards every call to a worker process
(:mod:`.isolation_worker`) that imported and constructed the plugin there. ``"all"`` isolates the
built-ins too (one worker each); ``"none"`` runs everything in this process (trusted code only).

What isolation gives
--------------------
* **Exits and crashes are contained.** ``sys.exit()``, ``os._exit()``, a segfault or a kill of
  the worker fails the call with the reason (``worker exited with status 3``, ``worker killed by
  SIGSEGV``); the benchmark records it and goes on. The next ``reset()`` (the next sequence)
  starts a fresh worker and loads the plugin again.
* **Time limit** (``time_limit`` seconds per call of load, ``reset()`` or ``denoise()``; default
  :data:`DEFAULT_TIME_LIMIT`): a call that runs over is failed, the worker killed, and the denoiser
  is **disabled** for the rest of this process (every later call fails at once with the same
  reason), so a hanging plugin costs one time limit per run, not one per frame.
* **Memory limit** (``memory_limit_mb`` MiB of resident memory of the worker; default
  :data:`DEFAULT_MEMORY_LIMIT_MB`): the parent reads the worker's RSS from ``/proc`` every
  :data:`~denoisebench.plugin_worker.POLL_SECONDS` while it waits and kills it when over. Address
  space that is reserved but not touched does not count; a very fast allocation may overshoot by
  what it touches in one poll.
* **Copies.** The frame reaches the worker through a shared memory file (:mod:`.shared_frames`;
  pickled through the pipe where ``memfd_create`` is missing) and the worker copies it into arrays
  of its own: making an input writable and changing it reaches nothing outside the worker.
* **No reference.** The harness hands over the frame after :func:`~.runner.sanitize_frame`, which
  withholds the reference image and every ``reference*`` and file-path entry of ``meta``.
* **Sandbox** (policies ``plugins`` and ``all``; :mod:`denoisebench.sandbox`): the worker runs
  under bubblewrap, without the host's files (but the Python environment, ``sys.path``, the plugin
  and its option files, read-only), network or a way to outlive its worker, under resource limits
  (:func:`~denoisebench.plugin_worker.rlimits`, set by the worker on itself) and a task count that
  a thread of the parent checks every :data:`~denoisebench.plugin_worker.TASK_POLL_SECONDS`, during
  calls and between them. Where no sandbox starts, the proxy is refused
  (:class:`~denoisebench.plugin_worker.SandboxUnavailableError`); ``process`` is a plain worker.
  The worker process itself (start, limits, end) is :class:`~denoisebench.plugin_worker.WorkerProcess`,
  shared with the samplers' isolation.
* **Replies are not unpickled.** The worker answers with a JSON header and raw array bytes
  (see :mod:`.isolation_worker`), so a plugin cannot run code in the harness through its output.

Pitfalls
--------
* A plain worker (``--isolation process``) is not a sandbox: it runs as the same user and can
  read what that user can; it keeps a plugin from ending, stalling or bloating the run and from
  seeing the answer through the harness only.
* Denoise time is measured inside the worker around ``denoise()`` only, as in-process; the
  transfer of the frame and the output (the isolation's overhead) is outside it, and is kept in
  :attr:`IsolatedDenoiser.overhead_seconds`.
* Start-up costs one Python interpreter plus the plugin's imports (≈0.3 s without torch, ≈2.5 s
  with it).
* The memory limit counts the worker's own resident memory; processes a plugin starts itself are
  not counted (nor limited in time once the worker is killed: they are the plugin's).
* The time limit runs while the parent waits for a reply to start; a worker that starts a reply
  and then stalls mid-message would block the read (the reply header is small and written at
  once by the harness's worker code, which a plugin would have to replace to do this).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from denoisebench import plugin_worker
from denoisebench.denoisers import registry, shared_frames
from denoisebench.denoisers.registry import BUILTINS, DenoiserLoadError, load_denoiser
from denoisebench.errors import UserInputError
from denoisebench.plugin_worker import (
    DEFAULT_OPEN_FILES,
    DEFAULT_PROCESS_LIMIT,
    DEFAULT_SCRATCH_MB,
    WorkerGone,
)

#: Seconds one call (load, reset or denoise) of an isolated denoiser may take.
DEFAULT_TIME_LIMIT = 120.0
#: Resident memory (MiB) an isolated denoiser's worker may hold.
DEFAULT_MEMORY_LIMIT_MB = 4096
#: Who runs in a worker: "plugins" (everything but the built-ins, sandboxed), "all" (built-ins too,
#: sandboxed), "process" (plugins in plain worker processes, no sandbox), "none".
POLICIES = ("plugins", "all", "process", "none")
SANDBOXED_POLICIES = ("plugins", "all")
DEFAULT_POLICY = "plugins"
#: dtype kinds an output may arrive with (the harness then checks it is float32).
_ARRAY_KINDS = "fiub"


class WorkerFailure(Exception):
    """An isolated call failed; the message is the one-line reason recorded for it."""


@dataclass(frozen=True)
class Limits:
    """Per-call time limit (seconds) and resident-memory limit (MiB) of an isolated denoiser, and
    the sandbox's task count, open files and scratch size (MiB; also the largest file)."""

    time_limit: float = DEFAULT_TIME_LIMIT
    memory_limit_mb: int = DEFAULT_MEMORY_LIMIT_MB
    processes: int = DEFAULT_PROCESS_LIMIT
    open_files: int = DEFAULT_OPEN_FILES
    scratch_mb: int = DEFAULT_SCRATCH_MB

    def __post_init__(self) -> None:
        if not self.time_limit > 0:
            raise UserInputError(f"--time-limit must be > 0 seconds (got {self.time_limit})")
        if not self.memory_limit_mb > 0:
            raise UserInputError(f"--memory-limit must be > 0 MiB (got {self.memory_limit_mb})")


class IsolatedDenoiser:
    """A denoiser living in a worker process; see the module docstring.

    ``name``, ``needs``, ``temporal`` and ``trained_scenes`` are what the worker's instance declared.
    ``last_seconds`` is the time inside the worker's ``denoise()`` of the last call,
    ``overhead_seconds`` the total time spent around those calls (transfer, checks).
    ``sandboxed``: the worker runs in the sandbox of :mod:`denoisebench.sandbox` (refused with
    :class:`~denoisebench.plugin_worker.SandboxUnavailableError` where none starts); False is a
    plain worker process.
    """

    def __init__(self, spec: str, options: dict | None = None, limits: Limits | None = None, sandboxed: bool = True):
        self.spec = spec
        self.options = dict(options or {})
        self.limits = limits or Limits()
        self.sandboxed = bool(sandboxed)
        if self.sandboxed:
            plugin_worker.require_sandbox(spec)
        self.last_seconds: float | None = None
        self.overhead_seconds = 0.0
        self._worker: plugin_worker.WorkerProcess | None = None
        self._disabled: str | None = None  # reason, after a time-limit kill
        self._broken: str | None = None  # reason, after the worker died; cleared by reset()
        self._channel = None
        if shared_frames.available():
            try:
                self._channel = shared_frames.FrameChannel()
            except OSError:  # e.g. a kernel without memfd support: frames go pickled
                self._channel = None
        info = self._start()
        self.name: str = info["name"]
        self.needs: frozenset[str] = frozenset(info["needs"])
        self.temporal: bool = bool(info["temporal"])
        self.trained_scenes: frozenset[str] = frozenset(str(s) for s in info.get("trained_scenes", []))

    # ------------------------------------------------------------------ process

    def _start(self) -> dict:
        args, fds = ((str(self._channel.fd),), (self._channel.fd,)) if self._channel is not None else ((), ())
        limits = self.limits
        self._worker = plugin_worker.WorkerProcess(
            "denoisebench.denoisers.isolation_worker",
            noun="denoiser",
            sandboxed=self.sandboxed,
            spec=self.spec,
            options=self.options,
            args=args,
            fds=fds,
            scratch_mb=limits.scratch_mb,
            processes=limits.processes,
            open_files=limits.open_files,
            memory_limit_mb=limits.memory_limit_mb,
        )
        try:
            header, _ = self._request(self._worker.load_message(), "load")
        except WorkerFailure as failure:
            raise DenoiserLoadError(f"cannot load {self.spec!r} in its worker: {failure}") from None
        if not header.get("ok"):
            self.close()
            raise _load_error(header.get("error_type", ""), header.get("error", "load failed"), self.spec)
        return header

    def close(self) -> None:
        """Stop the worker (a closed proxy starts a new one on the next ``reset()``)."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None

    def _request(self, message: tuple, what: str, max_bytes: int = 0) -> tuple[dict, bytes | None]:
        """Send ``message``; wait for the reply under the limits. WorkerFailure on any breach."""
        worker, limits = self._worker, self.limits
        try:
            worker.send(message)
            header = worker.receive_header(what, limits.time_limit, limits.memory_limit_mb)
            if header.get("payload") and header.get("kind") == "array":
                try:
                    shape = tuple(int(n) for n in header.get("shape", ()))
                    declared = int(np.prod(shape, dtype=np.int64)) * np.dtype(str(header.get("dtype"))).itemsize
                except (TypeError, ValueError) as error:
                    raise WorkerGone(
                        worker.kill(f"malformed message from the worker ({type(error).__name__})")
                    ) from None
                if declared > max_bytes:  # not read: the harness bounds what it takes in
                    reason = f"returned shape {shape}, expected H×W×3 of the frame; worker killed"
                    raise WorkerGone(worker.kill(reason))
            payload = worker.receive_payload(max_bytes) if header.get("payload") else None
        except WorkerGone as gone:
            if gone.timed_out:
                self._disabled = str(gone)
            raise WorkerFailure(str(gone)) from None
        return header, payload

    def _ready(self) -> None:
        if self._disabled:
            raise WorkerFailure(self._disabled)
        if self._broken:
            raise WorkerFailure(f"{self._broken} earlier in this sequence")

    def _call(self, message: tuple, what: str, max_bytes: int = 0) -> tuple[dict, bytes | None]:
        self._ready()
        try:
            return self._request(message, what, max_bytes)
        except WorkerFailure as failure:
            self._broken = self._broken or str(failure)
            raise

    # ------------------------------------------------------------------ protocol

    def reset(self) -> None:
        """Start of a sequence: a dead worker is replaced (plugin loaded afresh), then its reset()."""
        if self._disabled:
            raise WorkerFailure(self._disabled)
        if self._broken or self._worker is None or self._worker.conn is None:
            self._broken = None
            self.close()
            try:
                self._start()
            except Exception as error:  # noqa: BLE001 - a plugin that no longer loads fails the sequence
                self._broken = f"restart after a failure: {error}"
                raise WorkerFailure(self._broken) from None
        header, _ = self._call(("reset",), "reset()")
        if not header.get("ok"):
            raise WorkerFailure(str(header.get("error", "reset() failed")))

    def denoise(self, frame) -> Any:
        """The worker's output for ``frame`` (an array, or a stand-in naming what it returned)."""
        self.last_seconds = None
        started = time.perf_counter()
        max_bytes = frame.height * frame.width * 3 * 8
        descriptor = None
        if self._channel is not None:
            self._ready()
            descriptor = self._channel.pack(frame, max_bytes)
            message = ("denoise_shm", descriptor)
        else:
            message = ("denoise", frame)
        header, payload = self._call(message, "denoise()", max_bytes)
        self.last_seconds = float(header["seconds"]) if isinstance(header.get("seconds"), (int, float)) else None
        if not header.get("ok"):
            self.overhead_seconds += time.perf_counter() - started - (self.last_seconds or 0.0)
            raise WorkerFailure(str(header.get("error", "denoise() failed")))
        output = _rebuild(header, payload, self._channel if header.get("in_shm") and descriptor else None, descriptor)
        self.overhead_seconds += time.perf_counter() - started - (self.last_seconds or 0.0)
        return output

    def __del__(self) -> None:
        channel = getattr(self, "_channel", None)
        if channel is not None:
            channel.close()

    def __repr__(self) -> str:
        return f"IsolatedDenoiser({self.spec!r}, name={getattr(self, 'name', '?')!r})"


def _rebuild(header: dict, payload: bytes | None, channel=None, descriptor=None):
    if header.get("kind") != "array":
        # a stand-in whose type name is what the plugin returned: the output check names it
        return type(str(header.get("type", "object"))[:80], (), {})()
    try:
        dtype = np.dtype(str(header["dtype"]))
        shape = tuple(int(n) for n in header["shape"])
    except (KeyError, TypeError, ValueError) as error:
        raise WorkerFailure(f"malformed output description from the worker ({error})") from None
    if dtype.kind not in _ARRAY_KINDS or dtype.hasobject or any(n < 0 for n in shape) or len(shape) > 8:
        raise WorkerFailure(f"output of dtype {dtype} and shape {shape} refused")
    expected = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if channel is not None:
        output = channel.read_output(descriptor, dtype, shape)
        if output is None:
            raise WorkerFailure(f"returned shape {shape} ({dtype}), which does not fit the harness's size bound")
        return output
    if payload is None or len(payload) != expected:
        raise WorkerFailure(f"returned shape {shape} ({dtype}), which does not fit the harness's size bound")
    return np.frombuffer(payload, dtype=dtype).reshape(shape).copy()


def _load_error(type_name: str, message: str, spec: str) -> Exception:
    """The parent-side exception for a load failure reported by a worker."""
    kinds = {
        "UnknownDenoiserError": registry.UnknownDenoiserError,
        "UnknownOptionError": registry.UnknownOptionError,
        "DenoiserLoadError": registry.DenoiserLoadError,
    }
    if type_name in kinds:
        return kinds[type_name](message)
    return registry.DenoiserLoadError(f"cannot load {spec!r}: {type_name}: {message}")


def sandboxed(policy: str = DEFAULT_POLICY) -> bool:
    """Whether ``policy`` puts isolated denoisers into the sandbox (every policy but process/none)."""
    return policy in SANDBOXED_POLICIES


def isolation_text(config: dict, versions: dict) -> str:
    """The report's sentence on how a run's denoisers were confined (from its config and versions)."""
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


def isolated(spec: str, policy: str = DEFAULT_POLICY) -> bool:
    """Whether ``spec`` runs in a worker under ``policy``."""
    if policy not in POLICIES:
        raise UserInputError(f"--isolation must be one of {', '.join(POLICIES)} (got {policy!r})")
    if policy == "none":
        return False
    return policy == "all" or spec.strip() not in BUILTINS


def load(spec: str, options: dict | None = None, *, policy: str = DEFAULT_POLICY, limits: Limits | None = None):
    """The denoiser ``spec`` names: in this process or isolated, by ``policy`` (module docstring).

    Raises what :func:`~.registry.load_denoiser` raises (UnknownDenoiserError, UnknownOptionError,
    DenoiserLoadError), also when the failure happened in a worker.
    """
    if isolated(spec, policy):
        return IsolatedDenoiser(spec.strip(), options, limits, sandboxed=sandboxed(policy))
    return load_denoiser(spec, **(options or {}))


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
        help=f"per-call time limit of an isolated denoiser (default {DEFAULT_TIME_LIMIT:g})",
    )
    parser.add_argument(
        "--memory-limit",
        type=int,
        default=DEFAULT_MEMORY_LIMIT_MB,
        metavar="MIB",
        help=f"resident-memory limit of an isolated denoiser's worker in MiB (default {DEFAULT_MEMORY_LIMIT_MB})",
    )


def limits_from_args(args) -> Limits:
    return Limits(float(args.time_limit), int(args.memory_limit))
