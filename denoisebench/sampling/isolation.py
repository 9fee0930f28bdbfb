"""The samplers' side of isolation: the Sampler protocol across a worker process.

:func:`load` is how the benchmark and ``check-plugin --sampler`` construct samplers. Under the default
policy (``"plugins"``) a built-in (:data:`~denoisebench.sampling.registry.BUILTINS`) runs in this
process, and everything else (an entry point, ``module:attr``, ``file.py:attr``) in an
:class:`IsolatedSampler`: a proxy whose ``sample(budget, rounds)`` runs the plugin in a worker
(:class:`SamplerService`) against a :class:`ProxyHandle`, every round request crossing the process
boundary to the real :class:`~denoisebench.sampling.harness.RoundHandle` here, which renders it and
enforces the budget. The policies, the :class:`~denoisebench.plugins.Limits`, the sandbox and the one
failure type (:class:`~denoisebench.plugins.PluginFailure`) are the plugin shell's
(:mod:`denoisebench.plugins`), the same as the denoisers'.

What isolation gives
--------------------
* **Sandbox** (``plugins`` and ``all``; :mod:`denoisebench.plugins.sandbox`): rendering happens here,
  in the harness; the worker only decides the rounds, so it needs, and sees, nothing of the host but
  the Python environment, ``sys.path``, the plugin's folder and its option files (read-only): not the
  dataset (its reference EXRs, stages), the results store or the user's files, no network, a private
  scratch ``/tmp`` as its only writable place, resource limits and a task count. Where no sandbox
  starts, a plugin is refused (:class:`~denoisebench.plugins.SandboxUnavailableError`, exit 2).
* ``sys.exit()``, ``os._exit()``, a crash or a kill of the worker fails that frame's run with the
  reason (the harness records it, with the rounds rendered so far); the next ``sample`` starts a
  fresh worker.
* **Time limit** (``Limits.time_limit`` seconds) on every wait for the worker: its load, and each
  stretch of decisions between two of its requests. Over it, the worker is killed and the sampler
  disabled for the rest of this process.
* **Memory limit** (``Limits.memory_limit_mb`` MiB of the worker's resident memory).
* The worker's messages are JSON and raw bytes, never unpickled: a count map is rebuilt from a
  whitelisted dtype and a shape that must be the frame's.

Notes
-----
* Decision seconds are measured here, so a plugin's include the transfer of every round's buffers
  to its worker and of its request back (the isolation's cost is the sampler's cost).
* A denoiser's worker answers one call per request; a sampler's calls back into the renderer every
  round: while ``sample`` runs, the parent serves the worker's requests (``render``, ``remaining``,
  ``seconds_left``) until it says ``done`` or ``error``.
"""

from __future__ import annotations

import numpy as np

from denoisebench.plugins import Limits, PluginProxy, proxy
from denoisebench.plugins.worker import failure, reply
from denoisebench.sampling.protocol import Budget, BudgetExhausted, SamplerRequestError
from denoisebench.sampling.registry import BUILTINS, SamplerLoadError, UnknownSamplerError, load_sampler
from denoisebench.sampling.synthetic import RoundBuffers


class IsolatedSampler(PluginProxy):
    """A sampler living in a worker process (module docstring); ``name`` is what the worker's instance declared."""

    noun = "sampler"
    service = "denoisebench.sampling.isolation:SamplerService"
    load_errors = {"UnknownSamplerError": UnknownSamplerError, "SamplerLoadError": SamplerLoadError}
    load_error = SamplerLoadError
    header_bytes = 1 << 16

    def __init__(self, spec: str, options: dict | None = None, limits: Limits | None = None, *, sandboxed=True):
        super().__init__(spec, options, limits, sandboxed=sandboxed)
        self.name = self._start()

    def _start(self) -> str:
        return str(self.start().get("name") or self.spec)

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

    def _positions(self, header: dict, payload: bytes | None, dims) -> dict:
        """A placed round's request (N×D float64: film x, y, then lens u, v, then time) as ``render_placed``'s arguments."""
        if dims is None:
            raise SamplerRequestError("this frame cannot place samples (RoundHandle.dimensions is None)")
        width = 2 + 2 * ("lens" in dims) + ("time" in dims)
        try:
            rows, columns = (int(n) for n in header["shape"])
            dtype = np.dtype(str(header["dtype"]))
        except (KeyError, TypeError, ValueError):
            raise SamplerRequestError("malformed placed round request") from None
        if dtype != np.dtype("<f8") or columns != width or rows < 1:
            raise SamplerRequestError(f"a placed round is N×{width} float64 positions, got {rows}×{columns} of {dtype}")
        if payload is None or len(payload) != rows * columns * 8:
            raise SamplerRequestError("a placed round request whose bytes do not match its shape")
        points = np.frombuffer(payload, dtype="<f8").reshape(rows, columns).copy()
        out, at = {"film": points[:, :2], "lens": None, "time": None}, 2
        if "lens" in dims:
            out["lens"], at = points[:, at : at + 2], at + 2
        if "time" in dims:
            out["time"] = points[:, at]
        return out

    def sample(self, budget, rounds) -> None:
        """Run the plugin's ``sample`` in the worker, serving its requests with ``rounds``."""
        self.check_enabled()
        if not self.running:
            self.name = self._start()
        shape = (rounds.height, rounds.width)
        dims = getattr(rounds, "dimensions", None)
        self.send(("sample", budget.spp, budget.seconds, rounds.width, rounds.height, dims))
        while True:
            # a placed round's positions: at most 4x what is left (and a pixel's worth each), 5 float64 each
            placed_bytes = 4 * (max(rounds.remaining_samples(), 0) + shape[0] * shape[1]) * 5 * 8
            header, payload = self.receive("sample()", max(shape[0] * shape[1] * 8, placed_bytes))
            op = header.get("op")
            if op == "done":
                return
            if op == "error":
                if header.get("error_type") == "BudgetExhausted":
                    raise BudgetExhausted(str(header.get("error", "")).removeprefix("BudgetExhausted: "))
                raise proxy.failure_from(header, "failed")
            if op == "remaining":
                self.send(("value", int(rounds.remaining_samples())))
            elif op == "seconds_left":
                self.send(("value", rounds.seconds_left()))
            elif op in ("render", "place"):
                try:
                    if op == "render":
                        latest = rounds.render(self._counts(header, payload, shape))
                    else:
                        latest = rounds.render_placed(**self._positions(header, payload, dims))
                except (BudgetExhausted, SamplerRequestError) as refusal:
                    self.send(("refused", type(refusal).__name__, str(refusal)))
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
                        "placed": None if getattr(latest, "placed", None) is None else dict(latest.placed),
                    },
                }
                self.send(("rendered", state))
            else:
                raise self.kill(f"unknown request {str(op)[:40]!r} from the worker")


class ProxyHandle:
    """The sampler's ``rounds`` inside the worker: the RoundHandle's interface, served by the parent.

    ``dimensions`` is the frame's (None where it cannot place samples); :meth:`render_placed` sends the
    positions as one N×D float64 array (film x, y, then lens u, v, then time), which the parent checks
    and renders through its own handle.
    """

    def __init__(self, conn, budget: Budget, width: int, height: int, dimensions=None):
        self._conn = conn
        self.budget, self.width, self.height = budget, int(width), int(height)
        self.dimensions = None if dimensions is None else tuple(str(d) for d in dimensions)
        self.counts = np.zeros((self.height, self.width), dtype=np.int32)
        self.latest = None
        self.cut = False
        self.exhausted = False

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def spent(self) -> int:
        return int(self.counts.sum(dtype=np.int64))

    def _ask(self, op: str):
        reply(self._conn, {"op": op})
        kind, value = self._conn.recv()
        return value

    def remaining_samples(self) -> int:
        return int(self._ask("remaining"))

    def seconds_left(self):
        return self._ask("seconds_left")

    def render(self, counts):
        array = np.ascontiguousarray(np.asarray(counts))
        if array.dtype.kind not in "iuf" or array.dtype == np.bool_:
            raise SamplerRequestError(f"a round's counts must be integers, got dtype {array.dtype}")
        reply(self._conn, {"op": "render", "shape": list(array.shape), "dtype": array.dtype.str}, array.tobytes())
        return self._answer()

    def render_placed(self, film, lens=None, time=None):
        """One sample at each position (the harness's ``RoundHandle.render_placed``), rendered by the parent."""
        if self.dimensions is None:
            raise SamplerRequestError("this frame cannot place samples (RoundHandle.dimensions is None)")
        film = np.asarray(film, dtype="<f8")
        if film.ndim != 2 or film.shape[1] != 2:
            raise SamplerRequestError(f"film positions must be an N×2 array (got shape {film.shape})")
        columns = [film]
        for name, value, channels in (("lens", lens, 2), ("time", time, 1)):
            if name in self.dimensions:
                if value is None:
                    raise SamplerRequestError(f"this frame's plan samples {name}: give {name} positions")
                columns.append(np.asarray(value, dtype="<f8").reshape(len(film), channels))
        points = np.ascontiguousarray(np.concatenate(columns, axis=1))
        reply(self._conn, {"op": "place", "shape": list(points.shape), "dtype": "<f8"}, points.tobytes())
        return self._answer()

    def _answer(self):
        answer = self._conn.recv()
        if answer[0] == "refused":
            _, kind, message = answer
            raise (BudgetExhausted if kind == "BudgetExhausted" else SamplerRequestError)(message)
        state = answer[1]
        self.counts, self.cut, self.exhausted = state["counts"], state["cut"], state["exhausted"]
        round_state = dict(state["round"])
        placed = round_state.pop("placed", None)
        self.latest = RoundBuffers(**round_state)
        self.latest.placed = placed
        return self.latest


class SamplerService:
    """The worker's side (:mod:`denoisebench.plugins.worker`): one sampler, run against a :class:`ProxyHandle`.

    Requests: ``("sample", spp, seconds, width, height, dimensions)``, and the answers to the worker's own requests
    (``("rendered", state)``, ``("refused", kind, message)``, ``("value", number)``). The worker sends a
    JSON header, for a round request followed by the count map's raw bytes (a placed round's: its N×D
    float64 positions), and ends a ``sample`` with
    ``{"op": "done"}`` or ``{"op": "error", ...}`` (everything the sampler raised, SystemExit too).
    """

    def __init__(self, conn):
        self.conn = conn
        self.sampler = None

    def load(self, spec: str, options: dict) -> dict:
        self.sampler = load_sampler(spec, **options)
        return {"name": str(getattr(self.sampler, "name", None) or spec)}

    def handle(self, message: tuple) -> None:
        if message[0] != "sample":
            reply(self.conn, {"op": "error", "error": f"unknown request {message[0]!r}"})
            return
        _, spp, seconds, width, height, *rest = message
        handle = ProxyHandle(self.conn, Budget(spp=spp, seconds=seconds), width, height, rest[0] if rest else None)
        try:
            self.sampler.sample(handle.budget, handle)
        except BaseException as error:  # noqa: BLE001 - SystemExit too: the sampler's failure, one line
            reply(self.conn, {"op": "error", **failure(error)})
            return
        reply(self.conn, {"op": "done"})


def sampler_policy(denoiser_policy: str) -> str:
    """The samplers' policy for a run's ``--isolation`` (the denoisers' names, the same meaning)."""
    return proxy.check_policy(denoiser_policy)


def isolated(spec: str, policy: str = proxy.DEFAULT_POLICY) -> bool:
    """Whether ``spec`` runs in a worker under ``policy``."""
    return proxy.isolated(spec, policy, BUILTINS)


def load(
    spec: str,
    options: dict | None = None,
    *,
    policy: str = proxy.DEFAULT_POLICY,
    limits: Limits | None = None,
    time_limit: float | None = None,
    memory_limit_mb: int | None = None,
):
    """The sampler ``spec`` names: in this process, or in a worker by ``policy`` (module docstring).

    ``limits`` are the worker's; ``time_limit`` and ``memory_limit_mb`` (None: the default) replace
    those of ``limits``, for the benchmark's sampler units, which keep the two numbers.
    """
    if isolated(spec, policy):
        limits = limits or Limits()
        if time_limit is not None or memory_limit_mb is not None:
            limits = Limits(
                limits.time_limit if time_limit is None else float(time_limit),
                limits.memory_limit_mb if memory_limit_mb is None else int(memory_limit_mb),
                limits.processes,
                limits.open_files,
                limits.scratch_mb,
            )
        return IsolatedSampler(spec.strip(), options, limits, sandboxed=proxy.sandboxed(policy))
    return load_sampler(spec, **(options or {}))
