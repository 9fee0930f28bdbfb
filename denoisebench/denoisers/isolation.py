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
  :data:`POLL_SECONDS` while it waits and kills it when over. Address space that is reserved but
  not touched does not count; a very fast allocation may overshoot by what it touches in one poll.
* **Copies.** The frame reaches the worker through a shared memory file (:mod:`.shared_frames`;
  pickled through the pipe where ``memfd_create`` is missing) and the worker copies it into arrays
  of its own: making an input writable and changing it reaches nothing outside the worker.
* **No reference.** The harness hands over the frame after :func:`~.runner.sanitize_frame`, which
  withholds the reference image and every ``reference*`` and file-path entry of ``meta``.
* **Sandbox** (policies ``plugins`` and ``all``; :mod:`.sandbox`): the worker runs under bubblewrap,
  without the host's files (but the Python environment, ``sys.path``, the plugin and its option
  files, read-only), network or a way to outlive its worker, under resource limits
  (:meth:`Limits.rlimits`, set by the worker on itself) and a task count that a thread of the
  parent checks every :data:`TASK_POLL_SECONDS`, during calls and between them. Where no sandbox
  starts, the proxy is refused (:class:`SandboxUnavailableError`); ``process`` is a plain worker.
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

import atexit
import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from denoisebench.denoisers import sandbox, shared_frames
from denoisebench.errors import UserInputError

#: Seconds one call (load, reset or denoise) of an isolated denoiser may take.
DEFAULT_TIME_LIMIT = 120.0
#: Resident memory (MiB) an isolated denoiser's worker may hold.
DEFAULT_MEMORY_LIMIT_MB = 4096
#: How often the parent looks at the worker while it waits (seconds).
POLL_SECONDS = 0.02
#: How often a thread counts a sandbox's tasks, during and between calls (seconds).
TASK_POLL_SECONDS = 0.05
#: Tasks (processes and threads) a sandboxed worker may hold at once, itself included.
DEFAULT_PROCESS_LIMIT = 512
#: Open files of a sandboxed worker (RLIMIT_NOFILE).
DEFAULT_OPEN_FILES = 1024
#: Size of a sandboxed worker's private scratch tmpfs, and its largest file (RLIMIT_FSIZE), MiB.
DEFAULT_SCRATCH_MB = 1024
#: Address space (RLIMIT_AS, MiB) of a sandboxed worker: at least this, and 4x the memory limit.
MIN_ADDRESS_SPACE_MB = 32768
#: Who runs in a worker: "plugins" (everything but the built-ins, sandboxed), "all" (built-ins too,
#: sandboxed), "process" (plugins in plain worker processes, no sandbox), "none".
POLICIES = ("plugins", "all", "process", "none")
SANDBOXED_POLICIES = ("plugins", "all")
DEFAULT_POLICY = "plugins"
#: dtype kinds an output may arrive with (the harness then checks it is float32).
_ARRAY_KINDS = "fiub"


class WorkerFailure(Exception):
    """An isolated call failed; the message is the one-line reason recorded for it."""


class SandboxUnavailableError(UserInputError):
    """No sandbox starts on this machine; an untrusted plugin is refused (exit 2) unless the user
    accepts plain worker processes with ``--isolation process``."""


@dataclass(frozen=True)
class Limits:
    """Per-call time limit (seconds) and resident-memory limit (MiB) of an isolated denoiser, and
    the sandbox's task count, open files and scratch size (MiB; also the largest file)."""

    time_limit: float = DEFAULT_TIME_LIMIT
    memory_limit_mb: int = DEFAULT_MEMORY_LIMIT_MB
    processes: int = DEFAULT_PROCESS_LIMIT
    open_files: int = DEFAULT_OPEN_FILES
    scratch_mb: int = DEFAULT_SCRATCH_MB

    def rlimits(self) -> dict[str, int]:
        """What a sandboxed worker sets on itself before it imports the plugin (resource.RLIMIT_*).

        No address-space limit where NVIDIA devices exist: CUDA reserves terabytes of it."""
        import glob

        limits = {"NPROC": self.processes, "NOFILE": self.open_files, "FSIZE": self.scratch_mb << 20}
        if not glob.glob("/dev/nvidia[0-9]*"):
            limits["AS"] = max(MIN_ADDRESS_SPACE_MB, 4 * self.memory_limit_mb) << 20
        return limits

    def __post_init__(self) -> None:
        from denoisebench.errors import UserInputError

        if not self.time_limit > 0:
            raise UserInputError(f"--time-limit must be > 0 seconds (got {self.time_limit})")
        if not self.memory_limit_mb > 0:
            raise UserInputError(f"--memory-limit must be > 0 MiB (got {self.memory_limit_mb})")


_LIVE: set[IsolatedDenoiser] = set()


@atexit.register
def _close_all() -> None:
    for proxy in list(_LIVE):
        proxy.close()


def _rss_mb(pid: int) -> float | None:
    """Resident memory of ``pid`` in MiB (Linux /proc), or None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/statm", "rb") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return None


def _tree(root: int) -> tuple[list[int], int]:
    """The processes of the tree under ``root`` (itself first) and their task count (threads)."""
    pids, tasks, queue = [], 0, [root]
    while queue:
        pid = queue.pop(0)
        try:
            tids = os.listdir(f"/proc/{pid}/task")
        except OSError:
            continue
        pids.append(pid)
        tasks += len(tids)
        for tid in tids:
            try:
                with open(f"/proc/{pid}/task/{tid}/children", "rb") as handle:
                    queue += [int(n) for n in handle.read().split()]
            except (OSError, ValueError):
                continue
    return pids, tasks


def _exit_reason(code: int | None, sandboxed: bool = False) -> str:
    if code is None:
        return "worker stopped answering"
    if sandboxed and sandbox.exit_signal(code):  # bwrap: 128 + N for a worker ended by signal N
        code = -sandbox.exit_signal(code)
    if code < 0:
        try:
            return f"worker killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"worker killed by signal {-code}"
    return f"worker exited with status {code} (sys.exit/os._exit or a crash in the denoiser)"


class IsolatedDenoiser:
    """A denoiser living in a worker process; see the module docstring.

    ``name``, ``needs``, ``temporal`` and ``trained_scenes`` are what the worker's instance declared.
    ``last_seconds`` is the time inside the worker's ``denoise()`` of the last call,
    ``overhead_seconds`` the total time spent around those calls (transfer, checks).
    ``sandboxed``: the worker runs in the sandbox of :mod:`.sandbox` (refused with
    :class:`SandboxUnavailableError` where none starts); False is a plain worker process.
    """

    def __init__(self, spec: str, options: dict | None = None, limits: Limits | None = None, sandboxed: bool = True):
        self.spec = spec
        self.options = dict(options or {})
        self.limits = limits or Limits()
        self.sandboxed = bool(sandboxed)
        if self.sandboxed:
            reason = sandbox.unavailable_reason()
            if reason:
                raise SandboxUnavailableError(
                    f"cannot sandbox {spec!r}: {reason}; --isolation process runs plugins in plain worker "
                    "processes instead (they can then read your files and reach the network; the run records it)"
                )
        self._worker_pid: int | None = None
        self.last_seconds: float | None = None
        self.overhead_seconds = 0.0
        self._proc: subprocess.Popen | None = None
        self._conn = None
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
        from multiprocessing import Pipe

        ours, theirs = Pipe(duplex=True)
        command = [sys.executable, "-m", "denoisebench.denoisers.isolation_worker", str(theirs.fileno())]
        fds = (theirs.fileno(),)
        if self._channel is not None:
            command.append(str(self._channel.fd))
            fds += (self._channel.fd,)
        spec, options, rlimits, wrapped = self.spec, self.options, None, None
        if self.sandboxed:
            module, colon, attr = spec.partition(":")
            if colon and module.endswith(".py"):
                spec = f"{os.path.abspath(module)}:{attr}"  # the worker's folder is its scratch
            options, rlimits = sandbox.absolute_options(options), self.limits.rlimits()
            wrapped = sandbox.command(
                command, readable=sandbox.readable_paths(spec, options), scratch_bytes=self.limits.scratch_mb << 20
            )
            command, fds = wrapped.argv, fds + (wrapped.args_fd,)
        self._worker_pid = None
        try:
            self._proc = subprocess.Popen(
                command,
                pass_fds=fds,
                stdin=subprocess.DEVNULL,
                stdout=sys.__stderr__.fileno() if sys.__stderr__ is not None else subprocess.DEVNULL,
                close_fds=True,
            )
        finally:
            theirs.close()
            if wrapped is not None:
                wrapped.close()
        self._conn = ours
        self._breach = None
        if self.sandboxed:  # counted between calls too: a plugin's background forks do not wait for a call
            threading.Thread(target=self._watch_tasks, args=(self._proc,), daemon=True).start()
        _LIVE.add(self)
        try:
            header, _ = self._request(("load", spec, options, list(sys.path), rlimits), "load")
        except WorkerFailure as failure:
            from denoisebench.denoisers.registry import DenoiserLoadError

            raise DenoiserLoadError(f"cannot load {self.spec!r} in its worker: {failure}") from None
        if not header.get("ok"):
            self.close()
            raise _load_error(header.get("error_type", ""), header.get("error", "load failed"), self.spec)
        return header

    def _kill(self, reason: str) -> str:
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass
        self.close()
        return reason

    def close(self) -> None:
        """Stop the worker (a closed proxy starts a new one on the next ``reset()``)."""
        if self._conn is not None:
            try:
                if self._proc is not None and self._proc.poll() is None:
                    self._conn.send(("close",))
            except (OSError, ValueError):
                pass
            self._conn.close()
            self._conn = None
        if self._proc is not None:
            try:
                self._proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
            self._proc = None
        _LIVE.discard(self)

    def _request(self, message: tuple, what: str, max_bytes: int = 0) -> tuple[dict, bytes | None]:
        """Send ``message``; wait for the reply under the limits. WorkerFailure on any breach."""
        limit = self.limits.time_limit
        try:
            self._conn.send(message)
        except (OSError, ValueError):
            code = self._proc.poll() if self._proc else None
            raise WorkerFailure(self._kill(self._breach or _exit_reason(code, self.sandboxed))) from None
        deadline = time.monotonic() + limit
        while True:
            try:
                ready = self._conn.poll(POLL_SECONDS)
            except (OSError, ValueError):
                ready = True  # a closed pipe: recv below reports it
            if ready:
                break
            code = self._proc.poll()
            if code is not None:
                raise WorkerFailure(self._kill(self._breach or _exit_reason(code, self.sandboxed)))
            rss = _rss_mb(self._pid())
            if rss is not None and rss > self.limits.memory_limit_mb:
                raise WorkerFailure(
                    self._kill(
                        f"exceeded the memory limit ({rss:.0f} MiB > {self.limits.memory_limit_mb} MiB) in {what}; worker killed"
                    )
                )
            if time.monotonic() > deadline:
                reason = f"exceeded the time limit ({limit:g} s per call) in {what}; worker killed, denoiser disabled for this run"
                self._disabled = reason
                raise WorkerFailure(self._kill(reason))
        try:
            header = json.loads(self._conn.recv_bytes(1 << 20).decode("utf-8"))
            if not isinstance(header, dict):
                raise ValueError("reply is not an object")
            if header.get("payload") and header.get("kind") == "array":
                shape = tuple(int(n) for n in header.get("shape", ()))
                declared = int(np.prod(shape, dtype=np.int64)) * np.dtype(str(header.get("dtype"))).itemsize
                if declared > max_bytes:  # not read: the harness bounds what it takes in
                    raise WorkerFailure(
                        self._kill(f"returned shape {shape}, expected H×W×3 of the frame; worker killed")
                    )
            payload = self._conn.recv_bytes(max_bytes + 1) if header.get("payload") else None
        except (EOFError, OSError, ValueError, TypeError, UnicodeDecodeError) as error:
            code = None
            if self._proc is not None:
                try:
                    code = self._proc.wait(timeout=2)
                except subprocess.TimeoutExpired:
                    code = None
            reason = (
                self._breach or _exit_reason(code, self.sandboxed)
                if code is not None
                else f"malformed reply from the worker ({type(error).__name__})"
            )
            raise WorkerFailure(self._kill(reason)) from None
        return header, payload

    def _pid(self) -> int:
        """The worker's process id on this machine (sandboxed: the child of the sandbox's init)."""
        if not self.sandboxed or self._proc is None:
            return self._proc.pid if self._proc is not None else -1
        if self._worker_pid is None:
            pids, _ = _tree(self._proc.pid)  # bwrap, its init (PID 1 inside), the worker, ...
            if len(pids) < 3:
                return self._proc.pid
            self._worker_pid = pids[2]
        return self._worker_pid

    def _watch_tasks(self, proc: subprocess.Popen) -> None:
        """Kill the sandbox when it holds more tasks than allowed (the kernel does not enforce
        RLIMIT_NPROC for a root harness's worker); the next call reports the reason."""
        while proc.poll() is None:
            _, tasks = _tree(proc.pid)
            tasks -= 2  # bwrap and the sandbox's init
            if tasks > self.limits.processes:
                self._breach = f"exceeded the process limit ({tasks} tasks > {self.limits.processes}); sandbox killed"
                proc.kill()
                return
            time.sleep(TASK_POLL_SECONDS)

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
        if self._broken or self._conn is None:
            self._broken = None
            self._kill("restart")
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
    from denoisebench.denoisers import registry

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
    from denoisebench.denoisers.registry import BUILTINS

    if policy not in POLICIES:
        from denoisebench.errors import UserInputError

        raise UserInputError(f"--isolation must be one of {', '.join(POLICIES)} (got {policy!r})")
    if policy == "none":
        return False
    return policy == "all" or spec.strip() not in BUILTINS


def load(spec: str, options: dict | None = None, *, policy: str = DEFAULT_POLICY, limits: Limits | None = None):
    """The denoiser ``spec`` names: in this process or isolated, by ``policy`` (module docstring).

    Raises what :func:`~.registry.load_denoiser` raises (UnknownDenoiserError, UnknownOptionError,
    DenoiserLoadError), also when the failure happened in a worker.
    """
    from denoisebench.denoisers.registry import load_denoiser

    if isolated(spec, policy):
        return IsolatedDenoiser(spec.strip(), options, limits, sandboxed=sandboxed(policy))
    return load_denoiser(spec, **(options or {}))


def add_arguments(parser) -> None:
    """``--isolation``, ``--time-limit`` and ``--memory-limit`` on a command's parser."""
    parser.add_argument(
        "--isolation",
        choices=POLICIES,
        default=DEFAULT_POLICY,
        help="which denoisers run in a sandboxed worker process of their own: plugins (every non-built-in, "
        "default), all; process: plugins in plain worker processes without the sandbox (where none starts; "
        "recorded); none (trusted code only)",
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
