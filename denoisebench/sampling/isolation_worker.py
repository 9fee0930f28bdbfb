"""The worker process of :mod:`denoisebench.sampling.isolation`: loads one sampler and runs it against a proxy handle.

Started as ``python -m denoisebench.sampling.isolation_worker FD``, FD one end of a socket pair (a
:class:`multiprocessing.connection.Connection`). The parent is trusted, so what it sends is pickled:
``("load", spec, options, sys_path, rlimits)``, ``("sample", spp, seconds, width, height)``, the answers to the
worker's requests (``("rendered", state)``, ``("refused", kind, message)``, ``("value", number)``) and
``("close",)``. The worker is not trusted, so what it sends is **never a pickle**: a JSON header
(``send_bytes``), followed for a round request by the count map's raw bytes.

While ``sample`` runs, the sampler's handle is a :class:`ProxyHandle`: each ``render(counts)`` sends
the map to the parent, whose harness renders it (cutting it to the budget as in-process) and sends
back the accumulated buffers; ``remaining_samples()`` and ``seconds_left()`` ask the parent too.
Everything the sampler raises (``SystemExit`` included) goes back as one line; ``os._exit()``, a
crash or a signal ends the process, which the parent reports with the exit status.

Notes
-----
Under the sandbox (:mod:`denoisebench.sandbox`) this process sees no file of the host but Python,
``sys.path``, the plugin and its option files; it needs no more, since the parent renders every
round. ``rlimits`` (None outside the sandbox) are set on this process before the plugin is imported
(:func:`denoisebench.plugin_worker.set_rlimits`), so the plugin can lower them but never raise them.
"""

from __future__ import annotations

import json
import sys
from multiprocessing.connection import Connection

import numpy as np

from denoisebench.errors import one_line
from denoisebench.plugin_worker import set_rlimits
from denoisebench.sampling.protocol import Budget, BudgetExhausted, SamplerRequestError
from denoisebench.sampling.registry import load_sampler
from denoisebench.sampling.synthetic import RoundBuffers


def _send(conn, header: dict, payload: bytes | None = None) -> None:
    header["payload"] = payload is not None
    conn.send_bytes(json.dumps(header).encode("utf-8"))
    if payload is not None:
        conn.send_bytes(payload)


class ProxyHandle:
    """The sampler's ``rounds`` inside the worker: the RoundHandle's interface, served by the parent."""

    def __init__(self, conn, budget: Budget, width: int, height: int):
        self._conn = conn
        self.budget, self.width, self.height = budget, int(width), int(height)
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
        _send(self._conn, {"op": op})
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
        _send(self._conn, {"op": "render", "shape": list(array.shape), "dtype": array.dtype.str}, array.tobytes())
        answer = self._conn.recv()
        if answer[0] == "refused":
            _, kind, message = answer
            raise (BudgetExhausted if kind == "BudgetExhausted" else SamplerRequestError)(message)
        state = answer[1]
        self.counts, self.cut, self.exhausted = state["counts"], state["cut"], state["exhausted"]
        self.latest = RoundBuffers(**state["round"])
        return self.latest


def main(fd: int) -> int:

    conn = Connection(fd)
    sampler = None
    while True:
        try:
            message = conn.recv()
        except EOFError:
            return 0
        if message[0] == "close":
            return 0
        if message[0] == "load":
            _, spec, options, sys_path, rlimits = message
            set_rlimits(rlimits)
            sys.path[:] = list(sys_path)
            try:
                sampler = load_sampler(spec, **options)
                name = str(getattr(sampler, "name", None) or spec)
            except BaseException as error:  # noqa: BLE001 - every failure goes back as one line
                _send(conn, {"ok": False, "error_type": type(error).__name__, "error": one_line(error)})
                continue
            _send(conn, {"ok": True, "name": name})
        elif message[0] == "sample":
            _, spp, seconds, width, height = message
            handle = ProxyHandle(conn, Budget(spp=spp, seconds=seconds), width, height)
            try:
                sampler.sample(handle.budget, handle)
            except BaseException as error:  # noqa: BLE001 - SystemExit too: the sampler's failure, one line
                _send(conn, {"op": "error", "error_type": type(error).__name__, "error": one_line(error)})
                continue
            _send(conn, {"op": "done"})


if __name__ == "__main__":
    sys.exit(main(int(sys.argv[1])))
