"""The denoisers' side of isolation: the Denoiser protocol across a worker process.

:func:`load` is how the benchmark and ``check-plugin`` construct denoisers. Under the default
policy (``"plugins"``) a built-in (:data:`~.registry.BUILTINS`, code of this package) is constructed
in this process, and everything else (an entry point, a ``module:attr`` or ``file.py:attr`` spec) in
an :class:`IsolatedDenoiser`: a proxy that speaks the Denoiser protocol and forwards every call to a
worker process that imported and constructed the plugin there (:class:`DenoiserService`). ``"all"``
isolates the built-ins too (one worker each); ``"none"`` runs everything in this process (trusted code
only). The shell (worker process, sandbox, :class:`~denoisebench.plugins.Limits`, the one failure type
:class:`~denoisebench.plugins.PluginFailure`, the policies) is :mod:`denoisebench.plugins`; this module
holds what is the denoisers' own: the requests, the replies and what they carry.

What isolation gives
--------------------
* **Exits and crashes are contained.** ``sys.exit()``, ``os._exit()``, a segfault or a kill of
  the worker fails the call with the reason (``worker exited with status 3``, ``worker killed by
  SIGSEGV``); the benchmark records it and goes on. The next ``reset()`` (the next sequence)
  starts a fresh worker and loads the plugin again. A plugin that raises fails the call with its
  one-line error, and the :class:`~denoisebench.plugins.PluginFailure` carries its traceback.
* **Time limit** (``Limits.time_limit`` seconds per call of load, ``reset()`` or ``denoise()``): a
  call that runs over is failed, the worker killed, and the denoiser is **disabled** for the rest of
  this process, so a hanging plugin costs one time limit per run, not one per frame.
* **Memory limit** (``Limits.memory_limit_mb`` MiB of resident memory of the worker): the parent
  reads the worker's RSS from ``/proc`` every :data:`~denoisebench.plugins.process.POLL_SECONDS`
  while it waits and kills it when over. Address space that is reserved but not touched does not
  count; a very fast allocation may overshoot by what it touches in one poll.
* **Copies.** The frame reaches the worker through a shared memory file (:mod:`.shared_frames`;
  pickled through the pipe where ``memfd_create`` is missing) and the worker copies it into arrays
  of its own: making an input writable and changing it reaches nothing outside the worker.
* **No reference.** The harness hands over the frame after :func:`~.runner.sanitize_frame`, which
  withholds the reference image and every ``reference*`` and file-path entry of ``meta``.
* **Sandbox** (policies ``plugins`` and ``all``; :mod:`denoisebench.plugins.sandbox`): no host files
  but the Python environment, ``sys.path``, the plugin's folder and its option files (read-only), no
  network, no way to outlive the worker, resource limits. Where no sandbox starts, the proxy is
  refused (:class:`~denoisebench.plugins.SandboxUnavailableError`); ``process`` is a plain worker.
* **Replies are not unpickled.** The worker answers with a JSON header and raw array bytes, so a
  plugin cannot run code in the harness through its output.

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
from typing import Any

import numpy as np

from denoisebench.denoisers import registry, shared_frames
from denoisebench.denoisers.protocol import describe
from denoisebench.denoisers.registry import BUILTINS, DenoiserLoadError, load_denoiser
from denoisebench.plugins import Limits, PluginFailure, PluginProxy, proxy
from denoisebench.plugins.worker import failure, reply

#: dtype kinds an output may arrive with (the harness then checks it is float32).
_ARRAY_KINDS = "fiub"


class IsolatedDenoiser(PluginProxy):
    """A denoiser living in a worker process; see the module docstring.

    ``name``, ``needs``, ``temporal`` and ``trained_scenes`` are what the worker's instance declared.
    ``last_seconds`` is the time inside the worker's ``denoise()`` of the last call,
    ``overhead_seconds`` the total time spent around those calls (transfer, checks).
    """

    noun = "denoiser"
    service = "denoisebench.denoisers.isolation:DenoiserService"
    load_errors = {
        "UnknownDenoiserError": registry.UnknownDenoiserError,
        "UnknownOptionError": registry.UnknownOptionError,
        "DenoiserLoadError": registry.DenoiserLoadError,
    }
    load_error = DenoiserLoadError

    def __init__(self, spec: str, options: dict | None = None, limits: Limits | None = None, sandboxed: bool = True):
        super().__init__(spec, options, limits, sandboxed=sandboxed)
        self.last_seconds: float | None = None
        self.overhead_seconds = 0.0
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

    def _start(self) -> dict:
        if self._channel is None:
            return self.start()
        return self.start((str(self._channel.fd),), (self._channel.fd,))

    def check_payload(self, header: dict, max_bytes: int) -> str | None:
        """An array larger than the frame's H×W×3 float64 is refused unread."""
        if header.get("kind") != "array":
            return None
        try:
            shape = tuple(int(n) for n in header.get("shape", ()))
            declared = int(np.prod(shape, dtype=np.int64)) * np.dtype(str(header.get("dtype"))).itemsize
        except (TypeError, ValueError) as error:
            return f"malformed message from the worker ({type(error).__name__})"
        if declared > max_bytes:
            return f"returned shape {shape}, expected H×W×3 of the frame; worker killed"
        return None

    def _call(self, message: tuple, what: str, max_bytes: int = 0) -> tuple[dict, bytes | None]:
        """One request and its reply; a failure breaks the worker for the rest of the sequence."""
        self._ready()
        try:
            self.send(message)
            return self.receive(what, max_bytes)
        except PluginFailure as failed:
            self._broken = self._broken or str(failed)
            raise

    def _ready(self) -> None:
        self.check_enabled()
        if self._broken:
            raise PluginFailure(f"{self._broken} earlier in this sequence")

    # ------------------------------------------------------------------ protocol

    def reset(self) -> None:
        """Start of a sequence: a dead worker is replaced (plugin loaded afresh), then its reset()."""
        self.check_enabled()
        if self._broken or not self.running:
            self._broken = None
            try:
                self._start()
            except Exception as error:  # noqa: BLE001 - a plugin that no longer loads fails the sequence
                self._broken = f"restart after a failure: {error}"
                raise PluginFailure(self._broken) from None
        header, _ = self._call(("reset",), "reset()")
        if not header.get("ok"):
            raise proxy.failure_from(header, "reset() failed")

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
            raise proxy.failure_from(header, "denoise() failed")
        output = _rebuild(header, payload, self._channel if header.get("in_shm") and descriptor else None, descriptor)
        self.overhead_seconds += time.perf_counter() - started - (self.last_seconds or 0.0)
        return output

    def __del__(self) -> None:
        channel = getattr(self, "_channel", None)
        if channel is not None:
            channel.close()


def _rebuild(header: dict, payload: bytes | None, channel=None, descriptor=None):
    if header.get("kind") != "array":
        # a stand-in whose type name is what the plugin returned: the output check names it
        return type(str(header.get("type", "object"))[:80], (), {})()
    try:
        dtype = np.dtype(str(header["dtype"]))
        shape = tuple(int(n) for n in header["shape"])
    except (KeyError, TypeError, ValueError) as error:
        raise PluginFailure(f"malformed output description from the worker ({error})") from None
    if dtype.kind not in _ARRAY_KINDS or dtype.hasobject or any(n < 0 for n in shape) or len(shape) > 8:
        raise PluginFailure(f"output of dtype {dtype} and shape {shape} refused")
    expected = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    if channel is not None:
        output = channel.read_output(descriptor, dtype, shape)
        if output is None:
            raise PluginFailure(f"returned shape {shape} ({dtype}), which does not fit the harness's size bound")
        return output
    if payload is None or len(payload) != expected:
        raise PluginFailure(f"returned shape {shape} ({dtype}), which does not fit the harness's size bound")
    return np.frombuffer(payload, dtype=dtype).reshape(shape).copy()


class DenoiserService:
    """The worker's side (:mod:`denoisebench.plugins.worker`): one denoiser, its calls served.

    Requests: ``("reset",)``, ``("denoise", frame)`` (the frame pickled), ``("denoise_shm",
    descriptor)`` (the frame in the shared memory file ``memfd``, :mod:`.shared_frames`). A reply is a
    JSON header, and for an array output the array's raw bytes (or the array written into the shared
    file, ``in_shm``): the parent rebuilds it from a whitelisted dtype and a shape whose size must match.
    """

    def __init__(self, conn, memfd: str | None = None):
        self.conn = conn
        self.view = shared_frames.WorkerView(int(memfd)) if memfd is not None else None
        self.denoiser = None

    def load(self, spec: str, options: dict) -> dict:
        self.denoiser = load_denoiser(spec, **options)
        info = describe(self.denoiser, fallback_name=spec)
        return {
            "name": str(info.name),
            "needs": sorted(str(n) for n in info.needs),
            "temporal": bool(info.temporal),
            "trained_scenes": sorted(info.trained_scenes),
        }

    def handle(self, message: tuple) -> None:
        op = message[0]
        if op == "reset":
            reset = getattr(self.denoiser, "reset", None)
            try:
                if callable(reset):
                    reset()
            except BaseException as error:  # noqa: BLE001 - SystemExit included: contained and reported
                reply(self.conn, {"ok": False, **failure(error, "reset() raised ")})
                return
            reply(self.conn, {"ok": True})
        elif op == "denoise":
            self._denoise(message[1])
        elif op == "denoise_shm" and self.view is not None:
            self._denoise(self.view.unpack(message[1]), message[1])
        else:
            reply(self.conn, {"ok": False, "error": f"unknown request {op!r}"})

    def _denoise(self, frame, descriptor=None) -> None:
        for array in list(frame.buffers.values()) + list((frame.samples or {}).values()):
            array.flags.writeable = False  # the same contract as in-process; these are this process's copies
        started = time.perf_counter()
        try:
            output = self.denoiser.denoise(frame)
        except BaseException as error:  # noqa: BLE001 - SystemExit included: contained and reported
            reply(self.conn, {"ok": False, "seconds": time.perf_counter() - started, **failure(error, "raised ")})
            return
        seconds = time.perf_counter() - started
        if not isinstance(output, np.ndarray):
            reply(self.conn, {"ok": True, "seconds": seconds, "kind": "other", "type": type(output).__name__})
            return
        if output.dtype.kind not in _ARRAY_KINDS or output.dtype.hasobject:
            kind = f"ndarray of dtype {output.dtype}"
            reply(self.conn, {"ok": True, "seconds": seconds, "kind": "other", "type": kind})
            return
        plain = np.ascontiguousarray(output)
        header = {"ok": True, "seconds": seconds, "kind": "array", "dtype": plain.dtype.str, "shape": list(plain.shape)}
        if self.view is not None and descriptor is not None and self.view.write_output(descriptor, plain):
            reply(self.conn, {**header, "in_shm": True})
            return
        reply(self.conn, header, memoryview(plain).cast("B") if plain.size else b"")


def isolated(spec: str, policy: str = proxy.DEFAULT_POLICY) -> bool:
    """Whether ``spec`` runs in a worker under ``policy``."""
    return proxy.isolated(spec, policy, BUILTINS)


def load(spec: str, options: dict | None = None, *, policy: str = proxy.DEFAULT_POLICY, limits: Limits | None = None):
    """The denoiser ``spec`` names: in this process or isolated, by ``policy`` (module docstring).

    Raises what :func:`~.registry.load_denoiser` raises (UnknownDenoiserError, UnknownOptionError,
    DenoiserLoadError), also when the failure happened in a worker.
    """
    if isolated(spec, policy):
        return IsolatedDenoiser(spec.strip(), options, limits, sandboxed=proxy.sandboxed(policy))
    return load_denoiser(spec, **(options or {}))
