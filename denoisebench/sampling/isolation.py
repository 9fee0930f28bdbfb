"""Run plugin samplers in a sandboxed worker process of their own, with a time and a memory limit.

:func:`load` is how the benchmark and ``check-plugin --sampler`` construct samplers. Under the default
policy (``"plugins"``) a built-in (:data:`~denoisebench.sampling.registry.BUILTINS`) runs in this
process, and everything else (an entry point, ``module:attr``, ``file.py:attr``) in an
:class:`IsolatedSampler`: a proxy whose ``sample(budget, rounds)`` runs the plugin in a worker
(:mod:`denoisebench.sampling.isolation_worker`) against a proxy handle, every round request crossing
the process boundary to the real :class:`~denoisebench.sampling.harness.RoundHandle` here, which
renders it and enforces the budget. ``"all"`` isolates the built-ins too; ``"process"`` runs plugins
in plain (unsandboxed) workers; ``"none"`` runs everything in this process. The names are the
denoisers' ``--isolation`` policies, with the same meaning.

What isolation gives
--------------------
* **Sandbox** (``plugins`` and ``all``; :mod:`denoisebench.sandbox`): the worker runs under
  bubblewrap, as the denoisers' workers do. Rendering happens here, in the harness; the worker only
  decides the rounds, so it needs, and sees, nothing of the host but the Python environment,
  ``sys.path``, the plugin's file and its option files (read-only): not the dataset (its reference
  EXRs, stages), the results store or the user's files (paths given to
  :func:`denoisebench.sandbox.protect` are covered even under a ``sys.path`` entry), no network,
  a private scratch ``/tmp`` as its only writable place, and the resource limits of
  :func:`denoisebench.plugin_worker.rlimits` and a task count. Where no sandbox starts, a plugin is
  refused (:class:`~denoisebench.plugin_worker.SandboxUnavailableError`, exit 2).
* ``sys.exit()``, ``os._exit()``, a crash or a kill of the worker fails that frame's run with the
  reason (the harness records it, with the rounds rendered so far); the next ``sample`` starts a
  fresh worker.
* **Time limit** (``time_limit`` seconds, default :data:`DEFAULT_TIME_LIMIT`) on every wait for the
  worker: its load, and each stretch of decisions between two of its requests. Over it, the worker
  is killed and the sampler disabled for the rest of this process.
* **Memory limit** (``memory_limit_mb`` MiB of the worker's resident memory, polled every
  :data:`~denoisebench.plugin_worker.POLL_SECONDS`).
* The worker's messages are JSON and raw bytes, never unpickled: a count map is rebuilt from a
  whitelisted dtype and a shape that must be the frame's.

Notes
-----
* Decision seconds are measured here, so a plugin's include the transfer of every round's buffers
  to its worker and of its request back (the isolation's cost is the sampler's cost).
* The worker process itself (start, sandbox, limits, end) is
  :class:`~denoisebench.plugin_worker.WorkerProcess`, shared with the denoisers' isolation; the
  protocol differs: a denoiser's worker answers one call per request, a sampler's calls back into
  the renderer every round.
"""

from __future__ import annotations

import numpy as np

from denoisebench import plugin_worker
from denoisebench.errors import UserInputError
from denoisebench.plugin_worker import WorkerGone
from denoisebench.sampling.protocol import BudgetExhausted, SamplerRequestError
from denoisebench.sampling.registry import BUILTINS, SamplerLoadError, UnknownSamplerError, load_sampler

DEFAULT_TIME_LIMIT = 120.0
DEFAULT_MEMORY_LIMIT_MB = 4096
#: Who runs in a worker (the denoisers' ``--isolation`` names): "plugins" (sandboxed), "all" (built-ins
#: too, sandboxed), "process" (plugins in plain worker processes), "none".
POLICIES = ("plugins", "all", "process", "none")
SANDBOXED_POLICIES = ("plugins", "all")
#: The largest JSON header a sampler's worker may send.
HEADER_BYTES = 1 << 16


class SamplerWorkerError(RuntimeError):
    """The isolated sampler failed; the message is the one-line reason."""


class IsolatedSampler:
    """A sampler living in a worker process (module docstring); ``name`` is what the worker's instance declared.

    ``sandboxed``: the worker runs in the sandbox of :mod:`denoisebench.sandbox` (refused with
    :class:`~denoisebench.plugin_worker.SandboxUnavailableError` where none starts); False is a
    plain worker process.
    """

    def __init__(
        self, spec: str, options: dict | None = None, *, time_limit=None, memory_limit_mb=None, sandboxed=True
    ):
        self.spec, self.options = spec, dict(options or {})
        self.time_limit = float(time_limit or DEFAULT_TIME_LIMIT)
        self.memory_limit_mb = int(memory_limit_mb or DEFAULT_MEMORY_LIMIT_MB)
        self.sandboxed = bool(sandboxed)
        if self.sandboxed:
            plugin_worker.require_sandbox(spec)
        self._worker: plugin_worker.WorkerProcess | None = None
        self._disabled: str | None = None
        self.name = self._start()

    def _start(self) -> str:

        self._worker = plugin_worker.WorkerProcess(
            "denoisebench.sampling.isolation_worker",
            noun="sampler",
            sandboxed=self.sandboxed,
            spec=self.spec,
            options=self.options,
            memory_limit_mb=self.memory_limit_mb,
        )
        try:
            self._send(self._worker.load_message())
            header, _ = self._receive("load", 0)
        except SamplerWorkerError as failure:
            raise SamplerLoadError(f"cannot load sampler {self.spec!r} in its worker: {failure}") from None
        if not header.get("ok"):
            self.close()
            kind = UnknownSamplerError if header.get("error_type") == "UnknownSamplerError" else SamplerLoadError
            raise kind(str(header.get("error", "load failed")).removeprefix(f"{header.get('error_type')}: "))
        return str(header.get("name") or self.spec)

    def close(self) -> None:
        """Stop the worker (the next ``sample`` starts a new one)."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None

    def _failed(self, gone: WorkerGone) -> SamplerWorkerError:
        """The worker has ended (WorkerProcess kills it on every breach): forget it, disable on a time-out."""
        self._worker = None
        if gone.timed_out:
            self._disabled = str(gone)
        return SamplerWorkerError(str(gone))

    def _send(self, message: tuple) -> None:
        try:
            self._worker.send(message)
        except WorkerGone as gone:
            raise self._failed(gone) from None

    def _receive(self, what: str, max_bytes: int) -> tuple[dict, bytes | None]:
        """The worker's next message under the limits; SamplerWorkerError on any breach."""
        try:
            header = self._worker.receive_header(what, self.time_limit, self.memory_limit_mb, HEADER_BYTES)
            payload = self._worker.receive_payload(max_bytes) if header.get("payload") else None
        except WorkerGone as gone:
            raise self._failed(gone) from None
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
        if self._worker is None:
            self.name = self._start()
        shape = (rounds.height, rounds.width)
        self._send(("sample", budget.spp, budget.seconds, rounds.width, rounds.height))
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
                self._send(("value", int(rounds.remaining_samples())))
            elif op == "seconds_left":
                self._send(("value", rounds.seconds_left()))
            elif op == "render":
                try:
                    latest = rounds.render(self._counts(header, payload, shape))
                except (BudgetExhausted, SamplerRequestError) as refusal:
                    self._send(("refused", type(refusal).__name__, str(refusal)))
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
                self._send(("rendered", state))
            else:
                reason = self._worker.kill(f"unknown request {str(op)[:40]!r} from the worker")
                self._worker = None
                raise SamplerWorkerError(reason)

    def __repr__(self) -> str:
        return f"IsolatedSampler({self.spec!r}, name={self.name!r})"


def sampler_policy(denoiser_policy: str) -> str:
    """The samplers' policy for a run's ``--isolation`` (the denoisers' names, the same meaning)."""
    if denoiser_policy not in POLICIES:
        raise UserInputError(f"sampler isolation must be one of {', '.join(POLICIES)} (got {denoiser_policy!r})")
    return denoiser_policy


def isolated(spec: str, policy: str = "plugins") -> bool:
    """Whether ``spec`` runs in a worker under ``policy``."""
    if policy not in POLICIES:
        raise UserInputError(f"sampler isolation must be one of {', '.join(POLICIES)} (got {policy!r})")
    return policy == "all" or (policy in ("plugins", "process") and spec.strip() not in BUILTINS)


def load(spec: str, options: dict | None = None, *, policy: str = "plugins", time_limit=None, memory_limit_mb=None):
    """The sampler ``spec`` names: in this process, or in a worker by ``policy`` (module docstring)."""
    if isolated(spec, policy):
        return IsolatedSampler(
            spec.strip(),
            options,
            time_limit=time_limit,
            memory_limit_mb=memory_limit_mb,
            sandboxed=policy in SANDBOXED_POLICIES,
        )
    return load_sampler(spec, **(options or {}))
