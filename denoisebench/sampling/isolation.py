"""Run plugin samplers in a worker process of their own, with a time and a memory limit.

:func:`load` is how the benchmark and ``check-plugin --sampler`` construct samplers. Under the default
policy (``"plugins"``) a built-in (:data:`~.registry.BUILTINS`) runs in this process, and everything
else (an entry point, ``module:attr``, ``file.py:attr``) in an :class:`IsolatedSampler`: a proxy whose
``sample(budget, rounds)`` runs the plugin in a worker (:mod:`.isolation_worker`) against a proxy
handle, every round request crossing the process boundary to the real
:class:`~denoisebench.sampling.harness.RoundHandle` here, which renders it and enforces the budget.
``"all"`` isolates the built-ins too; ``"none"`` runs everything in this process.

What isolation gives
--------------------
* ``sys.exit()``, ``os._exit()``, a crash or a kill of the worker fails that frame's run with the
  reason (the harness records it, with the rounds rendered so far); the next ``sample`` starts a
  fresh worker.
* **Time limit** (``time_limit`` seconds, default :data:`DEFAULT_TIME_LIMIT`) on every wait for the
  worker: its load, and each stretch of decisions between two of its requests. Over it, the worker
  is killed and the sampler disabled for the rest of this process.
* **Memory limit** (``memory_limit_mb`` MiB of the worker's resident memory, polled every
  :data:`POLL_SECONDS`).
* The worker's messages are JSON and raw bytes, never unpickled: a count map is rebuilt from a
  whitelisted dtype and a shape that must be the frame's.

Notes
-----
* Decision seconds are measured here, so a plugin's include the transfer of every round's buffers
  to its worker and of its request back (the isolation's cost is the sampler's cost).
* This is process isolation, not the denoisers' sandbox (``denoisers/sandbox.py``): the worker runs
  as the same user; the layering keeps ``sampling`` from importing ``denoisers``, whose worker answers
  one call per request, where a sampler calls back into the renderer every round.
"""

from __future__ import annotations

import atexit
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np

from denoisebench.errors import UserInputError
from denoisebench.sampling.protocol import BudgetExhausted, SamplerRequestError

DEFAULT_TIME_LIMIT = 120.0
DEFAULT_MEMORY_LIMIT_MB = 4096
POLL_SECONDS = 0.02
POLICIES = ("plugins", "all", "none")


class SamplerWorkerError(RuntimeError):
    """The isolated sampler failed; the message is the one-line reason."""


_LIVE: set = set()


@atexit.register
def _close_all() -> None:
    for proxy in list(_LIVE):
        proxy.close()


def _rss_mb(pid: int) -> float | None:
    try:
        with open(f"/proc/{pid}/statm", "rb") as handle:
            return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return None


def _exit_reason(code: int | None) -> str:
    if code is None:
        return "worker stopped answering"
    if code < 0:
        try:
            return f"worker killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"worker killed by signal {-code}"
    return f"worker exited with status {code} (sys.exit/os._exit or a crash in the sampler)"


class IsolatedSampler:
    """A sampler living in a worker process (module docstring); ``name`` is what the worker's instance declared."""

    def __init__(self, spec: str, options: dict | None = None, *, time_limit=None, memory_limit_mb=None):
        self.spec, self.options = spec, dict(options or {})
        self.time_limit = float(time_limit or DEFAULT_TIME_LIMIT)
        self.memory_limit_mb = int(memory_limit_mb or DEFAULT_MEMORY_LIMIT_MB)
        self._proc = None
        self._conn = None
        self._disabled: str | None = None
        self.name = self._start()

    def _start(self) -> str:
        from multiprocessing import Pipe

        from denoisebench.sampling.registry import SamplerLoadError, UnknownSamplerError

        ours, theirs = Pipe(duplex=True)
        command = [sys.executable, "-m", "denoisebench.sampling.isolation_worker", str(theirs.fileno())]
        try:
            self._proc = subprocess.Popen(
                command,
                pass_fds=(theirs.fileno(),),
                stdin=subprocess.DEVNULL,
                stdout=sys.__stderr__.fileno() if sys.__stderr__ is not None else subprocess.DEVNULL,
                close_fds=True,
            )
        finally:
            theirs.close()
        self._conn = ours
        _LIVE.add(self)
        self._conn.send(("load", self.spec, self.options, list(sys.path)))
        try:
            header, _ = self._receive("load", 0)
        except SamplerWorkerError as failure:
            raise SamplerLoadError(f"cannot load sampler {self.spec!r} in its worker: {failure}") from None
        if not header.get("ok"):
            self.close()
            kind = UnknownSamplerError if header.get("error_type") == "UnknownSamplerError" else SamplerLoadError
            raise kind(str(header.get("error", "load failed")).removeprefix(f"{header.get('error_type')}: "))
        return str(header.get("name") or self.spec)

    def _kill(self, reason: str) -> str:
        if self._proc is not None and self._proc.poll() is None:
            self._proc.kill()
            self._proc.wait(timeout=10)
        self.close()
        return reason

    def close(self) -> None:
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

    def _receive(self, what: str, max_bytes: int) -> tuple[dict, bytes | None]:
        """The worker's next message under the limits; SamplerWorkerError on any breach."""
        deadline = time.monotonic() + self.time_limit
        while True:
            try:
                if self._conn.poll(POLL_SECONDS):
                    break
            except (OSError, ValueError):
                break
            code = self._proc.poll()
            if code is not None:
                raise SamplerWorkerError(self._kill(_exit_reason(code)))
            rss = _rss_mb(self._proc.pid)
            if rss is not None and rss > self.memory_limit_mb:
                raise SamplerWorkerError(
                    self._kill(f"exceeded the memory limit ({rss:.0f} MiB > {self.memory_limit_mb} MiB) in {what}")
                )
            if time.monotonic() > deadline:
                self._disabled = (
                    f"exceeded the time limit ({self.time_limit:g} s) in {what}; worker killed, sampler disabled"
                )
                raise SamplerWorkerError(self._kill(self._disabled))
        try:
            header = json.loads(self._conn.recv_bytes(1 << 16).decode("utf-8"))
            if not isinstance(header, dict):
                raise ValueError("not an object")
            payload = self._conn.recv_bytes(max_bytes + 1) if header.get("payload") else None
        except (EOFError, OSError, ValueError, TypeError, UnicodeDecodeError) as error:
            code = self._proc.wait(timeout=2) if self._proc is not None else None
            reason = _exit_reason(code) if code is not None else f"malformed message ({type(error).__name__})"
            raise SamplerWorkerError(self._kill(reason)) from None
        return header, payload

    def _counts(self, header: dict, payload: bytes | None, shape: tuple[int, int]) -> np.ndarray:
        try:
            dtype = np.dtype(str(header["dtype"]))
            asked = tuple(int(n) for n in header["shape"])
        except (KeyError, TypeError, ValueError):
            raise SamplerRequestError("malformed round request") from None
        if dtype.kind not in "iuf" or dtype.hasobject or asked != shape:
            raise SamplerRequestError(f"a round is an H×W = {shape[0]}×{shape[1]} map, got {asked} of {dtype}")
        if payload is None or len(payload) != int(np.prod(shape)) * dtype.itemsize:
            raise SamplerRequestError("a round request whose bytes do not match its shape")
        return np.frombuffer(payload, dtype=dtype).reshape(shape).copy()

    def sample(self, budget, rounds) -> None:
        """Run the plugin's ``sample`` in the worker, serving its requests with ``rounds``."""
        if self._disabled:
            raise SamplerWorkerError(self._disabled)
        if self._conn is None:
            self.name = self._start()
        shape = (rounds.height, rounds.width)
        self._conn.send(("sample", budget.spp, budget.seconds, rounds.width, rounds.height))
        while True:
            header, payload = self._receive("sample()", shape[0] * shape[1] * 8)
            op = header.get("op")
            if op == "done":
                return
            if op == "error":
                kind, message = str(header.get("error_type", "")), str(header.get("error", "failed"))
                if kind == "BudgetExhausted":
                    raise BudgetExhausted(message)
                raise SamplerWorkerError(message)
            if op == "remaining":
                self._conn.send(("value", int(rounds.remaining_samples())))
            elif op == "seconds_left":
                self._conn.send(("value", rounds.seconds_left()))
            elif op == "render":
                try:
                    latest = rounds.render(self._counts(header, payload, shape))
                except (BudgetExhausted, SamplerRequestError) as refusal:
                    self._conn.send(("refused", type(refusal).__name__, str(refusal)))
                    continue
                state = {
                    "counts": rounds.counts,
                    "cut": rounds.cut,
                    "exhausted": rounds.exhausted,
                    "round": {  # plain data: the worker need not import the renderer to read it
                        "buffers": dict(latest.buffers),
                        "counts": latest.counts,
                        "seconds": float(latest.seconds),
                        "samples": None if latest.samples is None else dict(latest.samples),
                    },
                }
                self._conn.send(("rendered", state))
            else:
                raise SamplerWorkerError(self._kill(f"unknown request {str(op)[:40]!r} from the worker"))

    def __repr__(self) -> str:
        return f"IsolatedSampler({self.spec!r}, name={self.name!r})"


def sampler_policy(denoiser_policy: str) -> str:
    """The samplers' policy for a run's ``--isolation`` (the denoisers'): ``none`` and ``all`` as they are, else ``plugins``."""
    return denoiser_policy if denoiser_policy in ("none", "all") else "plugins"


def isolated(spec: str, policy: str = "plugins") -> bool:
    from denoisebench.sampling.registry import BUILTINS

    if policy not in POLICIES:
        raise UserInputError(f"sampler isolation must be one of {', '.join(POLICIES)} (got {policy!r})")
    return policy == "all" or (policy == "plugins" and spec.strip() not in BUILTINS)


def load(spec: str, options: dict | None = None, *, policy: str = "plugins", time_limit=None, memory_limit_mb=None):
    """The sampler ``spec`` names: in this process, or in a worker by ``policy`` (module docstring)."""
    from denoisebench.sampling.registry import load_sampler

    if isolated(spec, policy):
        return IsolatedSampler(spec.strip(), options, time_limit=time_limit, memory_limit_mb=memory_limit_mb)
    return load_sampler(spec, **(options or {}))
