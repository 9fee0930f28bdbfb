"""A plugin's worker process: started plain or in the sandbox, watched while the harness waits, ended.

:class:`WorkerProcess` starts ``python -m denoisebench.plugins.worker FD SERVICE ...`` (FD one end of a
socket pair, SERVICE the protocol's worker side, :mod:`denoisebench.plugins.worker`), under bubblewrap
where ``sandboxed`` (:mod:`denoisebench.plugins.sandbox`: none of the host's files but Python,
``sys.path``, the plugin and its option files, read-only; no network; a private scratch), and while
the harness waits for a message it watches the worker's exit, its resident memory (polled every
:data:`POLL_SECONDS`) and a time limit (:class:`Limits`). A sandboxed worker's tasks are counted by a
thread every :data:`TASK_POLL_SECONDS`, during waits and between them. Every breach ends the worker and
raises :class:`WorkerGone` with a one-line reason. The proxies speak to it through
:class:`denoisebench.plugins.proxy.PluginProxy`.

Notes
-----
* The parent is trusted and the worker is not: the parent may pickle what it sends, but reads only
  JSON headers and raw bytes back (:meth:`WorkerProcess.receive_header`,
  :meth:`WorkerProcess.receive_payload`), so nothing a plugin does can run code in the harness.
* The worker sets the :func:`rlimits` on itself (:func:`set_rlimits`) before it imports the plugin:
  soft and hard, so the plugin may lower them but never raise them again.
* A sandboxed worker's process is the grandchild of the harness (bwrap, the sandbox's init, the
  worker): its memory is read from that process, not from bwrap's.
"""

from __future__ import annotations

import atexit
import glob
import json
import os
import resource
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from multiprocessing import Pipe

from denoisebench.errors import UserInputError
from denoisebench.interrupts import raise_if_requested
from denoisebench.plugins import sandbox

#: How often the parent looks at the worker while it waits (seconds).
POLL_SECONDS = 0.02
#: How often a thread counts a sandbox's tasks, during and between waits (seconds).
TASK_POLL_SECONDS = 0.05
#: Tasks (processes and threads) a sandboxed worker may hold at once, itself included.
DEFAULT_PROCESS_LIMIT = 512
#: Open files of a sandboxed worker (RLIMIT_NOFILE).
DEFAULT_OPEN_FILES = 1024
#: Size of a sandboxed worker's private scratch tmpfs, and its largest file (RLIMIT_FSIZE), MiB.
DEFAULT_SCRATCH_MB = 1024
#: Address space (RLIMIT_AS, MiB) of a sandboxed worker: at least this, and 4x the memory limit.
MIN_ADDRESS_SPACE_MB = 32768
#: Seconds one wait for a plugin's worker may take (a denoiser's call, a sampler's stretch of decisions).
DEFAULT_TIME_LIMIT = 120.0
#: Resident memory (MiB) a plugin's worker may hold.
DEFAULT_MEMORY_LIMIT_MB = 4096
#: The module run as the worker process.
WORKER_MODULE = "denoisebench.plugins.worker"


@dataclass(frozen=True)
class Limits:
    """A plugin worker's limits: time of one wait (seconds), resident memory (MiB), and the sandbox's
    task count, open files and scratch size (MiB; also the largest file). The same for every plugin kind."""

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


class WorkerGone(Exception):
    """The worker broke a limit, exited or sent garbage, and is ended; the message is the one-line reason.

    ``timed_out``: it ran over the time limit (the callers then disable the plugin for the process).
    """

    def __init__(self, reason: str, timed_out: bool = False):
        super().__init__(reason)
        self.timed_out = timed_out


class SandboxUnavailableError(UserInputError):
    """No sandbox starts on this machine; an untrusted plugin is refused (exit 2) unless the user
    accepts plain worker processes with ``--isolation process``."""


def require_sandbox(spec: str) -> None:
    """SandboxUnavailableError (one line, naming ``spec`` and the way out) where no sandbox starts here."""
    reason = sandbox.unavailable_reason()
    if reason:
        raise SandboxUnavailableError(
            f"cannot sandbox {spec!r}: {reason}; --isolation process runs plugins in plain worker "
            "processes instead (they can then read your files and reach the network; the run records it)"
        )


_LIVE: set[WorkerProcess] = set()


@atexit.register
def _close_all() -> None:
    for worker in list(_LIVE):
        worker.close()


def rlimits(processes: int, open_files: int, scratch_mb: int, memory_limit_mb: int) -> dict[str, int]:
    """What a sandboxed worker sets on itself before it imports the plugin (``resource.RLIMIT_*`` names).

    No address-space limit where NVIDIA devices exist: CUDA reserves terabytes of it."""
    limits = {"NPROC": processes, "NOFILE": open_files, "FSIZE": scratch_mb << 20}
    if not glob.glob("/dev/nvidia[0-9]*"):
        limits["AS"] = max(MIN_ADDRESS_SPACE_MB, 4 * memory_limit_mb) << 20
    return limits


def set_rlimits(limits: dict[str, int] | None) -> None:
    """In the worker: set each ``RLIMIT_<name>`` of ``limits``, soft and hard (never above the hard limit)."""
    for name, value in (limits or {}).items():
        kind = getattr(resource, f"RLIMIT_{name}")
        _, hard = resource.getrlimit(kind)
        value = int(value) if hard == resource.RLIM_INFINITY else min(int(value), hard)
        resource.setrlimit(kind, (value, value))


def confined_spec(spec: str, options: dict) -> tuple[str, dict]:
    """``spec`` and ``options`` with every file path made absolute: a sandboxed worker's folder is its scratch."""
    module, colon, attr = spec.rpartition(":") if spec.count(":") > 1 else spec.partition(":")
    if colon and module.endswith(".py"):
        spec = f"{os.path.abspath(module)}:{attr}"
    return spec, sandbox.absolute_options(options)


def rss_mb(pid: int) -> float | None:
    """Resident memory of ``pid`` in MiB (Linux /proc), or None where it cannot be read."""
    try:
        with open(f"/proc/{pid}/statm", "rb") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return None


def tree(root: int) -> tuple[list[int], int]:
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


def exit_reason(code: int | None, sandboxed: bool = False, noun: str = "plugin") -> str:
    """A worker's exit status in words (bwrap reports a worker ended by signal N as 128 + N)."""
    if code is None:
        return "worker stopped answering"
    if sandboxed and sandbox.exit_signal(code):
        code = -sandbox.exit_signal(code)
    if code < 0:
        try:
            return f"worker killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"worker killed by signal {-code}"
    return f"worker exited with status {code} (sys.exit/os._exit or a crash in the {noun})"


class WorkerProcess:
    """``python -m denoisebench.plugins.worker FD service *args``, the socket pair's other end as ``conn``.

    ``service`` (``"module:Class"``) is the protocol's worker side (:mod:`denoisebench.plugins.worker`);
    ``noun`` names the plugin in reasons (``denoiser disabled``); ``spec`` and ``options`` decide what
    a sandboxed worker may read, and are kept as the worker must be told them (:meth:`load_message`:
    paths absolute under the sandbox, with the :func:`rlimits` of ``limits``); ``fds`` are passed on.
    """

    def __init__(
        self,
        service: str,
        *,
        noun: str,
        sandboxed: bool,
        limits: Limits,
        spec: str = "",
        options: dict | None = None,
        args: tuple[str, ...] = (),
        fds: tuple[int, ...] = (),
    ):
        self.noun, self.sandboxed, self.processes = noun, bool(sandboxed), int(limits.processes)
        self.spec, self.options, self.rlimits = spec, dict(options or {}), None
        if self.sandboxed:
            self.spec, self.options = confined_spec(spec, self.options)
            self.rlimits = rlimits(
                self.processes, int(limits.open_files), int(limits.scratch_mb), int(limits.memory_limit_mb)
            )
        scratch_mb = int(limits.scratch_mb)
        self.breach: str | None = None  # why the task watcher killed the sandbox
        self._worker_pid: int | None = None
        ours, theirs = Pipe(duplex=True)
        command = [sys.executable, "-m", WORKER_MODULE, str(theirs.fileno()), service, *args]
        fds = (theirs.fileno(), *fds)
        wrapped = None
        if self.sandboxed:
            wrapped = sandbox.command(
                command, readable=sandbox.readable_paths(self.spec, self.options), scratch_bytes=int(scratch_mb) << 20
            )
            command, fds = wrapped.argv, (*fds, wrapped.args_fd)
        try:
            self.proc = subprocess.Popen(
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
        self.conn = ours
        _LIVE.add(self)
        if self.sandboxed:  # counted between waits too: a plugin's background forks do not wait for a call
            threading.Thread(target=self._watch_tasks, args=(self.proc,), daemon=True).start()

    def load_message(self) -> tuple:
        """``("load", spec, options, sys_path, rlimits)``: what every worker is first told."""
        return ("load", self.spec, self.options, list(sys.path), self.rlimits)

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def pid(self) -> int:
        """The worker's process id on this machine (sandboxed: the child of the sandbox's init)."""
        if self.proc is None:
            return -1
        if not self.sandboxed:
            return self.proc.pid
        if self._worker_pid is None:
            pids, _ = tree(self.proc.pid)  # bwrap, its init (PID 1 inside), the worker, ...
            if len(pids) < 3:
                return self.proc.pid
            self._worker_pid = pids[2]
        return self._worker_pid

    def _watch_tasks(self, proc: subprocess.Popen) -> None:
        """Kill the sandbox when it holds more tasks than allowed (the kernel does not enforce
        RLIMIT_NPROC for a root harness's worker); the next wait reports the reason."""
        while proc.poll() is None:
            _, tasks = tree(proc.pid)
            tasks -= 2  # bwrap and the sandbox's init
            if tasks > self.processes:
                self.breach = f"exceeded the process limit ({tasks} tasks > {self.processes}); sandbox killed"
                proc.kill()
                return
            time.sleep(TASK_POLL_SECONDS)

    def _ended(self, code: int | None) -> WorkerGone:
        return WorkerGone(self.kill(self.breach or exit_reason(code, self.sandboxed, self.noun)))

    def send(self, message) -> None:
        """Send a (pickled) message to the worker; WorkerGone where it has gone."""
        try:
            self.conn.send(message)
        except (OSError, ValueError, AttributeError):
            raise self._ended(self.proc.poll() if self.proc is not None else None) from None

    def wait(self, what: str, time_limit: float, memory_limit_mb: float) -> None:
        """Return when a message is there; WorkerGone on an exit, the memory limit or the time limit."""
        deadline = time.monotonic() + time_limit
        while True:
            try:
                if self.conn.poll(POLL_SECONDS):
                    return
            except (OSError, ValueError):
                return  # a closed pipe: the read reports it
            raise_if_requested()  # an interrupt (not the plugin) is why this call ends
            code = self.proc.poll()
            if code is not None:
                raise self._ended(code)
            rss = rss_mb(self.pid())
            if rss is not None and rss > memory_limit_mb:
                raise WorkerGone(
                    self.kill(
                        f"exceeded the memory limit ({rss:.0f} MiB > {memory_limit_mb} MiB) in {what}; worker killed"
                    )
                )
            if time.monotonic() > deadline:
                reason = f"exceeded the time limit ({time_limit:g} s per call) in {what}; worker killed, "
                raise WorkerGone(self.kill(reason + f"{self.noun} disabled for this run"), timed_out=True)

    def receive_header(self, what: str, time_limit: float, memory_limit_mb: float, max_bytes: int = 1 << 20) -> dict:
        """The worker's next JSON header, waited for under the limits (:meth:`wait`)."""
        self.wait(what, time_limit, memory_limit_mb)
        try:
            header = json.loads(self.conn.recv_bytes(max_bytes).decode("utf-8"))
            if not isinstance(header, dict):
                raise ValueError("not an object")
        except (EOFError, OSError, ValueError, TypeError, UnicodeDecodeError) as error:
            raise self._gone_after(error) from None
        return header

    def receive_payload(self, max_bytes: int) -> bytes:
        """The raw bytes that follow a header with ``payload`` (at most ``max_bytes``)."""
        try:
            return self.conn.recv_bytes(max_bytes + 1)
        except (EOFError, OSError, ValueError) as error:
            raise self._gone_after(error) from None

    def _gone_after(self, error: Exception) -> WorkerGone:
        """A failed read: the worker's exit (waited for a little), else a malformed message."""
        code = None
        if self.proc is not None:
            try:
                code = self.proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                code = None
        if code is not None:
            return self._ended(code)
        return WorkerGone(self.kill(f"malformed message from the worker ({type(error).__name__})"))

    def kill(self, reason: str) -> str:
        """End the worker at once; returns ``reason`` (for the caller's exception)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                pass
        self.close()
        return reason

    def close(self) -> None:
        """Ask the worker to stop (``("close",)``), wait a little, then kill it."""
        if self.conn is not None:
            try:
                if self.proc is not None and self.proc.poll() is None:
                    self.conn.send(("close",))
            except (OSError, ValueError):
                pass
            self.conn.close()
            self.conn = None
        if self.proc is not None:
            try:
                self.proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
            self.proc = None
        _LIVE.discard(self)
